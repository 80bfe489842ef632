"""Messages a user sees in a normal run: no NumbaWarning about an old
TBB, one summary line for DeFAUST's dropped handles, reference solves that reached
float64 precision said so rather than ``stalled``."""
from __future__ import annotations

import logging
import shutil
import subprocess
import sys

import numpy as np
import pytest

from .conftest import subprocess_env

_DEFORM_AND_PARALLEL = """
import numpy as np, igl, numba as nb
import sshade
from sshade import deform
t = (1 + 5 ** 0.5) / 2
V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
              [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
              [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
              [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
V, F = igl.upsample(V, F, 3)
order = np.argsort(V[:, 1])
h = np.r_[order[:20], order[-20:]]
T = V[h].copy(); T[20:] += [0.3, 0, 0]
V2 = deform(V, F.astype(np.int64), h, T, n_low=200, n_samplings=1, seed=0)

@nb.njit(parallel=True)
def total(a):
    s = 0.0
    for i in nb.prange(len(a)):
        s += a[i]
    return s

print("ok", V2.shape, total(np.ones(1000)), nb.threading_layer())
"""


def _fake_old_tbb(d) -> str:
    """A ``libtbb.so.12`` reporting TBB interface 12050 (older than numba accepts), as
    Ubuntu 22.04's libtbb12 does: the cause of numba's TBB warning."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None or not sys.platform.startswith("linux"):
        pytest.skip("needs a C compiler on Linux to make an old libtbb.so.12")
    src = d / "tbb.c"
    src.write_text("int TBB_runtime_interface_version(void) { return 12050; }\n")
    subprocess.run([cc, "-shared", "-fPIC", "-o", str(d / "libtbb.so.12"), str(src)], check=True)
    return str(d)


def _run(env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", _DEFORM_AND_PARALLEL], capture_output=True, text=True,
                          env=env, timeout=600)


def test_no_numba_tbb_warning_with_an_old_libtbb(tmp_path):
    """Importing sshade, deforming a small mesh and running a numba parallel kernel
    prints no NumbaWarning where an old libtbb is on the library path; the control run
    (numba's own TBB-first order forced) shows that this libtbb does trigger it."""
    lib = _fake_old_tbb(tmp_path)
    env = subprocess_env()
    env["LD_LIBRARY_PATH"] = lib + ":" + env.get("LD_LIBRARY_PATH", "")
    for k in ("NUMBA_THREADING_LAYER", "NUMBA_THREADING_LAYER_PRIORITY"):
        env.pop(k, None)
    r = _run(env)
    assert r.returncode == 0, r.stderr
    assert "ok (642, 3)" in r.stdout
    assert "NumbaWarning" not in r.stderr and "TBB" not in r.stderr, r.stderr
    control = _run(dict(env, NUMBA_THREADING_LAYER_PRIORITY="tbb omp workqueue"))
    assert control.returncode == 0, control.stderr
    assert "The TBB threading layer requires TBB" in control.stderr


def test_avoid_old_tbb_respects_the_users_choice(monkeypatch):
    """A layer or an order the user set through numba's environment variables is kept."""
    from sshade.arap import threads
    monkeypatch.setenv("NUMBA_THREADING_LAYER_PRIORITY", "tbb omp workqueue")
    assert threads.avoid_old_tbb() is False


def test_defaust_dropped_handles_one_summary_line(caplog, tmp_path):
    """Per case, a dropped handle is a DEBUG line; :func:`summarise_dropped` says it
    once, as what it is (the count stays per case in n_handles_dropped)."""
    from defaust.handles import snap_handles
    from eval.datasets.defaust_dataset import summarise_dropped
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1]], float)
    P = np.array([[0, 0, 0], [0.01, 0, 0], [1, 0, 0]], float)
    with caplog.at_level(logging.DEBUG):
        s = snap_handles(V, P, name="case")
    assert s.n_dropped == 1
    assert all(r.levelno < logging.WARNING for r in caplog.records)
    line = summarise_dropped([9, 15, 12], [180, 180, 180])
    assert line.startswith("DeFAUST: 9-15 of 180 handles per case (3 of 3 cases) share a high-res vertex")
    assert "n_handles_dropped" in line and "README" in line
    assert summarise_dropped([0, 0], [180, 180]) is None
    assert "7 of 180 handles per case (1 of 2 cases)" in summarise_dropped([0, 7], [180, 180])


def test_reference_status_words():
    """The log says what ``stalled`` means; the machine-readable status is unchanged."""
    from eval.metrics.reference import status_words
    assert status_words("stalled") == "reached float64 precision"
    assert status_words("converged") == "converged"
    assert status_words("max_iter") == "stopped at max_iter"
    assert status_words("something") == "something"

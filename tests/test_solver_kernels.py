"""sshade/arap/solver_kernels.py: a solve gives the same floats whether numba compiled
its kernels in this process or loaded them from its on-disk cache (a kernel called from a
kernel is linked into its caller as a weak symbol: which copy runs must not change a bit),
for L-BFGS, Anderson and ARAP-SR's block descent."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from tests.conftest import ROOT

SOLVES = textwrap.dedent("""
    import hashlib
    import numpy as np
    from sshade.arap import ArapOptions, solve_arap, solve_arap_sr
    from sshade.arap.problems import twisted_bar
    V, F, h, T = twisted_bar(90.0, h=0.2)
    out = []
    for acc in ("lbfgs", "anderson"):
        r = solve_arap(V, F, h, T, ArapOptions(accelerate=acc, max_iter=200))
        out.append((acc, r.iterations, hashlib.sha256(r.V.tobytes()).hexdigest()))
    r = solve_arap_sr(V, F, h, T, ArapOptions(max_iter=100))
    out.append(("arap_sr", r.iterations, hashlib.sha256(r.V.tobytes()).hexdigest()))
    print(len(V), out)
""")


def _solves(cache) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", SOLVES], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return r.stdout.strip().splitlines()[-1]


@pytest.mark.slow
def test_a_solve_gives_the_same_bits_with_kernels_compiled_here_or_loaded_from_the_cache(tmp_path):
    cold = _solves(tmp_path / "numba")  # every kernel compiled in the process
    warm = _solves(tmp_path / "numba")  # every kernel loaded from the cache the first filled
    assert (tmp_path / "numba").is_dir() and any((tmp_path / "numba").rglob("*.nbi"))
    assert warm == cold

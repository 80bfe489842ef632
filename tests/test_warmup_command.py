"""``python -m sshade warmup`` (sshade/warmup_command.py): every stage named on its own
line (SShaDe, the full-resolution ARAP of ARAP and Elastic, ARAP-SR through its entry
point), the cache folder said, the cache warm afterwards; a bad option is one error line."""
from __future__ import annotations

import subprocess
import sys

from .conftest import ROOT


def _run(*args, timeout=900):
    return subprocess.run([sys.executable, "-m", "sshade", "warmup", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def test_warmup_names_every_stage_and_leaves_the_cache_warm():
    r = _run()
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.splitlines()
    assert "numba's cache: " in lines[0]
    for stage in ("SShaDe kernels", "SShaDe pipeline", "ARAP (converged protocol)", "ARAP (paper protocol)",
                  "Elastic (converged protocol)", "Elastic (paper protocol)",
                  "full-resolution ARAP and ARAP-SR, parallel kernels", "ARAP-SR"):
        assert any(ln.startswith(f"{stage}: ") and ln.endswith(" s") for ln in lines), stage
    assert lines[-1].startswith("done in ") and "NUMBA_CACHE_DIR" in lines[-1]
    cold = subprocess.run([sys.executable, "-c", "from sshade.kernel_cache import cold_kernels; print(cold_kernels())"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert cold.stdout.strip() == "[]"


def test_warmup_refuses_an_unknown_option_in_one_line():
    r = _run("--bogus", timeout=120)
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith("error:")

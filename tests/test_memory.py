"""Peak memory of the process tree (eval/run/memory.py)."""
from __future__ import annotations

import sys
import time

import numpy as np
import pytest

from eval.run.memory import PeakMemory, tree_pss_mb

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PSS from /proc")


@linux
def test_peak_sees_a_short_allocation_and_start_is_the_first_sample():
    before = tree_pss_mb()
    with PeakMemory(interval=0.005) as pm:
        a = np.ones(25_000_000)  # 200 MB, touched
        time.sleep(0.05)
        del a
    assert pm.start_mb > 0 and abs(pm.start_mb - before) < 50
    assert pm.peak_mb - pm.start_mb > 150

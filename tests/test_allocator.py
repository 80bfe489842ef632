"""glibc's allocator told what to do with freed memory (sshade/allocator.py)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from eval.run.memory import tree_pss_mb
from sshade.allocator import release_freed

linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc and PSS from /proc")


def test_keep_freed_memory_takes_its_settings_in_a_fresh_process():
    code = "from sshade.allocator import keep_freed_memory; print(keep_freed_memory())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out in ("True", "False")  # True on glibc; never an exception
    if sys.platform.startswith("linux"):
        assert out == "True"


@linux
def test_release_freed_gives_heap_memory_back():
    assert release_freed() is True
    blocks = [np.ones(1_000) for _ in range(50_000)]  # 400 MB in 8 kB blocks: from the heap, not mmap
    high = tree_pss_mb()
    del blocks
    assert release_freed() is True
    assert tree_pss_mb() < high - 200  # the freed blocks went back to the OS

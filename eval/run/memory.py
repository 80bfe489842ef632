"""Peak memory of this process and its children (Linux /proc), sampled in a thread.

Uses PSS (proportional set size, /proc/PID/smaps_rollup), which splits pages shared
between the parent and its forked workers instead of counting them once per process,
so the sum over the process tree is an honest total. Falls back to ru_maxrss where
/proc is unavailable.
"""
from __future__ import annotations

import os
import resource
import threading
from pathlib import Path

from sshade.allocator import release_freed  # re-exported: the probe's users trim before measuring

__all__ = ["PeakMemory", "tree_pss_mb", "release_freed"]


def _children(pid: int) -> list[int]:
    out = []
    try:
        for t in Path(f"/proc/{pid}/task").iterdir():
            txt = (t / "children").read_text().split()
            out.extend(int(x) for x in txt)
    except OSError:
        pass
    return out


def _pss_kb(pid: int) -> int:
    try:
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Pss:"):
                return int(line.split()[1])
    except (OSError, ValueError):
        pass
    return 0


def tree_pss_mb(pid: int | None = None) -> float:
    """Current PSS of a process and all its descendants, in MB (1e6 bytes)."""
    pid = os.getpid() if pid is None else pid
    todo, total = [pid], 0
    while todo:
        p = todo.pop()
        total += _pss_kb(p)
        todo.extend(_children(p))
    return total * 1024 / 1e6


class PeakMemory:
    """Context manager sampling the process tree's PSS every ``interval`` seconds.

    Attributes
    ----------
    peak_mb : float, the largest sample (MB), available after the ``with`` block.
    start_mb : float, the first sample, taken on entering it (MB; 0.0 without /proc).

    Examples
    --------
    Example::

        with PeakMemory() as pm:
            work()
        pm.peak_mb
    """

    def __init__(self, interval: float = 0.02):
        self.interval = interval
        self.peak_mb = 0.0
        self.start_mb = 0.0
        self._stop = threading.Event()
        self._ok = Path("/proc/self/smaps_rollup").exists()

    def _loop(self):
        while not self._stop.is_set():
            self.peak_mb = max(self.peak_mb, tree_pss_mb())
            self._stop.wait(self.interval)

    def __enter__(self):
        if self._ok:
            self.peak_mb = self.start_mb = tree_pss_mb()
            self._t = threading.Thread(target=self._loop, daemon=True)
            self._t.start()
        return self

    def __exit__(self, *exc):
        if self._ok:
            self._stop.set()
            self._t.join()
            self.peak_mb = max(self.peak_mb, tree_pss_mb())
        else:
            self.peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3
        return False

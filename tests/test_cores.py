"""sshade/cores.py: the cores a process may use (its affinity, capped by a job runner's
share) and the size of a pool over them."""
from __future__ import annotations

import os

from sshade.cores import CORES_VARIABLE, available_cores, pool_size


def _affinity() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def test_available_cores_is_the_affinity_capped_by_the_share(monkeypatch):
    monkeypatch.delenv(CORES_VARIABLE, raising=False)
    assert available_cores() == _affinity()
    monkeypatch.setenv(CORES_VARIABLE, "1")
    assert available_cores() == 1
    monkeypatch.setenv(CORES_VARIABLE, str(_affinity() + 5))  # a share above the mask: the mask
    assert available_cores() == _affinity()
    for junk in ("0", "-3", "two", ""):  # not a positive count: ignored
        monkeypatch.setenv(CORES_VARIABLE, junk)
        assert available_cores() == _affinity()


def test_pool_size_is_the_workers_capped_by_the_jobs_and_at_least_one(monkeypatch):
    monkeypatch.setenv(CORES_VARIABLE, "1")
    assert pool_size(None, 10) == 1 and pool_size(8, 3) == 3 and pool_size(1, 10) == 1 and pool_size(4, 0) == 1

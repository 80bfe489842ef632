"""The samplings' pool and average (sshade/sampling.py, paper §3.3)."""
from __future__ import annotations

import numpy as np
import pytest

from sshade.sampling import SamplingPool, average, sampling_seeds, worker_state


@pytest.mark.parametrize("k", [1, 2, 5, 7])
def test_average_is_numpy_mean_bit_for_bit(k):
    """The in-place average adds in sampling order, as np.mean over the stacked results."""
    rng = np.random.default_rng(k)
    results = [rng.normal(size=(1000, 3)) * 10.0 ** rng.integers(-3, 4) for _ in range(k)]
    keep = [r.copy() for r in results]
    out = average(results)
    assert out.dtype == np.float64 and np.array_equal(out, np.mean(results, axis=0))
    assert all(np.array_equal(a, b) for a, b in zip(results, keep))  # inputs untouched
    assert out is not results[0]


def _task(i):
    return i, worker_state()["x"] * i


@pytest.mark.parametrize("workers", [1, 2])
def test_pool_runs_tasks_with_the_state_in_order(workers):
    with SamplingPool({"x": 3}, workers) as pool:
        got = [f.result() for f in [pool.submit(_task, i) for i in range(4)]]
    assert got == [(0, 0), (1, 3), (2, 6), (3, 9)] and worker_state() == {}


def test_sampling_seeds_are_recorded_values():
    a, b = sampling_seeds(0, 5), sampling_seeds(0, 3)
    assert a[:3] == b and len(set(a)) == 5 and all(isinstance(s, int) for s in a)


def test_keep_freed_memory_only_in_forked_workers(monkeypatch):
    """glibc's allocator is tuned in the forked workers (they end with the pool), never
    in the caller's process: a pool run in-process does not call it."""
    import sshade.sampling as sampling

    def refuse(*a, **k):
        raise AssertionError("keep_freed_memory called in the caller's process")

    monkeypatch.setattr(sampling, "keep_freed_memory", refuse)
    with SamplingPool({"x": 1}, 1) as pool:
        assert pool.submit(_task, 2).result() == (2, 2)

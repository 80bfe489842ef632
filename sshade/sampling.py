"""The k samplings of SShaDe run side by side (paper §3.3): one process pool, shared by
the handle pipeline (:mod:`sshade.pipeline`), :mod:`sshade.prepared` and the
correspondence transfers (:mod:`sshade.isometric`); the samplings' seeds and average.

Example::

    with SamplingPool(job, workers=1) as pool:
        pool.submit_with_job(task, 0).result()   # task(job, 0)
"""
from __future__ import annotations

import multiprocessing as mp
import time
from concurrent.futures import Future, ProcessPoolExecutor

import numpy as np

from .allocator import keep_freed_memory
from .arap import warmup_kernels
from .cores import pool_size  # noqa: F401 - the samplings' worker count (None: the cores this process may use)
from .kernel_cache import compile_kernels
from .mesh.geodesic import VoronoiState
from .mesh.halfedge import halfedges, vertex_fan_count
from .projection import project_to_fans

__all__ = ["SamplingPool", "worker_state", "pool_size", "sampling_seeds", "warm_kernels", "average"]

# The job of the running pool, installed in this process (serial pool) or in a forked
# worker (at its start): empty, or that one job.
_INSTALLED: list = []
_WARM = [False]


def worker_state():
    """The job of the :class:`SamplingPool` running the current task (in a forked worker:
    its inherited copy); ``{}`` outside a pool. Tasks submitted with
    :meth:`SamplingPool.submit_with_job` receive it as their first argument instead."""
    return _INSTALLED[0] if _INSTALLED else {}


def _install(job) -> None:
    _INSTALLED.clear()
    _INSTALLED.append(job)


def _init_forked(job) -> None:
    """Initializer of a forked sampling worker: the job, and glibc's allocator told
    to keep freed memory (:func:`keep_freed_memory`)."""
    keep_freed_memory()
    _install(job)


def _call_with_job(fn, *args):
    """``fn(job, *args)`` in a forked worker, ``job`` the one installed at its start."""
    return fn(_INSTALLED[0], *args)


def sampling_seeds(seed: int, k: int) -> list[int]:
    """The k first-seed RNG seeds derived from ``seed`` (recorded in every output)."""
    return [int(s) for s in np.random.SeedSequence(seed).generate_state(k, dtype=np.uint32)]


def average(results: list) -> np.ndarray:
    """The mean of the samplings' results, summed in sampling order (paper §3.3).

    Parameters
    ----------
    results : list of k >= 1 arrays of one shape, e.g. (n, 3) float64 deformed meshes.

    Returns
    -------
    array of that shape, float64: the same values as ``np.mean(results, axis=0)`` (the
    same additions in the same order), without stacking the k arrays into a new
    (k, n, 3) one (at a million vertices that copy and its first-touch page faults
    cost up to tenths of a second, on the critical path).

    Examples
    --------
    >>> average([np.zeros(2), np.ones(2)]).tolist()
    [0.5, 0.5]
    """
    out = np.array(results[0], np.float64)
    for r in results[1:]:
        out += r
    out /= len(results)
    return out


def warm_kernels(large: bool = True) -> float:
    """Compile (or load from numba's cache) the kernels of one sampling in this process
    (geodesic sampling, half-edges, projection, the low-res ARAP's serial kernels), so
    that forked workers inherit them instead of each compiling its own.

    Parameters
    ----------
    large : also those of a mesh of at least :data:`sshade.mesh.halfedge.KERNEL_MIN_FACES`
        faces (:func:`sshade.mesh.halfedge.large_mesh` of the call's faces).

    Returns
    -------
    float, the seconds spent (0.0 when already done in this process).
    """
    t0 = time.perf_counter()
    seconds = compile_kernels(large=large)  # on a cold cache: half of them in a forked child at the same time
    if _WARM[0]:
        return seconds
    V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 4], [2, 3, 4], [3, 1, 4]])
    st = VoronoiState(V, F)
    st.sample(3, 0)
    st.add([4])
    project_to_fans(V, np.zeros(5, np.int64), V[:3], np.array([[0, 1, 2]]))
    vertex_fan_count(F, halfedges(F, 5), 5)
    warmup_kernels()  # the low-res ARAP's serial kernels, inherited by the forked workers
    _WARM[0] = True
    return time.perf_counter() - t0


class SamplingPool:
    """A pool running sampling tasks, as a context manager.

    Parameters
    ----------
    job : the object every task works on (e.g. :class:`sshade.pipeline.SamplingJob`: meshes,
        seeds, options), handed to each forked worker once, at fork (never pickled per task).
    workers : int >= 1, processes (:func:`sshade.cores.pool_size`: None = the cores this
        process may use, :func:`sshade.cores.available_cores`); 1 runs the tasks in this process
        (so does a platform without ``fork``).

    ``submit_with_job(fn, *args)`` runs ``fn(job, *args)`` and ``submit(fn, *args)`` runs
    ``fn(*args)``, each returning a :class:`concurrent.futures.Future`; ``fn`` must be a
    module-level function (it runs in a worker). Leaving the ``with`` block waits for the
    workers and uninstalls the job.
    """

    def __init__(self, job, workers: int):
        self.job, self.workers = job, int(workers)
        self._ex = None

    def __enter__(self) -> SamplingPool:
        if self.workers == 1 or "fork" not in mp.get_all_start_methods():
            _install(self.job)
        else:
            # fork: workers inherit the job's arrays and the compiled numba code without pickling
            self._ex = ProcessPoolExecutor(max_workers=self.workers, mp_context=mp.get_context("fork"),
                                           initializer=_init_forked, initargs=(self.job,)).__enter__()
        return self

    def submit_with_job(self, fn, *args) -> Future:
        """Run ``fn(job, *args)`` in a worker (or here, at once, when serial)."""
        if self._ex is not None:
            return self._ex.submit(_call_with_job, fn, *args)
        return self.submit(fn, self.job, *args)

    def submit(self, fn, *args) -> Future:
        """Run ``fn(*args)`` in a worker (or here, at once, when serial)."""
        if self._ex is not None:
            return self._ex.submit(fn, *args)
        f: Future = Future()
        f.set_result(fn(*args))
        return f

    def __exit__(self, *exc) -> bool:
        try:
            if self._ex is not None:
                self._ex.__exit__(*exc)
        finally:
            self._ex = None
            _INSTALLED.clear()
        return False

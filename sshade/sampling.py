"""The k samplings of SShaDe run side by side (paper §3.3): one process pool, shared by
the handle pipeline (:func:`sshade.deform.deform`) and the correspondence transfers
(:mod:`sshade.isometric`).

Each sampling remeshes the high-resolution mesh with its own first seed
(:func:`sampling_seeds`) and its results are averaged. The samplings run in forked
worker processes, which inherit the high-resolution mesh (the pool's ``state``, read in
a task with :func:`worker_state`) and the numba kernels compiled before the fork
(:func:`warm_kernels`) without pickling; with one worker, or where ``fork`` is not
available, they run in this process, in the same order, with the same results.

Example::

    with SamplingPool({"x": 2}, workers=1) as pool:
        pool.submit(task, 0).result()
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

# The state of the running pool, in this process (workers=1) or in a forked worker.
_STATE: dict = {}
_WARM = [False]


def worker_state() -> dict:
    """The ``state`` mapping of the :class:`SamplingPool` running the current task (in a
    forked worker: its inherited copy)."""
    return _STATE


def _init_worker(state: dict) -> None:
    _STATE.clear()
    _STATE.update(state)


def _init_forked(state: dict) -> None:
    """Initializer of a forked sampling worker: the state, and glibc's allocator told
    to keep freed memory (:func:`keep_freed_memory`)."""
    keep_freed_memory()
    _init_worker(state)


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


def warm_kernels() -> float:
    """Compile (or load from numba's cache) the kernels of one sampling in this process
    (geodesic sampling, half-edges, projection, the low-res ARAP's serial kernels), so
    that forked workers inherit them instead of each compiling its own.

    Returns
    -------
    float, the seconds spent (0.0 when already done in this process).
    """
    if _WARM[0]:
        return 0.0
    t0 = time.perf_counter()
    compile_kernels()  # on a cold cache: half of them in a forked child at the same time
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
    state : dict, what every task reads through :func:`worker_state` (meshes, seeds,
        options); handed to each forked worker once, at fork.
    workers : int >= 1, processes (:func:`sshade.cores.pool_size`: None = the cores this
        process may use, :func:`sshade.cores.available_cores`); 1 runs the tasks in this process
        (so does a platform without ``fork``).

    ``submit(fn, *args)`` returns a :class:`concurrent.futures.Future`; ``fn`` must be a
    module-level function (it runs in a worker). Leaving the ``with`` block waits for the
    workers and clears the state.
    """

    def __init__(self, state: dict, workers: int):
        self.state, self.workers = state, int(workers)
        self._ex = None

    def __enter__(self) -> SamplingPool:
        if self.workers == 1 or "fork" not in mp.get_all_start_methods():
            _init_worker(self.state)
        else:
            # fork: workers inherit the mesh and the compiled numba code without pickling
            self._ex = ProcessPoolExecutor(max_workers=self.workers, mp_context=mp.get_context("fork"),
                                           initializer=_init_forked, initargs=(self.state,)).__enter__()
        return self

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
            _STATE.clear()
        return False

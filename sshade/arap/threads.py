"""Thread policy of the ARAP kernels: how many threads numba's parallel kernels use.

:func:`max_threads`, :func:`resolve_threads` (serial below :data:`MAIN_MIN_CELLS` cells for
a solve of the main thread, below :data:`PARALLEL_MIN_CELLS` for one of another thread or
inside :func:`beside_others`, in worker processes, and in a forked child of an OpenMP pool's
owner: :func:`fork_unsafe`), :func:`numba_threads` (context manager), :class:`ThreadPicker`
(the automatic mode of :func:`sshade.arap.solver.solve_arap`) and :func:`avoid_old_tbb`
(run at import). No kernel's result depends on the thread count. Threading layers:
docs/implementation.md ("Implementation notes: sshade/arap/threads.py").
"""
from __future__ import annotations

import ctypes
import multiprocessing
import os
import sys
import threading
from contextlib import contextmanager

from ..errors import SShaDeError

try:  # numba is a dependency of the package; without it the numpy paths are used
    import numba as nb
    from numba.np.ufunc import parallel as nb_parallel
except ImportError:  # pragma: no cover
    nb = None
    nb_parallel = None

__all__ = ["PARALLEL_MIN_CELLS", "MAIN_MIN_CELLS", "TBB_MIN_INTERFACE", "tbb_usable", "avoid_old_tbb", "max_threads",
           "uses_parallel_kernels",
           "resolve_threads", "beside_others", "fork_unsafe", "note_launch", "numba_threads", "ThreadPicker"]

#: in the automatic mode, a solve of a thread other than the main one, or inside
#: :func:`beside_others`, below this many cells uses the serial kernels (no numba threading
#: layer; a parallel region costs ~10-50 us, which small meshes do not pay back, and the
#: low-res solves already run one per core).
PARALLEL_MIN_CELLS = 20_000
#: the same threshold for a solve of the main thread of the main process, outside
#: :func:`beside_others` (a full-resolution solve): no other solve shares its cores, and the
#: solver's :class:`ThreadPicker` times the serial kernels against the threads, so small
#: problems gain (benchmarks/records/elastic_small_cases.md, "The main thread's threshold").
MAIN_MIN_CELLS = 2_000

_LOCAL = threading.local()  # .beside: this thread is inside beside_others()

_LAUNCH_PID = None  # process that started numba's thread pool through this package

#: the oldest TBB interface numba's TBB layer accepts (numba/np/ufunc/parallel.py)
TBB_MIN_INTERFACE = 12060
_TBB_LIB = {"win32": "tbb12.dll", "darwin": "libtbb.12.dylib"}


def tbb_usable() -> bool:
    """True when a TBB runtime that numba's TBB layer accepts can be loaded (the check
    numba makes, without its warning): ``libtbb.so.12`` with interface >= 12060."""
    try:
        lib = ctypes.CDLL(_TBB_LIB.get(sys.platform, "libtbb.so.12"))
        fn = lib.TBB_runtime_interface_version
    except (OSError, AttributeError):
        return False
    fn.argtypes, fn.restype = [], ctypes.c_int
    return int(fn()) >= TBB_MIN_INTERFACE


def avoid_old_tbb() -> bool:
    """Without a usable TBB (:func:`tbb_usable`), make numba try OpenMP, then its
    workqueue, before TBB: the layer numba would fall back to anyway, minus the
    NumbaWarning an old ``libtbb`` triggers. Does nothing when the user chose a layer or
    an order (``NUMBA_THREADING_LAYER``, ``NUMBA_THREADING_LAYER_PRIORITY``), when TBB
    is usable, or once numba's thread pool runs. Returns True when the order was set."""
    if nb is None or getattr(nb_parallel, "_is_initialized", False):
        return False
    if os.environ.get("NUMBA_THREADING_LAYER") or os.environ.get("NUMBA_THREADING_LAYER_PRIORITY"):
        return False
    if tbb_usable():
        return False
    nb.config.THREADING_LAYER_PRIORITY = ["omp", "workqueue", "tbb"]
    return True


avoid_old_tbb()


def max_threads() -> int:
    """Threads the parallel kernels may use: numba's ``NUMBA_NUM_THREADS`` (its
    environment variable, default the CPU count); 1 without numba."""
    return int(nb.config.NUMBA_NUM_THREADS) if nb is not None else 1


def fork_unsafe() -> bool:
    """True in a forked child whose parent had started numba's OpenMP thread pool: GNU
    libgomp is not fork-safe and numba aborts the process ("fork() called from a process
    already using GNU OpenMP") at the child's first parallel region."""
    if not getattr(nb_parallel, "_is_initialized", False):
        return False  # no pool yet: this process would start its own
    if _LAUNCH_PID == os.getpid():
        return False
    try:
        return nb.threading_layer() == "omp"
    except Exception:  # pragma: no cover - unknown state: stay serial
        return True


def note_launch() -> None:
    """Record that this process runs numba's thread pool (see :func:`fork_unsafe`)."""
    global _LAUNCH_PID
    if _LAUNCH_PID is None:
        _LAUNCH_PID = os.getpid()


def resolve_threads(threads: int | None, n_cells: int) -> int:
    """Threads for the per-cell kernels of a problem with ``n_cells`` cells (1 = serial).

    ``threads=None`` (automatic): 1 below :data:`MAIN_MIN_CELLS` cells in the main thread,
    below :data:`PARALLEL_MIN_CELLS` in another thread or inside :func:`beside_others`, or
    inside a child process (``multiprocessing`` workers: the caller already parallelises over
    processes), else :func:`max_threads` (``NUMBA_NUM_THREADS``). An explicit
    ``threads >= 1`` is capped at :func:`max_threads`, and at 1 in a forked child of a
    process that ran numba's OpenMP threads (a parallel region would abort it).

    Raises
    ------
    SShaDeError on ``threads < 1``.
    """
    if threads is not None and (int(threads) != threads or int(threads) < 1):
        raise SShaDeError(f"threads must be an integer >= 1 or None, got {threads!r}")
    child = multiprocessing.parent_process() is not None
    if threads is None:
        alone = threading.current_thread() is threading.main_thread() and not getattr(_LOCAL, "beside", False)
        if n_cells < (MAIN_MIN_CELLS if alone else PARALLEL_MIN_CELLS) or child:
            return 1
        t = max_threads()
    else:
        t = min(int(threads), max_threads())
    if t > 1 and child and fork_unsafe():
        return 1
    return t


def uses_parallel_kernels(n_vertices: int | None) -> bool:
    """Whether a full-resolution ARAP solve on an ``n_vertices`` mesh runs numba's parallel
    kernels (:func:`resolve_threads` in the automatic mode, from this thread: enough
    rotation cells = vertices, more than one thread, not inside a worker process). False
    for None."""
    return n_vertices is not None and resolve_threads(None, int(n_vertices)) > 1


@contextmanager
def beside_others():
    """Context manager: the automatic thread count of the solves this thread starts inside
    takes :data:`PARALLEL_MIN_CELLS` as its threshold, as in any thread but the main one
    (SShaDe's low-res solves: one per sampling, side by side on the cores, or one after the
    other where a job was given one core). Nests."""
    prev = getattr(_LOCAL, "beside", False)
    _LOCAL.beside = True
    try:
        yield
    finally:
        _LOCAL.beside = prev


@contextmanager
def numba_threads(t: int):
    """Context manager: numba's thread count set to ``t`` for the calls inside (restored
    after). Only entered for parallel kernels (``t > 1``)."""
    t = int(t)
    note_launch()
    prev = nb.get_num_threads()
    if prev != t:
        nb.set_num_threads(t)
    try:
        yield
    finally:
        if prev != t:
            nb.set_num_threads(prev)


class ThreadPicker:
    """Threads of the solver's kernels in the automatic mode: 1 or ``tmax``, whichever ran
    the iterations faster (the results are the same to the bit). The other choice is
    re-timed every ``probe`` iterations, so that the pick follows the load of a shared
    machine: there a parallel region waits for its slowest thread, and numba's OpenMP
    workers spin after each region, taking CPU from the serial Cholesky solve (so that
    parallel iterations can be slower than serial ones).

    Attributes
    ----------
    cur : int, threads of the next iteration. best : int, the faster mode so far.
    count, n_par : int, iterations recorded, of which with ``tmax`` threads.
    """

    def __init__(self, tmax: int, probe: int = 16):
        self.tmax, self.probe = tmax, probe
        self.cost = {tmax: None, 1: None}  # smoothed seconds per iteration
        self.cur, self.best, self.count, self.n_par = tmax, tmax, 0, 0

    def record(self, t: int, dt: float) -> None:
        """Account an iteration run with ``t`` threads in ``dt`` seconds; pick the next."""
        c = self.cost[t]
        self.cost[t] = dt if c is None else 0.5 * (c + dt)
        self.count += 1
        self.n_par += t > 1
        other = 1 if t > 1 else self.tmax
        if self.cost[other] is None:
            self.cur = other
            return
        self.best = min(self.cost, key=self.cost.get)
        worse = 1 if self.best > 1 else self.tmax
        self.cur = worse if self.count % self.probe == 0 else self.best

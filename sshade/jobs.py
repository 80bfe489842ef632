"""Jobs in worker processes: a DeFAUST build's subjects, an evaluation's cases side by side.

:func:`run_jobs` runs ``job(*args)`` for every ``args`` of a list in a
``ProcessPoolExecutor`` with the ``spawn`` context (pymeshlab and numba are not known to
be fork-safe): every worker process starts fresh, runs ``init(*init_args)`` once and then
its jobs. A job reports progress with :func:`send` (delivered in the main process to
``on_message``, while the jobs run; every message of a job before :func:`run_jobs`
returns) and returns its result (delivered to ``on_result``
with the job's index). Results are whatever the jobs return, in the order they finish:
callers that need a fixed order (the manifest) sort them by index.

Each worker's threads are limited so that ``workers x threads`` does not exceed the cores
of this process (:func:`available_cores`, the affinity mask), through the environment
variables the libraries read at import (:data:`THREAD_VARIABLES`, or those the caller
names), set while the workers start; :data:`CORES_VARIABLE` tells the worker's own code
(:func:`available_cores`, e.g. SShaDe's sampling pool, :func:`sshade.sampling.pool_size`)
that it has that many cores.

Users: :mod:`defaust.build` (``workers``) and :mod:`eval.experiments.cases_jobs` (``jobs``).

Example::

    run_jobs(square, [(1,), (2,)], workers=2, on_result=lambda i, r: print(i, r))
"""
from __future__ import annotations

import multiprocessing as mp
import os
import queue
import signal
import threading
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

from sshade.errors import SShaDeError

__all__ = ["THREAD_VARIABLES", "CORES_VARIABLE", "available_cores", "pool_size", "thread_limit", "run_jobs", "send",
           "in_worker"]

#: Environment variables that cap the threads of OpenBLAS, MKL, OpenMP, Accelerate, numexpr and numba.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
                    "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS")

#: Set in the workers of :func:`run_jobs` to their share of the cores (:func:`thread_limit`);
#: :func:`available_cores` reads it.
CORES_VARIABLE = "SSHADE_JOB_CORES"

_CHANNEL: list = [None]  # in a worker: the queue to the main process


def available_cores() -> int:
    """CPU cores this process may use, >= 1: its affinity mask where the OS has one (else
    the CPU count), at most :data:`CORES_VARIABLE` when set (a worker of :func:`run_jobs`)."""
    try:
        n = max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - macOS, Windows
        n = max(1, os.cpu_count() or 1)
    share = os.environ.get(CORES_VARIABLE, "")
    return max(1, min(n, int(share))) if share.isdigit() and int(share) > 0 else n


def pool_size(workers: int | None, n_jobs: int) -> int:
    """Worker processes (or threads) for ``n_jobs`` jobs: ``workers`` (None:
    :func:`available_cores`), capped at ``n_jobs``, at least 1.

    Examples
    --------
    >>> pool_size(4, 2), pool_size(3, 0)
    (2, 1)
    """
    w = available_cores() if workers is None else int(workers)
    return max(1, min(w, int(n_jobs)))


def thread_limit(workers: int) -> int:
    """Threads per worker so that ``workers x threads <= available_cores()`` (>= 1)."""
    return max(1, available_cores() // max(1, int(workers)))


def in_worker() -> bool:
    """Whether this process is a worker of :func:`run_jobs`."""
    return _CHANNEL[0] is not None


def send(message) -> None:
    """From a job: deliver ``message`` (picklable) to ``on_message`` in the main process.

    Raises
    ------
    SShaDeError outside a worker of :func:`run_jobs`.
    """
    if _CHANNEL[0] is None:
        raise SShaDeError("sshade.jobs.send: not in a worker of run_jobs")
    _CHANNEL[0].put(message)


def _init_worker(channel, init, init_args) -> None:
    _CHANNEL[0] = channel
    if init is not None:
        init(*init_args)


@contextmanager
def _thread_env(threads: int, names=THREAD_VARIABLES):
    """Set the variables ``names`` to ``threads`` in this process's environment (inherited
    by processes started meanwhile), restored on exit."""
    old = {k: os.environ.get(k) for k in names}
    os.environ.update({k: str(int(threads)) for k in names})
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


_DONE = "__sshade.jobs: job done__"


@contextmanager
def _deferred_sigint():
    """Ctrl-C while jobs run is noted, and re-delivered by :func:`run_jobs`'s loop at a
    safe point (``hit`` non-empty: call :func:`_deliver`). A KeyboardInterrupt raised
    inside ``concurrent.futures.wait`` can leave a future's lock held, and the executor's
    shutdown then waits forever (seen once in the test suite under load). Does nothing
    off the main thread or when SIGINT is ignored; the previous handler is restored."""
    hit: list = []
    if threading.current_thread() is not threading.main_thread():
        yield hit
        return
    old = signal.getsignal(signal.SIGINT)
    if not callable(old):  # SIG_IGN / SIG_DFL: leave it
        yield hit
        return
    signal.signal(signal.SIGINT, lambda signum, frame: hit.append((old, signum, frame)))
    try:
        yield hit
    finally:
        signal.signal(signal.SIGINT, old)


def _deliver(hit: list) -> None:
    """Run the handler a deferred Ctrl-C was meant for (raises KeyboardInterrupt)."""
    handler, signum, frame = hit[0]
    handler(signum, frame)
    raise KeyboardInterrupt  # a handler that returned: still stop the jobs


def _call(job, index: int, args: tuple):
    """A job in a worker, then its end marker on the channel (after all its messages)."""
    try:
        return job(*args)
    finally:
        _CHANNEL[0].put((_DONE, index))


def _drain(channel, on_message, ended: set, *, until: set | None = None) -> None:
    """Deliver the channel's messages; note the jobs whose end marker came in ``ended``.
    With ``until``: wait (at most 30 s per message) until those jobs' markers came."""
    while True:
        try:
            if until is not None and not until <= ended:
                msg = channel.get(timeout=30)
            else:
                msg = channel.get_nowait()
        except queue.Empty:
            return
        if isinstance(msg, tuple) and len(msg) == 2 and msg[0] == _DONE:
            ended.add(msg[1])
        elif on_message is not None:
            on_message(msg)


def run_jobs(job, args_list, *, workers: int, init=None, init_args=(), on_message=None, on_result=None,
             thread_variables=THREAD_VARIABLES, what: str = "build") -> None:
    """Run ``job(*args)`` for every ``args`` in ``args_list`` in ``workers`` spawned processes.

    At most ``workers`` jobs are handed out at a time, so that after a failure or Ctrl-C
    no new job starts; on Ctrl-C (or any exception in this process) the workers are
    terminated before it propagates.

    Parameters
    ----------
    job : a module-level function (picklable by reference); its arguments and result picklable.
    args_list : list of tuples. workers : int >= 1, processes (capped at ``len(args_list)``).
    init, init_args : run once in every worker before its first job (module-level function).
    on_message : called in this process with every :func:`send` message, while jobs run.
    on_result : called in this process as ``on_result(index, result)`` when a job finishes.
    thread_variables : the variables of :data:`THREAD_VARIABLES` set to the workers'
        thread limit (the others keep this process's values); :data:`CORES_VARIABLE` is
        always set to it.
    what : the workers' purpose, in the message when one dies (``"build"``, ``"job"``).

    Raises
    ------
    The first failing job's exception (after the jobs already running have finished, so
    that their work is kept; the others are not started). SShaDeError if a worker
    process dies (killed, out of memory).
    """
    n = pool_size(workers, len(args_list))
    ctx = mp.get_context("spawn")
    channel = ctx.Queue()
    before = set(mp.active_children())
    todo = list(enumerate(args_list))[::-1]
    futures, errors, finished, ended, collected = {}, [], False, set(), set()
    # the workers start at submit() and inherit these variables
    with _thread_env(thread_limit(n), (*thread_variables, CORES_VARIABLE)), _deferred_sigint() as hit:
        ex = ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_init_worker,
                                 initargs=(channel, init, tuple(init_args)))
        try:
            while todo or futures:
                if hit:
                    _deliver(hit)
                while todo and len(futures) < n and not errors:
                    i, args = todo.pop()
                    futures[ex.submit(_call, job, i, args)] = i
                if not futures:
                    break
                done, _ = wait(futures, timeout=0.25, return_when=FIRST_COMPLETED)
                _drain(channel, on_message, ended)
                for f in sorted(done, key=futures.get):
                    i = futures.pop(f)
                    if _collect(f, i, on_result, errors, what):
                        collected.add(i)
            _drain(channel, on_message, ended, until=collected)  # every message of the jobs that ran
            if hit:
                _deliver(hit)
            finished = True
        finally:
            if not finished:  # Ctrl-C or an error here: stop the workers now (a remesh ignores signals)
                for p in set(mp.active_children()) - before:
                    p.terminate()
            ex.shutdown(wait=True, cancel_futures=True)
            channel.close()
    if errors:
        raise errors[0]


def _collect(f, index: int, on_result, errors: list, what: str = "build") -> bool:
    """A finished job: its result to ``on_result``, or its exception to ``errors``; False
    if its worker died (no end marker will come)."""
    try:
        result = f.result()
    except BrokenProcessPool as e:
        errors.append(SShaDeError(f"a {what} worker process died ({e}); run the same command again to resume "
                                  "(finished items are kept)"))
        return False
    except Exception as e:  # noqa: BLE001 - raised by run_jobs once the running jobs are done
        errors.append(e)
    else:
        if on_result is not None:
            on_result(index, result)
    return True

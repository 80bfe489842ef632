"""Jobs in worker processes: a DeFAUST build's subjects (:mod:`defaust.build`, ``workers``)
and an evaluation's cases (:mod:`eval.experiments.cases.case_jobs`, ``jobs``) side by side.

:func:`run_jobs` runs ``job(*args)`` for every ``args`` of a list in workers started with
``spawn``, each running ``init`` once and then one job at a time; a job reports progress
with :func:`send`; results arrive in the order the jobs finish. Each worker's threads are
limited so that workers x threads fits this process's cores (:data:`THREAD_VARIABLES`,
:data:`sshade.cores.CORES_VARIABLE`). Workers never outlive the main process nor report a
Ctrl-C, and a dying worker loses only its job (``on_lost``). How, and why:
docs/layout.md, "Implementation notes: harness/jobs.py".
"""
from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import pickle
import queue
import signal
import sys
import threading
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass

from sshade.cores import CORES_VARIABLE, available_cores, pool_size
from sshade.errors import SShaDeError

__all__ = ["THREAD_VARIABLES", "GRACE_S", "JobOptions", "thread_limit", "run_jobs", "send", "in_worker",
           "death_reason"]

#: Environment variables that cap the threads of OpenBLAS, MKL, OpenMP, Accelerate, numexpr and numba.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
                    "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS")

#: Seconds a terminated worker is given to end before it is killed (SIGKILL).
GRACE_S = 3.0


@dataclass(frozen=True)
class JobOptions:
    """How :func:`run_jobs` sets up its workers and words a worker's death, checked when
    made (SShaDeError naming the field).

    thread_variables : tuple of str, default :data:`THREAD_VARIABLES`: those of its
        variables set to the workers' thread limit (the others keep this process's values);
        :data:`sshade.cores.CORES_VARIABLE` is always set to it. A list is taken as a tuple.
    what : str, default ``"build"``: the workers' purpose, in the message when a worker
        dies without ``on_lost`` or while starting (``"a build worker process died ..."``).
    advice : str, default ``"run the same command again to resume (finished items are
        kept)"``: what to do next, in that message.

    >>> JobOptions(what="evaluation").what
    'evaluation'
    """

    thread_variables: tuple[str, ...] = THREAD_VARIABLES
    what: str = "build"
    advice: str = "run the same command again to resume (finished items are kept)"

    def __post_init__(self):
        names = self.thread_variables
        if not isinstance(names, (tuple, list)) or not set(names) <= set(THREAD_VARIABLES):
            raise SShaDeError(f"JobOptions: thread_variables must be some of {THREAD_VARIABLES}, got {names!r}")
        object.__setattr__(self, "thread_variables", tuple(names))
        for name in ("what", "advice"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise SShaDeError(f"JobOptions: {name} must be a non-empty string, got {getattr(self, name)!r}")


_CHANNEL: list = [None, 0, None]  # in a worker: its connection to the main process, its pid, a send lock
_hard_exit = os._exit  # bound once: a guarded plug-in may replace os._exit meanwhile (sshade.guard)
_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def thread_limit(workers: int) -> int:
    """Threads per worker so that ``workers x threads <= available_cores()`` (>= 1)."""
    return max(1, available_cores() // max(1, int(workers)))


def in_worker() -> bool:
    """Whether this process is a worker of :func:`run_jobs` (not a process it forked)."""
    return _CHANNEL[0] is not None and _CHANNEL[1] == os.getpid()


def send(message) -> None:
    """From a job: deliver ``message`` (picklable) to ``on_message`` in the main process
    (from any thread of the worker).

    Raises
    ------
    SShaDeError outside a worker of :func:`run_jobs` (a process a worker forked included).
    """
    if not in_worker():
        raise SShaDeError("harness.jobs.send: not in a worker of run_jobs")
    _reply(("msg", message))


def death_reason(exitcode) -> str:
    """How a worker ended, from its exit code: ``"worker process died (SIGKILL)"`` for a
    signal, ``"worker process exited with status 1"`` for an exit.

    >>> death_reason(-9), death_reason(3)
    ('worker process died (SIGKILL)', 'worker process exited with status 3')
    """
    if exitcode is None:
        return "worker process vanished"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"worker process died ({name})"
    return f"worker process exited with status {exitcode}"


# ----------------------------------------------------------------------------- in a worker
def _reply(item) -> None:
    with _CHANNEL[2]:
        _CHANNEL[0].send(item)


def _set_death_signal() -> bool:
    """Linux: the kernel sends SIGKILL to this process when the thread that started it
    ends (its parent's, for our processes: the whole process). False where unavailable."""
    if not sys.platform.startswith("linux"):  # pragma: no cover
        return False
    try:
        return ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError, TypeError):  # pragma: no cover
        return False


def _watch_parent(sentinel) -> None:
    """A worker's watchdog thread: ends the worker when the main process has ended (the
    pipe ``sentinel`` reads end-of-file once the main process's end of it is closed)."""
    from multiprocessing.connection import wait
    wait([sentinel])
    _hard_exit(1)


def _forked_from_worker() -> None:
    """In a process a worker forks (a sampling pool): dies with the worker, and holds no
    copy of the worker's pipe (so the main process sees the pipe close when the worker
    dies). A worker killed before the death signal was set (this process not yet run
    since the fork) is seen by the parent's pid: this process then ends at once."""
    worker = _CHANNEL[1]
    if _set_death_signal() and worker and os.getppid() != worker:
        _hard_exit(1)
    conn = _CHANNEL[0]
    _CHANNEL[:] = [None, 0, None]
    if conn is not None:
        with contextlib.suppress(OSError):
            conn.close()


def _worker_main(conn, parent_pid: int, init, init_args) -> None:
    """A worker process: ignore SIGINT, die with the main process, ``init``, then the jobs
    the main process sends (``(job, args)``; None: end), one reply each (``("done",
    result)`` or ``("error", exception, traceback text)``), after the job's messages."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # discards a Ctrl-C pending since the start
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    _set_death_signal()
    if os.getppid() != parent_pid:  # the main process ended before the death signal was set
        _hard_exit(1)
    parent = mp.parent_process()
    if parent is not None and getattr(parent, "sentinel", None) is not None:
        threading.Thread(target=_watch_parent, args=(parent.sentinel,), daemon=True, name="sshade-watchdog").start()
    _CHANNEL[:] = [conn, os.getpid(), threading.Lock()]
    os.register_at_fork(after_in_child=_forked_from_worker)
    try:
        if init is not None:
            init(*init_args)
    except BaseException as e:  # noqa: BLE001 - reported to the main process, which raises it
        _reply(("error", *_portable(e)))
        return
    _reply(("ready",))
    while True:
        try:
            item = conn.recv()
        except (EOFError, OSError):  # the main process ended
            return
        except Exception as e:  # noqa: BLE001 - a job that cannot be unpickled here
            _reply(("error", *_portable(e)))
            continue
        if item is None:
            return
        job, args = item
        try:
            result = job(*args)
        except BaseException as e:  # noqa: BLE001 - the job's failure, raised in the main process
            _reply(("error", *_portable(e)))
            continue
        try:
            _reply(("done", result))
        except Exception as e:  # noqa: BLE001 - a result that cannot be pickled
            _reply(("error", *_portable(e)))


def _portable(e: BaseException) -> tuple:
    """``(exception, traceback text)`` that crosses to the main process: ``e`` itself
    when it pickles and unpickles, else a RuntimeError (an SShaDeError for ours) with its
    ``Type: message``. An exit (SystemExit) becomes a RuntimeError: it must not end the
    main process."""
    tb = "".join(traceback.format_exception(type(e), e, e.__traceback__))
    if isinstance(e, (Exception, KeyboardInterrupt)):
        try:
            pickle.loads(pickle.dumps(e))
            return e, tb
        except Exception:  # noqa: BLE001 - any pickling problem
            pass
    kind = SShaDeError if isinstance(e, SShaDeError) else RuntimeError
    return kind(f"{type(e).__name__}: {e} (in a worker process)"), tb


# ----------------------------------------------------------------------------- in the main process
class _RemoteTraceback(Exception):
    """The worker's traceback of an exception raised in a job (its ``__cause__``)."""

    def __str__(self):
        return f'\n"""\n{self.args[0]}"""'


@contextmanager
def _sigint_blocked():
    """SIGINT blocked in this thread (a signal meanwhile is delivered at the end)."""
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - Windows
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class _Worker:
    """A worker process, its end of the pipe (read by a thread into ``inbox``), the job it
    runs (index or None) and whether it said it is ready."""

    def __init__(self, ctx, inbox: queue.Queue, init, init_args):
        self.conn, child = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_worker_main, args=(child, os.getpid(), init, tuple(init_args)),
                                name="sshade-worker")
        try:
            with _sigint_blocked():  # inherited: no Ctrl-C reaches the worker before it ignores SIGINT
                self.proc.start()
        finally:
            child.close()
        self.index, self.ready = None, False
        self.reader = threading.Thread(target=self._read, args=(inbox,), daemon=True, name="sshade-worker-reader")
        self.reader.start()

    def _read(self, inbox: queue.Queue) -> None:
        """Every message of the worker into ``inbox`` as ``(self, message)``, then
        ``(self, None)`` once its pipe closed (it ended; a message cut short by its death
        included). A message that arrived whole but cannot be unpickled here is an error
        of the job."""
        while True:
            try:
                msg = self.conn.recv()
            except (EOFError, OSError):
                inbox.put((self, None))
                return
            except Exception as e:  # noqa: BLE001 - e.g. a result whose class this process cannot import
                msg = ("error", SShaDeError(f"a message of a worker process could not be read: {e}"), "")
            inbox.put((self, msg))

    def give(self, job, index: int, args) -> None:
        """Hand job ``index`` to the worker (from a thread: a stopped worker never blocks
        this process on a full pipe)."""
        self.index = index

        def hand():
            with contextlib.suppress(Exception):  # a worker that died meanwhile: its reader reports it
                self.conn.send((job, args))
        threading.Thread(target=hand, daemon=True, name="sshade-worker-sender").start()

    def stop(self) -> None:
        """Ask the worker to end after its current job (no effect on a dead one)."""
        with contextlib.suppress(Exception):
            self.conn.send(None)

    def close(self) -> None:
        """Release the pipe once the worker has ended and its reader has read the end."""
        self.reader.join(timeout=1.0)
        if not self.reader.is_alive():
            with contextlib.suppress(OSError):
                self.conn.close()
        with contextlib.suppress(ValueError):
            self.proc.close()


def _end_all(workers: list, *, grace: float, ask: bool) -> None:
    """End ``workers``: asked to (``ask``: after their current job), else terminated
    (continued if stopped, so that the signal acts); any still alive after ``grace``
    seconds killed; each one reaped and its pipe released."""
    for w in workers:
        if ask:
            w.stop()
        elif w.proc.exitcode is None:
            with contextlib.suppress(OSError, ValueError):
                w.proc.terminate()
                os.kill(w.proc.pid, signal.SIGCONT)
    deadline = time.monotonic() + grace
    for w in workers:
        w.proc.join(timeout=max(0.0, deadline - time.monotonic()))
        if w.proc.exitcode is None:
            with contextlib.suppress(OSError, ValueError):
                w.proc.kill()
            w.proc.join(timeout=10.0)
    for w in workers:
        w.close()


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


@contextmanager
def _deferred_signals():
    """Ctrl-C (SIGINT) and SIGTERM while jobs run are noted, and re-delivered by the
    pool's loop at a safe point (``hit`` non-empty: call :func:`_deliver`), never in the
    middle of its bookkeeping. A signal whose handler is not a Python function
    (ignored, or the default) keeps it; off the main thread nothing changes. The
    previous handlers are restored."""
    hit: list = []
    if threading.current_thread() is not threading.main_thread():
        yield hit
        return
    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s, h in old.items():
        if callable(h):
            signal.signal(s, lambda signum, frame, h=h: hit.append((h, signum, frame)))
    try:
        yield hit
    finally:
        for s, h in old.items():
            if callable(h):
                signal.signal(s, h)


def _deliver(hit: list) -> None:
    """Run the handlers the deferred signals were meant for, in order (run_command's
    raise KeyboardInterrupt). A SIGINT handler that returns still stops the jobs
    (KeyboardInterrupt); a SIGTERM handler that returns (a scheduler's that ignores it)
    lets them go on."""
    pending = list(hit)
    hit.clear()
    for handler, signum, frame in pending:
        handler(signum, frame)
        if signum == signal.SIGINT:
            raise KeyboardInterrupt


def run_jobs(job, args_list, *, workers: int, init=None, init_args=(), on_message=None, on_result=None,
             on_lost=None, options: JobOptions | None = None) -> None:
    """Run ``job(*args)`` for every ``args`` in ``args_list`` in ``workers`` spawned processes.

    A job is handed out only when a worker is free, so that after a failure or Ctrl-C
    no new job starts; on Ctrl-C, SIGTERM (see :func:`_deferred_signals`) or any
    exception in this process the workers are ended (terminated, then killed after
    :data:`GRACE_S` seconds) before it propagates.

    Parameters
    ----------
    job : a module-level function (picklable by reference); its arguments and result picklable.
    args_list : list of tuples. workers : int >= 1, processes (capped at ``len(args_list)``).
    init, init_args : run once in every worker before its first job (module-level function).
    on_message : called in this process with every :func:`send` message, while jobs run.
    on_result : called in this process as ``on_result(index, result)`` when a job finishes.
    on_lost : called in this process as ``on_lost(index, reason)`` when the worker running
        job ``index`` dies (``reason``: :func:`death_reason`, e.g. ``"worker process died
        (SIGKILL)"``); returns the arguments of a job to run in its place under the same
        index (e.g. the items it had not reached), or None. None: a dying worker is an error.
    options : :class:`JobOptions` or None (its defaults): the thread variables set in the
        workers, and the words of the message when a worker dies without ``on_lost`` or
        while starting.

    Raises
    ------
    The first failing job's exception (after the jobs already running have finished, so
    that their work is kept; the others are not started), with the worker's traceback as
    its ``__cause__``; what ``init`` raised; SShaDeError if a worker process dies while
    starting, or while running a job without ``on_lost``; KeyboardInterrupt (a job's
    own, or Ctrl-C / SIGTERM) after the workers are ended.

    Example::

        run_jobs(square, [(1,), (2,)], workers=2, on_result=lambda i, r: print(i, r))
    """
    if not len(args_list):
        return
    options = JobOptions() if options is None else options
    n = pool_size(workers, len(args_list))
    pool = _Pool(job, n, init, tuple(init_args), on_message, on_result, on_lost, options.what, options.advice)
    pool.todo = [(i, tuple(a)) for i, a in enumerate(args_list)][::-1]
    finished = False
    with _thread_env(thread_limit(n), (*options.thread_variables, CORES_VARIABLE)), _deferred_signals() as hit:
        try:
            pool.run(hit)
            finished = True
        finally:  # Ctrl-C, SIGTERM or an error here: terminate the workers now, mid-job
            _end_all(pool.workers, grace=GRACE_S, ask=finished)
    if pool.errors:
        raise pool.errors[0]


class _Pool:
    """:func:`run_jobs`'s workers and bookkeeping: ``todo`` (a stack of ``(index,
    args)``), ``workers`` (:class:`_Worker`), ``errors``."""

    def __init__(self, job, n, init, init_args, on_message, on_result, on_lost, what, advice):
        self.job, self.n, self.init, self.init_args = job, n, init, init_args
        self.on_message, self.on_result, self.on_lost = on_message, on_result, on_lost
        self.what, self.advice = what, advice
        self.ctx = mp.get_context("spawn")
        self.inbox: queue.Queue = queue.Queue()
        self.todo: list = []
        self.workers: list[_Worker] = []
        self.errors: list = []

    def busy(self) -> int:
        return sum(w.index is not None for w in self.workers)

    def run(self, hit: list) -> None:
        """Hand out the jobs and handle the workers' messages until every job has ended
        (or, after an error, the running ones)."""
        while (self.todo and not self.errors) or self.busy():
            if hit:
                _deliver(hit)
            want = 0 if self.errors else min(self.n, len(self.todo) + self.busy())
            while len(self.workers) < want:
                self.workers.append(_Worker(self.ctx, self.inbox, self.init, self.init_args))
            for w in self.workers:
                if w.ready and w.index is None and self.todo and not self.errors:
                    w.give(self.job, *self.todo.pop())
            try:
                w, msg = self.inbox.get(timeout=0.25)
            except queue.Empty:
                continue
            while True:
                if hit:
                    _deliver(hit)
                self._handle(w, msg)
                try:
                    w, msg = self.inbox.get_nowait()
                except queue.Empty:
                    break
        if hit:
            _deliver(hit)

    def _handle(self, w: _Worker, msg) -> None:
        """One message of worker ``w`` (None: its pipe closed); none of a retired worker."""
        if w not in self.workers:
            return
        if msg is None:
            self._ended(w)
        elif msg[0] == "msg":
            if self.on_message is not None:
                self.on_message(msg[1])
        elif msg[0] == "ready":
            w.ready = True
        elif msg[0] == "done":
            i, w.index = w.index, None
            if self.on_result is not None:
                self.on_result(i, msg[1])
        elif msg[0] == "error":
            exc, tb = msg[1], msg[2]
            exc.__cause__ = _RemoteTraceback(tb)
            if isinstance(exc, KeyboardInterrupt):  # a job's own KeyboardInterrupt: stop now
                raise exc
            self.errors.append(exc)
            if w.index is None:  # init failed: this worker takes no job
                self._retire(w)
            w.index = None

    def _retire(self, w: _Worker) -> None:
        self.workers.remove(w)
        _end_all([w], grace=GRACE_S, ask=False)

    def _ended(self, w: _Worker) -> None:
        """Worker ``w``'s pipe closed: it died (or cut a message short). Its job, if any,
        is lost (``on_lost``, or an error); a worker that died before it was ready is an
        error (no new worker is started for it)."""
        w.proc.join(timeout=5.0)
        reason = death_reason(w.proc.exitcode)
        i, ready = w.index, w.ready
        self._retire(w)
        if not ready:
            self.errors.append(SShaDeError(f"{_a(self.what)} {reason} while starting; {self.advice}"))
        elif i is not None and self.on_lost is not None:
            again = self.on_lost(i, reason)
            if again is not None:
                self.todo.append((i, tuple(again)))
        elif i is not None:
            self.errors.append(SShaDeError(f"{_a(self.what)} {reason}; {self.advice}"))


def _a(word: str) -> str:
    """``word`` after its indefinite article: ``"a build"``, ``"an evaluation"``."""
    return f"{'an' if word[:1].lower() in 'aeiou' else 'a'} {word}"

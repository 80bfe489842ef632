"""The ``cases`` experiment's runs side by side: whole cases in worker processes.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md.

Example::

    python -m eval jobs=2            # two cases at a time, one core each (2 cores)"""
from __future__ import annotations

import logging
from dataclasses import dataclass

from eval import method_config as method_table
from eval.experiments.cases.case_references import CaseReferences
from eval.experiments.cases.pair import run_and_store, run_pair
from eval.experiments.cases.reference_cutoff import scored_against
from eval.metrics.meshes import CaseMeshes
from eval.run.jsonsafe import json_safe
from eval.run.outdir import resume_command
from eval.run.paths import abs_path
from eval.run.result_store import ResultStore
from eval.run.spec import MethodSpec, ReferenceOptions
from harness.jobs import JobOptions, in_worker, run_jobs, send, thread_limit
from sshade.cores import available_cores, pool_size
from sshade.errors import SShaDeError

__all__ = ["AUTO_MIN_S", "WorkerSetup", "check_jobs", "job_count", "describe", "run_case_jobs", "init_worker",
           "case_job",
           "lost_record"]

log = logging.getLogger("eval")

#: ``jobs: auto`` runs workers only when the runs to do are estimated at this many
#: seconds or more (a spawned worker imports the stack and compiles its kernels: ~5 s).
AUTO_MIN_S = 120.0

_W: dict = {}  # a worker's state: its methods, reference options, guard, store, metric meshes


def check_jobs(value) -> int | None:
    """``jobs`` (module docstring) checked: an integer from 1 to 1024, or
    None for ``auto`` / null.

    Raises
    ------
    SShaDeError for any other value.

    >>> check_jobs("auto"), check_jobs(2)
    (None, 2)
    """
    if value is None or (isinstance(value, str) and value.strip().lower() == "auto"):
        return None
    if isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 1024:
        return value
    raise SShaDeError(f"jobs must be an integer from 1 to 1024 or auto, got {value!r}")


def job_count(value, *, cases: int, estimate_s: float) -> int:
    """The worker count of ``jobs`` = ``value``: an integer >= 1 or ``"auto"`` (module
    docstring), at most ``cases`` (the cases with runs to do), at least 1.

    Raises
    ------
    SShaDeError for any other value.

    >>> job_count("auto", cases=40, estimate_s=10.0), job_count(4, cases=3, estimate_s=0)
    (1, 3)
    """
    n = check_jobs(value)  # eval.config_check.check_config refuses a bad value first, before any work
    if n is None:  # auto
        n = available_cores() if estimate_s >= AUTO_MIN_S and cases >= 2 else 1
    return pool_size(n, max(int(cases), 1))


def describe(jobs: int) -> str:
    """``"2 runs at a time, 1 core each"`` for ``jobs`` > 1, else ``""``."""
    if jobs <= 1:
        return ""
    t = thread_limit(jobs)
    return f"{jobs} runs at a time, {t} core{'s' if t != 1 else ''} each"


class _Forward(logging.Handler):
    """In a worker: every record of the ``eval`` logger to the main process."""

    def emit(self, record):  # noqa: D401
        try:
            send(("log", record.levelno, record.name, record.getMessage()))
        except Exception:  # noqa: BLE001 - a log line never stops a run
            pass


@dataclass(frozen=True)
class WorkerSetup:
    """What each worker of :func:`run_case_jobs` builds its state from (sent to it once):
    the methods' entries (built again in the worker, plug-ins included), the reference
    options, the guard (:meth:`eval.run.spec.GuardOptions.as_dict`), the run's folder and
    ``store.meshes``."""

    methods: tuple[MethodSpec, ...]
    reference: ReferenceOptions
    guard: dict
    out_dir: str
    store_meshes: bool = False


def init_worker(setup: WorkerSetup) -> None:
    """A worker's setup (once, before its first case): its methods built from ``setup``
    (:func:`eval.method_config.make_methods`, plug-ins included), the reference options,
    guard, result store, and its log records forwarded."""
    lg = logging.getLogger("eval")
    lg.handlers[:] = [_Forward()]
    lg.setLevel(logging.INFO)
    lg.propagate = False
    methods, refs = method_table.make_methods(setup.methods), CaseReferences(setup.reference)
    store = ResultStore(abs_path(setup.out_dir), meshes=setup.store_meshes, annotate=scored_against(refs, methods))
    _W.update(methods=methods, refs=refs, guard=dict(setup.guard), store=store, meshes=CaseMeshes())


def case_job(ci: int, case, pairs, ref_on: bool, want_meshes: bool) -> dict:
    """In a worker: the methods ``pairs`` (``(mi, key, key_fields)``, in table order) on
    case ``ci``, each stored as it finishes. Sends ``("start", ci, mi)`` as each pair
    starts and ``("pair", ci, mi, seconds, seconds less compilation, record, U or None)``
    as it ends (:func:`harness.jobs.send`). Returns ``{"ci", "references_s"}``."""
    w = _W
    w["refs"].start_case(ci, case, ref_on)
    ref0 = w["refs"].computed_s
    for mi, key, fields in pairs:
        send(("start", ci, mi))
        m = w["methods"][mi]
        rec, U, wall, cost_s = run_and_store(m, m.name, case, w["refs"], w["guard"], w["meshes"], w["store"], key,
                                             fields, extra={"cores": available_cores()})
        send(("pair", ci, mi, wall, cost_s, rec, U if want_meshes else None))
    return {"ci": ci, "references_s": w["refs"].computed_s - ref0}


class _Lost:
    """Stands in for a method whose worker process died while it ran: fails with
    ``message``, so that its row is the one :func:`eval.experiments.cases.pair.run_pair` writes
    for any failed run."""

    def __init__(self, name: str, message: str):
        self.name, self.message = name, message

    def deform(self, V, F, handles, targets):
        raise SShaDeError(self.message)


def lost_record(case, name: str, reason: str, cores: int) -> dict:
    """The record (``row``, ``info``, ``case``, ``method``) of method ``name`` on ``case``
    when its worker died (``reason``, :func:`harness.jobs.death_reason`): a failed row
    whose ``error`` is ``"<reason> while running this pair"``. Never stored: a resume
    runs the pair again."""
    row, _, _ = run_pair(_Lost(name, f"{reason} while running this pair"), name, case, None,
                         {"timeout_s": None, "handle_error_max_pct": None})
    row["cores"] = cores
    return {"row": json_safe(row), "info": {}, "case": case.name, "method": name}


class _Cases:
    """The main process's side of :func:`run_case_jobs`: each job's case arguments (a job
    lost with its worker continues with the pairs it had not reached), the pairs each
    case finished, the pair each case is running, the pairs lost."""

    def __init__(self, tasks, names: list, jobs: int, on_pair, on_case):
        self.tasks, self.names, self.cores = list(tasks), names, thread_limit(jobs)
        self.on_pair, self.on_case = on_pair, on_case
        self.got: dict = {}  # ci -> [(mi, record, U or None), ...]
        self.running: dict = {}  # ci -> mi
        self.lost: list = []  # (case name, method name, reason)
        self.references_s = 0.0

    def message(self, msg) -> None:
        if msg[0] == "log":
            logging.getLogger(msg[2]).log(msg[1], msg[3])
        elif msg[0] == "start":
            self.running[msg[1]] = msg[2]
        elif msg[0] == "pair":
            ci, mi, wall, cost_s, rec, U = msg[1:]
            self.running.pop(ci, None)
            self.got.setdefault(ci, []).append((mi, rec, U))
            self.on_pair(ci, mi, wall, cost_s)

    def result(self, _i: int, res: dict) -> None:
        self.references_s += float(res.get("references_s") or 0.0)
        self.on_case(res["ci"], self.got.pop(res["ci"], []))

    def lost_job(self, i: int, reason: str):
        """Job ``i``'s worker died: the pair it ran fails (its row names ``reason``), the
        pairs it had not reached run in a fresh worker (returned: the job's new
        arguments), or the case ends here when none is left."""
        ci, case, pairs, ref_on, want = self.tasks[i]
        mi = self.running.pop(ci, None)
        got = self.got.setdefault(ci, [])
        if mi is not None:
            name = self.names[mi]
            got.append((mi, lost_record(case, name, reason, self.cores), None))
            self.lost.append((case.name, name, reason))
            self.on_pair(ci, mi, 0.0, None)
        finished = {m for m, _, _ in got}
        rest = [p for p in pairs if p[0] not in finished]
        if rest:
            self.tasks[i] = (ci, case, rest, ref_on, want)
            return self.tasks[i]
        self.on_case(ci, self.got.pop(ci))
        return None


def run_case_jobs(setup: WorkerSetup, tasks, *, jobs: int, on_pair, on_case, names=None) -> float:
    """Run ``tasks`` in ``jobs`` worker processes (:func:`harness.jobs.run_jobs`).

    A worker that dies (killed, out of memory, a plug-in's crash in compiled code) fails
    the pair it was running: its row's ``error`` names the signal
    (:func:`lost_record`; the row is not stored, so ``resume=true`` runs it again), the
    case's other pairs run in a fresh worker, and the run goes on; the pairs lost are
    listed at the end with the command that runs them again.

    Parameters
    ----------
    setup : what each worker builds its methods, references, guard and store from.
    tasks : list of ``(ci, case, pairs, ref_on, want_meshes)`` (:func:`case_job`'s
        arguments), in the order they are handed out (costliest first).
    on_pair : called ``on_pair(ci, mi, seconds, cost_s)`` as each pair ends (``cost_s``:
        the seconds less the method's one-off compilation; None for a pair lost with its worker).
    on_case : called ``on_case(ci, [(mi, record, U or None), ...])`` as each case ends.
    names : the methods' names, by index (for a lost pair's row); default: built from ``setup``.

    Returns
    -------
    float, the seconds the workers spent computing references.

    Raises
    ------
    SShaDeError when a worker dies while starting (finished pairs stay stored: the
    message gives the command that continues the run); KeyboardInterrupt after the
    workers are ended.
    """
    if in_worker():  # pragma: no cover - never nested
        raise SShaDeError("eval: jobs > 1 inside a worker")
    if names is None:
        names = [m.name for m in method_table.make_methods(setup.methods)]
    again = resume_command(setup.out_dir)
    c = _Cases(tasks, list(names), jobs, on_pair, on_case)
    run_jobs(case_job, c.tasks, workers=jobs, init=init_worker, init_args=(setup,), on_message=c.message,
             on_result=c.result, on_lost=c.lost_job,
             options=JobOptions(what="evaluation", advice=f"the finished runs are stored; to continue: {again}"))
    if c.lost:
        log.warning("%d run(s) failed with their worker process: %s; their rows are not stored, to run them "
                    "again: %s", len(c.lost), "; ".join(f"{a} {b}: {r}" for a, b, r in c.lost), again)
    return c.references_s

"""The ``cases`` experiment's runs side by side (issue 23): whole cases in worker processes.

``jobs`` (config) worker processes (:func:`sshade.jobs.run_jobs`: spawned, each with
``cores / jobs`` threads) take the cases with runs to do, the costliest first (their
estimated seconds, :class:`eval.progress.CostModel`); a worker runs a case's methods in
table order (:func:`eval.experiments.pair.run_pair`), so that a reference solution still
continues from the method on its energy's path (:class:`~eval.experiments.case_references.CaseReferences`),
and stores each pair as soon as it finishes (:class:`eval.store.ResultStore`), as the
one-process loop does. The main process gets every pair's seconds as it ends (the
progress bar), every log record of the workers (``eval.log`` and the console) and each
finished case's rows (and deformed meshes, for the figures and 3D views of the first
cases). Results do not depend on ``jobs``; timings do: each run has ``cores / jobs``
cores (the row's ``cores`` column, set only for runs made in a worker; the table's
title says so).

``jobs: auto`` (the default) takes one worker per core when the runs to do are estimated
at :data:`AUTO_MIN_S` seconds or more and there are at least two cases, else runs in
this process (a worker costs a few seconds to start). ``jobs: 1`` always runs in this
process: ``python -m eval.reproduce`` does that, so that ``results/`` times every method
on the whole machine.

Example::

    python -m eval jobs=2            # two cases at a time, one core each (2 cores)
"""
from __future__ import annotations

import logging

from sshade.errors import SShaDeError
from sshade.jobs import available_cores, in_worker, pool_size, run_jobs, send, thread_limit

from .. import methods as method_table
from ..config_check import check_jobs
from ..metric_meshes import CaseMeshes
from ..paths import abs_path
from ..store import ResultStore
from .case_references import CaseReferences
from .pair import guard_options, run_and_store

__all__ = ["AUTO_MIN_S", "job_count", "describe", "run_case_jobs", "init_worker", "case_job"]

log = logging.getLogger("eval")

#: ``jobs: auto`` runs workers only when the runs to do are estimated at this many
#: seconds or more (a spawned worker imports the stack and compiles its kernels: ~5 s).
AUTO_MIN_S = 120.0

_W: dict = {}  # a worker's state: its methods, reference options, guard, store, metric meshes


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


def init_worker(config: dict) -> None:
    """A worker's setup (once, before its first case): the config (a resolved mapping),
    its methods built from it (:func:`eval.methods.make_methods`, plug-ins included), the
    reference options, guard, result store, and its log records forwarded."""
    from omegaconf import OmegaConf

    lg = logging.getLogger("eval")
    lg.handlers[:] = [_Forward()]
    lg.setLevel(logging.INFO)
    lg.propagate = False
    cfg = OmegaConf.create(config)
    _W.update(methods=method_table.make_methods(cfg), refs=CaseReferences(cfg), guard=guard_options(cfg),
              store=ResultStore(abs_path(cfg.out_dir), meshes=bool((cfg.get("store") or {}).get("meshes", False))),
              meshes=CaseMeshes())


def case_job(ci: int, case, pairs, ref_on: bool, want_meshes: bool) -> dict:
    """In a worker: the methods ``pairs`` (``(mi, key, key_fields)``, in table order) on
    case ``ci``, each stored as it finishes and its seconds sent to the main process
    (``("pair", ci, mi, seconds, seconds less compilation)``). Returns ``{"ci", "pairs": [(mi, record,
    U or None), ...], "references_s"}``."""
    w = _W
    w["refs"].start_case(ci, case, ref_on)
    ref0, out = w["refs"].computed_s, []
    for mi, key, fields in pairs:
        m = w["methods"][mi]
        rec, U, wall, cost_s = run_and_store(m, m.name, case, w["refs"], w["guard"], w["meshes"], w["store"], key,
                                             fields, extra={"cores": available_cores()})
        send(("pair", ci, mi, wall, cost_s))
        out.append((mi, rec, U if want_meshes else None))
    return {"ci": ci, "pairs": out, "references_s": w["refs"].computed_s - ref0}


def run_case_jobs(config: dict, tasks, *, jobs: int, on_pair, on_case) -> float:
    """Run ``tasks`` in ``jobs`` worker processes (:func:`sshade.jobs.run_jobs`).

    Parameters
    ----------
    config : the run's config as a resolved mapping (each worker builds its methods from it).
    tasks : list of ``(ci, case, pairs, ref_on, want_meshes)`` (:func:`case_job`'s
        arguments), in the order they are handed out (costliest first).
    on_pair : called ``on_pair(ci, mi, seconds, cost_s)`` as each pair ends (``cost_s``:
        the seconds less the method's one-off compilation).
    on_case : called ``on_case(ci, [(mi, record, U or None), ...])`` as each case ends.

    Returns
    -------
    float, the seconds the workers spent computing references.

    Raises
    ------
    SShaDeError when a worker dies (finished pairs stay stored: resume=true continues);
    KeyboardInterrupt after the workers are stopped.
    """
    if in_worker():  # pragma: no cover - never nested
        raise SShaDeError("eval: jobs > 1 inside a worker")
    refs_s = [0.0]

    def message(msg):
        if msg[0] == "log":
            logging.getLogger(msg[2]).log(msg[1], msg[3])
        elif msg[0] == "pair":
            on_pair(*msg[1:])

    def result(_i, res):
        refs_s[0] += float(res.get("references_s") or 0.0)
        on_case(res["ci"], res["pairs"])

    run_jobs(case_job, tasks, workers=jobs, init=init_worker, init_args=(config,), on_message=message,
             on_result=result, what="evaluation")
    return refs_s[0]

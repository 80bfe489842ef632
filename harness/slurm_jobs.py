"""SLURM jobs submitted through submitit, waited on until each has an outcome: its result,
its error, or killed (OOM, time limit, node lost, scancel, kill -9), with or without
``sacct``; used by the sweeps (:mod:`eval.sweeps.launcher`) and the ``cases`` experiment's
job array (:mod:`eval.experiments.cases.case_array`). Reads SLURM with its commands
(``sacct``, ``squeue``, ``scontrol``); submits nothing itself."""
from __future__ import annotations

import logging
import re
import shutil
import subprocess
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

__all__ = ["ACTIVE_STATES", "SlurmQueryError", "slurm_states", "expand_job_ids", "JobOutcome", "wait_for_jobs",
           "state_text", "killed_message"]

log = logging.getLogger(__name__)

#: SLURM job states of a job that is queued or still running (``squeue --states``).
ACTIVE_STATES = frozenset({"PENDING", "CONFIGURING", "RUNNING", "COMPLETING", "SUSPENDED", "REQUEUED",
                           "REQUEUE_FED", "REQUEUE_HOLD", "RESIZING", "SIGNALING", "STAGE_OUT", "STOPPED",
                           "RESV_DEL_HOLD", "POWER_UP_NODE", "SPECIAL_EXIT"})


class SlurmQueryError(RuntimeError):
    """SLURM could not be asked (``squeue`` missing or failing for another reason than
    jobs that left the queue)."""


def expand_job_ids(spec: str) -> list[str]:
    """``"16_[1-3,5%2]"`` -> ``["16_1", "16_2", "16_3", "16_5"]`` (the form ``sacct`` and
    ``squeue`` print for pending array tasks); any other id is returned as is."""
    m = re.fullmatch(r"(\d+)_\[([^\]]*)\]", spec.strip())
    if not m:
        return [spec.strip()]
    out = []
    for part in m.group(2).split("%", 1)[0].split(","):
        lo, _, hi = part.partition("-")
        if lo.isdigit() and (not hi or hi.isdigit()):
            out += [f"{m.group(1)}_{i}" for i in range(int(lo), int(hi or lo) + 1)]
    return out


def _run(cmd: list[str], runner) -> tuple[int, str, str] | None:
    """(returncode, stdout, stderr) of ``cmd``, None when the program is not installed."""
    if runner is None and shutil.which(cmd[0]) is None:
        return None
    try:
        r = (runner or subprocess.run)(cmd, capture_output=True, text=True, timeout=60)
    except FileNotFoundError:
        return None
    except subprocess.TimeoutExpired:
        return 1, "", f"{cmd[0]} timed out"
    return r.returncode, r.stdout or "", r.stderr or ""


def _parse_pairs(text: str) -> dict[str, str]:
    """``id|STATE ...`` lines -> {id: STATE} (array ranges expanded; ``CANCELLED by 0`` ->
    ``CANCELLED``)."""
    out = {}
    for line in text.splitlines():
        if "|" not in line:
            continue
        jid, state = line.split("|", 1)
        state = (state.split() or [""])[0].rstrip("+")
        for j in expand_job_ids(jid):
            out[j] = state
    return out


def slurm_states(job_ids: Sequence[str], *, runner: Callable | None = None) -> dict[str, str | None]:
    """Current SLURM state of each job id (``"16_1"`` for task 1 of array 16).

    ``sacct -X`` first (when accounting works); for the ids it does not know (no
    accounting: ``sacct`` exits non-zero; or not recorded yet) ``squeue`` (queued or
    running jobs), then ``scontrol show job`` (jobs that ended in the last
    ``MinJobAge`` seconds, 300 by default). None: SLURM knows nothing of the job any
    more (neither queued, running nor recently ended).

    Parameters
    ----------
    job_ids : the ids as submitit reports them (``job.job_id``).
    runner : ``subprocess.run``-like callable (tests); default runs the SLURM commands.

    Returns
    -------
    dict id -> state (``RUNNING``, ``PENDING``, ``COMPLETED``, ``FAILED``, ``CANCELLED``,
    ``OUT_OF_MEMORY``, ``TIMEOUT``, ``NODE_FAIL``, ...) or None.

    Raises
    ------
    SlurmQueryError when ``squeue`` is not installed or fails (controller unreachable).
    """
    ids = [str(j) for j in job_ids]
    states: dict[str, str | None] = {}
    r = _run(["sacct", "-n", "-P", "-X", "-o", "JobID,State", "-j", ",".join(ids)], runner)
    if r is not None and r[0] == 0:
        got = _parse_pairs(r[1])
        states.update({j: got[j] for j in ids if got.get(j)})
    rest = [j for j in ids if j not in states]
    if not rest:
        return states
    parents = sorted({j.split("_", 1)[0] for j in rest})
    r = _run(["squeue", "-h", "-r", "-o", "%i|%T", "-j", ",".join(parents)], runner)
    if r is None:
        raise SlurmQueryError("squeue not found: is this a SLURM cluster?")
    if r[0] != 0 and "invalid job id" not in r[2].lower():
        raise SlurmQueryError(f"squeue failed: {r[2].strip() or r[1].strip()}")
    queued = _parse_pairs(r[1]) if r[0] == 0 else {}
    for j in rest:
        if j in queued:
            states[j] = queued[j]
            continue
        sc = _run(["scontrol", "-o", "show", "job", j], runner)
        m = re.search(r"\bJobState=(\S+)", sc[1]) if sc is not None and sc[0] == 0 else None
        states[j] = m.group(1) if m else None
    return states


@dataclass
class JobOutcome:
    """How a submitted job ended: ``kind`` ``result`` (``value``: what the job returned),
    ``error`` (``value``: the traceback text of an exception raised in the job) or
    ``killed`` (no result; ``state``: SLURM's last known state, None when gone)."""

    kind: str
    value: object = None
    state: str | None = None


def _load_result(job) -> JobOutcome | None:
    """The job's result pickle as a :class:`JobOutcome`, None while it is absent or
    still being written."""
    p = Path(job.paths.result_pickle)
    if not p.exists():
        return None
    try:
        from submitit.core.utils import pickle_load
        tag, value = pickle_load(p)
    except Exception:  # noqa: BLE001 -- partly written: read it at the next poll
        return None
    return JobOutcome("result" if tag == "success" else "error", value)


def wait_for_jobs(jobs: Sequence, *, states: Callable = slurm_states, poll_s: float = 10.0,
                  grace_polls: int = 2, unreachable_s: float = 1800.0, sleep: Callable = time.sleep,
                  clock: Callable = time.monotonic, report: Callable | None = None) -> list[JobOutcome]:
    """Wait until every job has an outcome; never raises for a job and never waits on
    a job that SLURM no longer runs.

    A job is over when its result pickle exists (``result`` or ``error``), or when for
    ``grace_polls`` polls in a row it has no result and is neither queued nor running
    (``states`` gives a state outside :data:`ACTIVE_STATES`, or None): ``killed``. The
    grace polls let a result written on a shared file system appear. If ``states``
    raises :class:`SlurmQueryError` for ``unreachable_s`` seconds in a row, the jobs
    still without result are reported killed (state ``UNREACHABLE``).

    Parameters
    ----------
    jobs : submitit jobs (``job_id``, ``paths.result_pickle``).
    states : ``(job_ids) -> {id: state or None}`` (:func:`slurm_states`).
    poll_s : seconds between polls. report : called as ``report(index, outcome)`` when a
        job's outcome is known (e.g. to log it at once).

    Returns
    -------
    list of :class:`JobOutcome`, in the order of ``jobs``.
    """
    out: list[JobOutcome | None] = [None] * len(jobs)
    strikes = [0] * len(jobs)
    failing_since = None
    while True:
        left = [i for i, o in enumerate(out) if o is None]
        for i in left:
            out[i] = _load_result(jobs[i])
            if out[i] is not None and report:
                report(i, out[i])
        left = [i for i in left if out[i] is None]
        if not left:
            return out  # type: ignore[return-value]
        try:
            st = states([str(jobs[i].job_id) for i in left])
            failing_since = None
        except SlurmQueryError as e:
            now = clock()
            failing_since = now if failing_since is None else failing_since
            log.warning("cannot query SLURM (%s); %d job(s) without result", e, len(left))
            if now - failing_since >= unreachable_s:
                for i in left:
                    out[i] = JobOutcome("killed", state="UNREACHABLE")
                    if report:
                        report(i, out[i])
                continue
            sleep(poll_s)
            continue
        for i in left:
            s = st.get(str(jobs[i].job_id))
            if s in ACTIVE_STATES:
                strikes[i] = 0
                continue
            strikes[i] += 1
            if strikes[i] >= grace_polls and _load_result(jobs[i]) is None:
                out[i] = JobOutcome("killed", state=s)
                if report:
                    report(i, out[i])
        if any(o is None for o in out):
            sleep(poll_s)


def state_text(state: str | None, job_id: str) -> str:
    """``"SLURM state TIMEOUT, job 16_1"``, or ``"no longer known to SLURM, job 16_1"`` for
    ``state`` None."""
    return f"{f'SLURM state {state}' if state else 'no longer known to SLURM'}, job {job_id}"


def killed_message(state: str | None, job_id: str) -> str:
    """The error text of job ``job_id`` that died without a result, naming the likely
    cause from its last known SLURM ``state`` (None: gone from SLURM), e.g. ``"died without
    a result (SLURM state TIMEOUT, job 16_1): time limit"``."""
    why = {"OUT_OF_MEMORY": "out of memory", "TIMEOUT": "time limit", "NODE_FAIL": "node failure",
           "CANCELLED": "cancelled", "PREEMPTED": "preempted", "BOOT_FAIL": "node boot failure",
           "DEADLINE": "deadline", "UNREACHABLE": "SLURM unreachable"}.get(state or "", "")
    why = why or "killed, OOM, time limit, node lost or cancelled"
    return f"died without a result ({state_text(state, job_id)}): {why}"

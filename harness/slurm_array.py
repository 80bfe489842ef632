"""A job array through submitit (``cluster=slurm``, or its local executor): the checked
``cluster`` options (:class:`ClusterOptions`, :func:`cluster_options`), the executor with
each task's threads capped (:func:`array_executor`), and :func:`run_array`, which submits,
waits for every task's outcome (:func:`harness.slurm_jobs.wait_for_jobs`) and cancels the
tasks left on Ctrl-C or SIGTERM. Used by the evaluator's table
(:mod:`eval.experiments.cases.case_array`) and the DeFAUST builder (:mod:`defaust.build`)."""
from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from harness.checks import check_fields, checked_field
from harness.jobs import THREAD_VARIABLES
from harness.slurm_jobs import JobOutcome, slurm_states, wait_for_jobs
from sshade.cores import CORES_VARIABLE
from sshade.errors import SShaDeError

__all__ = ["EXECUTORS", "ClusterOptions", "cluster_options", "thread_caps", "array_executor", "run_array"]

log = logging.getLogger(__name__)

#: ``cluster.executor``: submitit's SLURM executor, or its local one (every task a process
#: on this machine: the same path without a cluster, for checks).
EXECUTORS = ("slurm", "local")


@dataclass(frozen=True)
class ClusterOptions:
    """The ``cluster`` section (``conf/cluster/slurm.yaml`` says what each key does), its
    numbers checked and coerced when made (:func:`harness.checks.check_fields`; SShaDeError
    naming ``cluster.<key>``), the other keys by :func:`cluster_options`."""

    executor: str
    partition: str | None
    account: str | None
    qos: str | None
    timeout_min: int = checked_field(int, min=1)
    cpus_per_task: int = checked_field(int, min=1, max=4096)
    mem_gb: float | None = checked_field(float, min=0.001, allow_none=True)
    array_parallelism: int = checked_field(int, min=1)
    setup: tuple[str, ...]
    additional_parameters: Mapping
    folder: str
    poll_s: float = checked_field(float, min=0.01)
    grace_polls: int = checked_field(int, min=1, max=1000)
    unreachable_s: float = checked_field(float, min=0)

    def __post_init__(self):
        check_fields(self, "cluster")


def _text(values: Mapping, key: str, *, allow_none: bool = True) -> str | None:
    """``values[key]``: a non-empty string (or None when allowed); SShaDeError naming ``cluster.<key>``."""
    v = values.get(key)
    if v is None and allow_none:
        return None
    if not isinstance(v, str) or not v.strip():
        raise SShaDeError(f"cluster.{key} must be a non-empty string{' or null' if allow_none else ''}, got {v!r}")
    return v


def cluster_options(values) -> ClusterOptions | None:
    """The ``cluster`` section's plain values checked and typed (the ``cases``
    experiment's own options, :func:`eval.experiments.register_experiment`; the builder's
    ``cluster`` section).

    Parameters
    ----------
    values : mapping of every key of :class:`ClusterOptions` (``conf/cluster/slurm.yaml``),
        or None (no ``cluster``: the pairs run here).

    Returns
    -------
    :class:`ClusterOptions`, or None for ``values`` None.

    Raises
    ------
    SShaDeError naming the first absent or bad key (``folder`` must be a relative path
    inside the output folder).
    """
    if values is None:
        return None
    if not isinstance(values, Mapping):
        raise SShaDeError(f"cluster must be a mapping (cluster=slurm), got {values!r}")
    missing = [k for k in ClusterOptions.__dataclass_fields__ if k not in values]
    if missing:
        raise SShaDeError(f"cluster.{missing[0]} is not set (cluster=slurm sets every key)")
    if values["executor"] not in EXECUTORS:
        raise SShaDeError(f"cluster.executor must be one of {list(EXECUTORS)}, got {values['executor']!r}")
    folder = PurePosixPath(str(_text(values, "folder", allow_none=False)))
    if folder.is_absolute() or ".." in folder.parts or str(folder) in ("", "."):
        raise SShaDeError(f"cluster.folder must be a folder inside the output folder (a relative path), "
                          f"got {str(folder)!r}")
    setup = values["setup"] or ()
    extra = values["additional_parameters"] or {}
    if not isinstance(setup, (list, tuple)) or not all(isinstance(x, str) for x in setup):
        raise SShaDeError(f"cluster.setup must be a list of shell lines or null, got {setup!r}")
    if setup and values["executor"] == "local":  # a shell between this process and the task: Ctrl-C would miss it
        raise SShaDeError("cluster.setup is for SLURM tasks; the local executor's tasks take this process's "
                          "environment (set it before the command)")
    if not isinstance(extra, Mapping) or not all(isinstance(k, str) for k in extra):
        raise SShaDeError(f"cluster.additional_parameters must be a mapping of sbatch options, got {extra!r}")
    return ClusterOptions(  # the numbers as given: ClusterOptions checks them
        executor=values["executor"], partition=_text(values, "partition"), account=_text(values, "account"),
        qos=_text(values, "qos"), timeout_min=values["timeout_min"], cpus_per_task=values["cpus_per_task"],
        mem_gb=values["mem_gb"], array_parallelism=values["array_parallelism"], setup=tuple(setup),
        additional_parameters=dict(extra), folder=folder.as_posix(), poll_s=values["poll_s"],
        grace_polls=values["grace_polls"], unreachable_s=values["unreachable_s"])


def thread_caps(options: ClusterOptions, variables: Sequence[str] = THREAD_VARIABLES) -> dict:
    """The environment that caps a task's threads at ``cpus_per_task``: ``variables``
    (default :data:`harness.jobs.THREAD_VARIABLES`) and :data:`sshade.cores.CORES_VARIABLE`."""
    return {v: str(options.cpus_per_task) for v in (*variables, CORES_VARIABLE)}


@contextlib.contextmanager
def _local_launch(options: ClusterOptions, log_path: Path, variables: Sequence[str] = THREAD_VARIABLES):
    """Meanwhile, what a local task's process inherits: the thread caps
    (:func:`thread_caps`) in the environment, and stdout / stderr to ``log_path`` (its
    controller's messages, e.g. when cancelled, go there, not to this command's output)."""
    values = thread_caps(options, variables)
    old = {k: os.environ.get(k) for k in values}
    log_path.parent.mkdir(parents=True, exist_ok=True)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        os.environ.update(values)
        with open(log_path, "ab") as fh:
            os.dup2(fh.fileno(), 1)
            os.dup2(fh.fileno(), 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def array_executor(options: ClusterOptions, folder: Path, name: str, variables: Sequence[str] = THREAD_VARIABLES):
    """submitit's executor for ``options`` writing its scripts and logs in ``folder``, its
    jobs named ``name``; a
    SLURM task's threads capped by its script (:func:`thread_caps`), a local task's by
    the environment it inherits (no shell in between: a cancel reaches it)."""
    import submitit

    cap = [f"export {k}={v}" for k, v in thread_caps(options, variables).items()]
    ex = submitit.AutoExecutor(folder=str(folder / "%j"), cluster=options.executor)
    params: dict = {"timeout_min": options.timeout_min, "cpus_per_task": options.cpus_per_task,
                    "name": name}
    if options.mem_gb is not None:
        params["mem_gb"] = options.mem_gb
    if options.executor == "slurm":
        params.update(slurm_array_parallelism=options.array_parallelism, slurm_setup=[*cap, *options.setup],
                      slurm_additional_parameters=dict(options.additional_parameters))
        params.update({f"slurm_{k}": getattr(options, k) for k in ("partition", "account", "qos")
                       if getattr(options, k) is not None})
    ex.update_parameters(**params)
    return ex


def _states(options: ClusterOptions, jobs: list) -> Callable:
    """``(job ids) -> {id: state}`` for :func:`harness.slurm_jobs.wait_for_jobs`: SLURM's
    (:func:`harness.slurm_jobs.slurm_states`), or the local processes' (``RUNNING`` while alive)."""
    if options.executor == "slurm":
        return slurm_states
    by_id = {str(j.job_id): j for j in jobs}
    return lambda ids: {i: by_id[i].state for i in ids}


@contextlib.contextmanager
def _sigterm_interrupts():
    """SIGTERM raises KeyboardInterrupt meanwhile (in the main thread), as Ctrl-C does."""
    def raise_interrupt(signum, frame):
        raise KeyboardInterrupt

    try:
        old = signal.signal(signal.SIGTERM, raise_interrupt)
    except ValueError:  # not the main thread: SIGTERM keeps its handler
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def _cancel(jobs: list, ended: set, options: ClusterOptions) -> None:
    """Cancel every job not in ``ended`` (``scancel`` through submitit; a local task gets
    SIGINT), logging one line; a failure to cancel is logged, never raised."""
    left = [j for i, j in enumerate(jobs) if i not in ended]
    for j in left:
        try:
            j.cancel(check=False)
        except Exception as e:  # noqa: BLE001 -- cancelling goes on for the others
            log.warning("could not cancel array task %s: %s", j.job_id, e)
    t_end = time.monotonic() + 10.0  # a local task's controller ends it (SIGINT, then SIGKILL after 1 s)
    while options.executor == "local" and any(j.state == "RUNNING" for j in left) and time.monotonic() < t_end:
        time.sleep(0.1)
    if left:
        log.warning("interrupted: cancelled %d array task(s) without result: %s", len(left),
                    " ".join(str(j.job_id) for j in left))


def run_array(fn: Callable, args: Sequence, options: ClusterOptions, folder: Path, *, name: str, what: str,
              report: Callable[[int, JobOutcome, object], None],
              variables: Sequence[str] = THREAD_VARIABLES) -> list:
    """Submit ``fn(arg)`` for each of ``args`` as one job array and wait for every task.

    Parameters
    ----------
    fn : a picklable function of one argument. args : its arguments, one per task.
    options : the ``cluster`` section. folder : where submitit writes scripts and logs
    (``folder/<job id>/``; a local run's controller output in ``folder/local.log``).
    name : the jobs' name. what : one task in words, for the log (e.g. "one per case").
    report : called ``report(i, outcome, job)`` as task ``i`` ends
    (:class:`harness.slurm_jobs.JobOutcome`). variables : the thread variables capped at
    ``cpus_per_task`` in each task (:func:`thread_caps`).

    Returns
    -------
    list, the submitit jobs.

    Raises
    ------
    SShaDeError when the array cannot be submitted (no ``sbatch``, refused by SLURM);
    KeyboardInterrupt (Ctrl-C or SIGTERM) after cancelling the tasks without outcome.
    """
    try:
        local = options.executor == "local"
        with _local_launch(options, folder / "local.log", variables) if local else contextlib.nullcontext():
            jobs = array_executor(options, folder, name, variables).map_array(fn, list(args))
    except Exception as e:  # noqa: BLE001 -- sbatch missing, refused, a bad sbatch option
        raise SShaDeError(f"cluster: submitting the array failed: {' '.join(str(e).split())[-600:]}") from None
    log.info("submitted %d array task(s) (%s, %s): %s; logs in %s", len(jobs), options.executor, what,
             " ".join(str(j.job_id) for j in jobs), folder)
    ends: set = set()

    def on_end(i: int, outcome: JobOutcome) -> None:
        ends.add(i)
        report(i, outcome, jobs[i])

    try:
        with _sigterm_interrupts():
            wait_for_jobs(jobs, states=_states(options, jobs), poll_s=options.poll_s, grace_polls=options.grace_polls,
                          unreachable_s=options.unreachable_s, report=on_end)
    except KeyboardInterrupt:
        _cancel(jobs, ends, options)
        raise
    return jobs

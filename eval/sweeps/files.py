"""The files of a sweep folder (:mod:`eval.sweeps.sweep_command`): each job's ``status.json``, the
sweep's ``sweep.json`` (grid, command, runs, the launcher's notes) and the job folders.

Read by the summary table (:mod:`eval.sweeps.sweep_table`), written by the jobs and the Hydra
callback (:mod:`eval.sweeps.sweep_command`) and by the SLURM launcher (:mod:`eval.sweeps.launcher`,
:func:`record_outcome`), which imports only this light module.
"""
from __future__ import annotations

import datetime as _dt
import json
import os
from pathlib import Path

from sshade.files import atomic_write
from sshade.json_file import read_json

__all__ = ["STATUS_FILE", "MANIFEST", "RESUME_ENV", "OUTCOMES", "KEEP", "now_iso", "write_status", "read_status",
           "read_manifest", "write_manifest", "job_dirs", "record_outcome"]

STATUS_FILE = "status.json"
MANIFEST = "sweep.json"      # the sweep's grid and command, written before any job starts
RESUME_ENV = "SSHADE_SWEEP_RESUME"  # "1" in a resumed sweep: jobs already done are skipped
#: Final outcome of a job in the table ("running" only while the sweep still runs).
OUTCOMES = ("done", "partial", "failed", "killed", "missing")
KEEP = ("done", "partial")   # outcomes a resume keeps; the others are run again


def now_iso() -> str:
    """The local time with its UTC offset, ISO 8601 to the second (the times of status.json and sweep.json)."""
    return _dt.datetime.now().astimezone().isoformat(timespec="seconds")


# ----------------------------------------------------------------------------- status.json
def write_status(out_dir, status: dict) -> Path:
    """Write ``out_dir/status.json`` atomically; returns its path."""
    p = Path(out_dir) / STATUS_FILE
    with atomic_write(p, "w") as fh:
        json.dump(status, fh, indent=2, default=str)
        fh.write("\n")
    return p


def read_status(job_dir) -> dict | None:
    """``status.json`` of a job folder, or None when absent or unreadable."""
    p = Path(job_dir) / STATUS_FILE
    try:
        return read_json(p)
    except (OSError, ValueError):
        return None


# ----------------------------------------------------------------------------- sweep.json
def read_manifest(sweep_dir) -> dict | None:
    """``sweep_dir/sweep.json`` (the sweep's grid and command, see :func:`eval.sweeps.sweep_command.start_manifest`),
    or None when absent or unreadable."""
    try:
        m = read_json(Path(sweep_dir) / MANIFEST)
    except (OSError, ValueError):
        return None
    return m if isinstance(m, dict) else None


def write_manifest(sweep_dir, m: dict) -> Path:
    """Write ``sweep_dir/sweep.json`` atomically (the folder is made if needed); returns its path."""
    p = Path(sweep_dir) / MANIFEST
    p.parent.mkdir(parents=True, exist_ok=True)
    with atomic_write(p, "w") as fh:
        json.dump(m, fh, indent=2, default=str)
        fh.write("\n")
    return p


# ----------------------------------------------------------------------------- job folders
def job_dirs(sweep_dir: Path) -> list[Path]:
    """Folders under ``sweep_dir`` (itself included) holding a job: a status.json or a
    Hydra ``.hydra/overrides.yaml``; hidden folders (.submitit, .hydra) are skipped."""
    found = []
    for root, dirs, files in os.walk(sweep_dir):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        r = Path(root)
        if STATUS_FILE in files or (r / ".hydra" / "overrides.yaml").is_file():
            found.append(r)
    return found


def record_outcome(sweep_dir, job_num: int, outcome: str, error: str = "", *, missing_error: str = "",
                   **fields) -> str:
    """Record what the launcher saw of job ``job_num`` (e.g. ``killed``, with the SLURM
    state and job id in ``fields``): turn the job's ``status.json`` from ``running`` into
    ``outcome`` (a job that died cannot write it itself), and note it in ``sweep.json``
    under ``jobs``. A job without such a folder never started: it is noted as
    ``missing`` with ``missing_error`` (the table lists it so).

    Returns the outcome noted (``outcome`` or ``missing``)."""
    d = Path(sweep_dir)
    started = False
    for j in job_dirs(d):
        st = read_status(j)
        if st and st.get("job_num") == job_num and st.get("status") == "running":
            st.update(status=outcome, error=error, finished=now_iso(), **fields)
            write_status(j, st)
            started = True
    if not started and missing_error:
        outcome, error = "missing", missing_error
    m = read_manifest(d) or {}
    m.setdefault("jobs", {})[str(job_num)] = {"outcome": outcome, "error": error, "time": now_iso(), **fields}
    write_manifest(d, m)
    return outcome

"""The summary table of a sweep folder (:mod:`eval.sweeps.sweep_command`): ``sweep_table.csv`` (one row
per job: its overrides, one column per overridden key, status, error, the rows its tables
mark pending, and ``<method>/<column>`` for every column of the job's ``table.csv``) and
``sweep_table.md`` (varying keys, status, pending rows and the main metrics), built by :func:`aggregate_sweep` from the
folder's files (:mod:`eval.sweeps.files`) at the end of a multirun, by
``python -m eval.sweeps aggregate DIR`` and by a resume.
"""
from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path

from eval.run.outdir import refuse_results
from eval.run.pending_rows import marked_pending
from eval.run.row_check import read_cases
from eval.sweeps.files import MANIFEST, OUTCOMES, STATUS_FILE, job_dirs, read_manifest, read_status
from eval.tables import TABLE_COLUMNS, method_order_key
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.json_file import read_bounded, read_json

__all__ = ["aggregate_sweep", "sweep_markdown", "sweep_title", "TABLE_CSV", "TABLE_MD"]

TABLE_CSV = "sweep_table.csv"
TABLE_MD = "sweep_table.md"
MAX_YAML_BYTES = 16 * 2**20  #: the largest Hydra record (multirun.yaml, overrides.yaml) read
MAX_OVERRIDES = 1000  #: overrides read from one record
MAX_TITLE_SPEC = 2000  #: characters of the multirun's overrides in the table's title


def _overrides(job_dir: Path, status: dict | None) -> list[str]:
    if status and isinstance(status.get("overrides"), list):
        return [str(o) for o in status["overrides"]]
    v = _read_yaml(job_dir / ".hydra" / "overrides.yaml")
    return [str(o) for o in v][:MAX_OVERRIDES] if isinstance(v, list) else []


def _read_yaml(p: Path):
    """The YAML file ``p`` that Hydra wrote, read as untrusted input: a regular file of at
    most :data:`MAX_YAML_BYTES`, without aliases (a few hundred bytes of nested aliases
    expand to gigabytes when printed); None when absent, unreadable or refused."""
    import yaml

    class _NoAliases(yaml.SafeLoader):
        def compose_node(self, parent, index):
            if self.check_event(yaml.events.AliasEvent):
                raise yaml.YAMLError(f"{p}: an alias (Hydra writes none)")
            return super().compose_node(parent, index)

    if not p.is_file():
        return None
    try:
        return yaml.load(read_bounded(p, MAX_YAML_BYTES), Loader=_NoAliases)  # noqa: S506 -- a SafeLoader
    except (OSError, ValueError, RecursionError, yaml.YAMLError):
        return None


def _split(override: str) -> tuple[str, str]:
    key, _, value = override.partition("=")
    return key.lstrip("+~"), value


def _value(v: str):
    try:
        f = float(v)
    except ValueError:
        return v
    return int(f) if f.is_integer() and "." not in v and "e" not in v.lower() else f


def _job_sort_key(row: dict):
    n = row.get("job")
    return (0, n, "") if isinstance(n, int) else (1, 0, str(row.get("dir")))


def _job_row(d: Path, j: Path, keys: list, ended, seen: dict) -> dict:
    """The table row of the job folder ``j`` of the sweep ``d`` (its overridden keys are
    appended to ``keys``; ``ended``: the end of the sweep's last run, ``seen``: the
    launcher's notes)."""
    st = read_status(j)
    ov = _overrides(j, st)
    row = {"job": None, "dir": str(j.relative_to(d)) or ".", "overrides": " ".join(ov)}
    if st and st.get("job_num") is not None:
        row["job"] = int(st["job_num"])
    elif j.name.isdigit():
        row["job"] = int(j.name)
    for o in ov:
        k, v = _split(o)
        if k not in keys:
            keys.append(k)
        row[k] = _value(v)
    if st:
        row["status"] = str(st.get("status", "missing"))
        row["error"] = str(st.get("error") or "")
        if row["status"] == "running" and ended is not None and _before(st.get("started"), ended):
            row["status"] = "killed"  # the sweep is over and the job never wrote its result
            row["error"] = _launcher_note(seen, row["job"]) or _KILLED
        elif row["status"] == "running" and not row["error"]:
            row["error"] = "no final status yet: the job is still running (or was killed, if the sweep is over)"
    else:
        run_json = j / "run.json"
        try:
            rs = read_json(run_json).get("status") if run_json.is_file() else None
        except (OSError, ValueError):
            rs = None
        row["status"] = {"done": "done", "running": "running"}.get(rs, "missing")
        row["error"] = "" if rs == "done" else f"no {STATUS_FILE} (not run through eval.sweeps?)"
    for k in ("wall_s", "n_cases", "n_errors"):
        row[k] = (st or {}).get(k, math.nan)
    marks = marked_pending(j)  # rows made by older code, as the job's table.md lists them
    row["pending"] = len(marks)
    row["pending_from"] = " ".join(sorted({c for _, _, c in marks}))
    tab = j / "table.csv"
    if tab.is_file():
        try:
            t = read_cases(tab)  # a regular file of bounded size
        except Exception as e:  # noqa: BLE001
            row["error"] = (row["error"] + f"; unreadable table.csv ({e})").lstrip("; ")
            t = None
        if t is not None and "method" in t.columns:
            for _, r in t.iterrows():
                for c in t.columns:
                    if c != "method":
                        row[f"{r['method']}/{c}"] = r[c]
    return row


def _missing_rows(rows: list, points: list, keys: list, ended, seen: dict) -> list[dict]:
    """Rows of the points of the grid (``sweep.json``) that have no folder: never started."""
    out = []
    have = {r["overrides"] for r in rows} | {r["job"] for r in rows if r["job"] is not None}
    for num, ov in enumerate(points):
        ov = [str(o) for o in ov]
        if " ".join(ov) in have or num in have:
            continue
        row = {"job": num, "dir": "", "overrides": " ".join(ov), "status": "missing",
               "error": _launcher_note(seen, num) or "never started (no job folder): cancelled or not scheduled"
               + ("" if ended is not None else ", or not started yet")}
        for o in ov:
            k, v = _split(o)
            if k not in keys:
                keys.append(k)
            row[k] = _value(v)
        out.append(row)
    return out


def aggregate_sweep(sweep_dir, *, write: bool = True):
    """One table for a sweep folder: a row per job (parameter setting).

    Parameters
    ----------
    sweep_dir : the multirun folder (``hydra.sweep.dir``), holding one folder per job.
    write : also write ``sweep_table.csv`` and ``sweep_table.md`` into ``sweep_dir``
        (atomically).

    Returns
    -------
    pandas DataFrame with columns ``job``, ``dir`` (relative to ``sweep_dir``; empty for
    a missing job), ``overrides`` (space-separated), one column per overridden key,
    ``status`` (:data:`eval.sweeps.files.OUTCOMES`, or running while the sweep runs; a point of
    ``sweep.json``'s grid without folder is missing), ``error``, ``wall_s``, ``n_cases``,
    ``n_errors``, ``pending`` and ``pending_from`` (the rows the job's ``table.md`` marks
    pending, made by older code, and the commits that made them, space-separated:
    :func:`eval.run.pending_rows.marked_pending`), then ``<method>/<column>`` for every column of the job's
    ``table.csv`` (per-method means over successful cases; NaN where none).

    Raises
    ------
    SShaDeError if ``sweep_dir`` is not a folder or holds no job.
    """
    import pandas as pd
    d = Path(sweep_dir).expanduser().resolve()
    if not d.is_dir():
        raise SShaDeError(f"sweep folder not found: {d}")
    if write:
        refuse_results(d, "use --no-write to print the table only")
    jobs = job_dirs(d)
    man = read_manifest(d) or {}
    points = man.get("points") if isinstance(man.get("points"), list) else []
    if not jobs and not points:
        raise SShaDeError(f"no sweep jobs in {d} (no {STATUS_FILE} or .hydra/overrides.yaml below it, "
                          f"no {MANIFEST})")
    ended = _last_run_end(man)
    seen = {"jobs": dict(man.get("jobs") or {})}
    rows, keys = [], []
    for j in jobs:
        rows.append(_job_row(d, j, keys, ended, seen))
    rows += _missing_rows(rows, points, keys, ended, seen)
    rows.sort(key=_job_sort_key)
    head = ["job", "dir", "overrides", *keys, "status", "error", "wall_s", "n_cases", "n_errors", *_PENDING]
    metric_cols = [c for r in rows for c in r if c not in head]
    metric_cols = list(dict.fromkeys(metric_cols))
    df = pd.DataFrame(rows, columns=head + metric_cols)
    df["job"] = df["job"].astype("Int64")
    if write:
        with atomic_write(d / TABLE_CSV, "w", newline="") as fh:
            df.to_csv(fh, index=False, float_format="%.6g")
        with atomic_write(d / TABLE_MD, "w") as fh:
            fh.write(sweep_markdown(df, title=sweep_title(d, df)))
    return df


_PENDING = ("pending", "pending_from")  #: the columns of the rows made by older code
_KILLED = "died without a result (killed: out of memory, time limit, node failure or cancelled)"


def _last_run_end(man: dict):
    """End time (datetime) of the sweep's last run in ``sweep.json``, None while it runs
    or without a manifest."""
    runs = man.get("runs") or []
    end = runs[-1].get("finished") if runs and isinstance(runs[-1], dict) else None
    try:
        return _dt.datetime.fromisoformat(end) if end else None
    except (TypeError, ValueError):
        return None


def _before(started, end) -> bool:
    """``started`` (ISO time of a job's start, may be missing) is before ``end``."""
    try:
        return _dt.datetime.fromisoformat(str(started)) <= end
    except (TypeError, ValueError):
        return True  # no start time: the job cannot still be running after its sweep ended


def _launcher_note(seen: dict, num) -> str:
    """The launcher's record of job ``num`` (``sweep.json`` ``jobs``), as an error text."""
    j = seen["jobs"].get(str(num)) if num is not None else None
    if not isinstance(j, dict):
        return ""
    return str(j.get("error") or "")


def sweep_title(d: Path, df) -> str:
    """Title of the sweep table of folder ``d``: its job counts per outcome, the rows its
    jobs' tables mark pending (with the commits that made them) and the multirun's overrides."""
    counts = df["status"].value_counts()
    parts = ", ".join(f"{int(counts[s])} {s}" for s in (*OUTCOMES, "running") if s in counts)
    n = int(df["pending"].fillna(0).sum()) if "pending" in df.columns else 0
    if n:
        made = sorted({c for v in df["pending_from"].fillna("").astype(str) for c in v.split()})
        parts += f"; {n} row(s) pending from {', '.join(made)} (made by older code: python -m eval.reproduce)"
    spec = ""
    v = _read_yaml(d / "multirun.yaml")
    try:
        task = v.get("hydra", {}).get("overrides", {}).get("task") if isinstance(v, dict) else None
    except AttributeError:  # a section that is no mapping
        task = None
    if isinstance(task, list) and task:
        spec = f" ({' '.join(str(t) for t in task[:MAX_OVERRIDES])})"[:MAX_TITLE_SPEC]
    return f"Sweep {d.name}: {len(df)} job(s), {parts}{spec}"


def _md_cell(v, dec: int | None = None) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "--"
    try:
        import pandas as pd
        if pd.isna(v):
            return "--"
    except (TypeError, ValueError):
        pass
    if dec is not None:
        try:
            return f"{float(v):.{dec}f}"
        except (TypeError, ValueError):
            pass
    return str(v).replace("|", "\\|").replace("\n", " ")


def sweep_markdown(df, *, title: str | None = None) -> str:
    """Markdown view of :func:`aggregate_sweep`'s table: job, the overridden keys that
    vary across jobs (all of them if none varies), status, the rows made by older code
    (where a job has any: how many and from which commits), per method the main metrics
    of ``eval.tables.TABLE_COLUMNS`` and the number of cases, and the error (shortened)."""
    fixed = {"job", "dir", "overrides", "status", "error", "wall_s", "n_cases", "n_errors", *_PENDING}
    keys = [c for c in df.columns if c not in fixed and "/" not in c]
    vary = [k for k in keys if df[k].astype(str).nunique(dropna=False) > 1] or keys
    methods = list(dict.fromkeys(c.split("/", 1)[0] for c in df.columns if "/" in c))
    methods.sort(key=method_order_key)
    cols: list[tuple[str, str, int | None]] = []
    for m in methods:
        if f"{m}/n_cases" in df.columns:
            cols.append((f"{m}/n_cases", f"{m} cases", 0))
        for c, h, _, dec, _ in TABLE_COLUMNS:
            if f"{m}/{c}" in df.columns:
                cols.append((f"{m}/{c}", f"{m} {h}", dec))
    pend = "pending" in df.columns and bool(df["pending"].fillna(0).astype(float).gt(0).any())
    head = ["Job", *vary, "Status", *(["Pending rows"] if pend else []), *[h for _, h, _ in cols], "Error"]
    lines = [f"### {title}", ""] if title else []
    lines += ["| " + " | ".join(head) + " |",
              "|" + "|".join(["---:"] + ["---"] * (len(vary) + 1 + pend) + ["---:"] * len(cols) + ["---"]) + "|"]
    for _, r in df.iterrows():
        err = str(r.get("error") or "")
        err = err if len(err) <= 100 else err[:97] + "..."
        cells = [_md_cell(r["job"]), *[_md_cell(r[k]) for k in vary], _md_cell(r["status"]),
                 *([_pending_cell(r)] if pend else []), *[_md_cell(r[c], d) for c, _, d in cols],
                 _md_cell(err) if err else ""]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _pending_cell(r) -> str:
    """``"4 from 3e79476"``: the rows of a job made by older code, ``""`` when none."""
    try:
        n = float(r.get("pending"))
    except (TypeError, ValueError):
        return ""
    if not math.isfinite(n) or n <= 0:
        return ""
    return f"{int(n)} from {', '.join(str(r.get('pending_from') or 'unknown').split())}"

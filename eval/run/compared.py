"""Rows of earlier runs beside a new one (``compare_with=[results/defaust]``): a new
method's row beside the committed baselines without rerunning them.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from eval.run.jsonsafe import json_safe
from eval.run.names import safe_name
from eval.run.result_store import ResultStore, case_identity
from eval.run.row_check import MAX_LISTED, cell_differs, read_cases, shown_cell
from eval.run.runinfo import read_runinfo
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.json_file import read_json
from sshade.method_interface import check_name

__all__ = ["ComparedRun", "read_compared", "compared_rows", "run_settings", "write_compared", "checked_compared",
           "IDENTITY_FIELDS", "SETTINGS", "COMPARED_CSV", "COMPARED_RECORD"]

#: The fields of a case identity that must agree (the data digests say whether it is the
#: same data; the dataset's seed may differ where the data agree).
IDENTITY_FIELDS = ("dataset", "case", "V", "F", "handles", "targets", "V_gt")
#: The settings of a run's ``config`` (``run.json``) that make the numbers of its rows
#: besides the methods and the data: the handle bound that fails a row, the reference's
#: stopping (the Ref and E-gap columns), the dataset's protocol. A compared run must agree
#: on each (dotted paths into the config).
SETTINGS = ("handle_error_max_pct", "reference.max_iter", "reference.time_budget_s", "dataset.protocol")
_ABSENT = "(absent)"
#: The file of an evaluator run folder that keeps the compared rows (beside ``cases.csv``).
COMPARED_CSV = "compared.csv"
#: Their record, as read and checked from their runs' stores (``rows`` and their sha256,
#: ``digest``): what ``compared.csv`` is held against, as ``cases.csv`` is against ``runs/``.
COMPARED_RECORD = "compared.json"


@dataclass
class ComparedRun:
    """The rows read from one earlier run folder.

    Attributes
    ----------
    folder : Path, the run folder. label : str, how its rows are named (the path as given).
    commit : str or None, the commit its ``run.json`` records (``+dirty`` when it was).
    machine : str, its platform and core count. methods : its method names, in order.
    rows : list of dict, one per (case, method) record of this run's cases.
    missing : names of this run's cases it has no record of.
    """
    folder: Path
    label: str
    commit: str | None
    machine: str
    methods: list = field(default_factory=list)
    rows: list = field(default_factory=list)
    missing: list = field(default_factory=list)


def _run_json(folder: Path) -> dict:
    d = read_runinfo(folder)
    if not d:
        raise SShaDeError(f"compare_with: {folder} has no readable run.json holding a run record (is it a "
                          "python -m eval run folder?)")
    return d


def run_settings(record) -> dict:
    """The :data:`SETTINGS` of a run's resolved config as recorded (a mapping: ``run.json``'s
    ``config``, or :meth:`eval.run.spec.EvalSpec.record` of this run), each dotted path to
    its value (``"(absent)"`` where the record has none)."""
    out = {}
    for path in SETTINGS:
        v = record
        for k in path.split("."):
            v = v.get(k, _ABSENT) if isinstance(v, dict) else _ABSENT
        out[path] = v
    return out


def _identity_problem(stored, ours: dict) -> str:
    """``""`` when a record's case identity ``stored`` agrees with ``ours`` on
    :data:`IDENTITY_FIELDS`, else the fields that differ, in words."""
    if not isinstance(stored, dict):
        return "it records no case identity"
    bad = [k for k in IDENTITY_FIELDS if stored.get(k) != ours.get(k)]
    return f"its {', '.join(bad)} differ" if bad else ""


def read_compared(folder, label: str, cases, *, dataset: str, seed, settings: dict | None = None) -> ComparedRun:
    """The rows of run folder ``folder`` on ``cases`` (this run's), checked (module docstring).

    Parameters
    ----------
    folder : str or Path, an earlier ``python -m eval`` run folder (``run.json``, ``runs/``).
    label : str, the name its rows carry (e.g. ``results/defaust``).
    cases : this run's cases (``name``, ``V``, ``F``, ``handles``, ``targets``, ``V_gt``).
    dataset, seed : this run's dataset name and seed (:func:`case_identity`).
    settings : this run's :func:`run_settings` (None: not checked).

    Returns
    -------
    :class:`ComparedRun`.

    Raises
    ------
    SShaDeError naming the folder and the file: not a run folder, a link out of it,
    another dataset, another value of a setting of :data:`SETTINGS` (naming it), an
    invalid or edited record, a record made on other data (another build), or no record
    of any case of this run.
    """
    folder = Path(folder)
    if not (folder / "runs").is_dir():
        raise SShaDeError(f"compare_with: {folder} is not a python -m eval run folder (no runs/)")
    store = ResultStore(folder)
    store.check_links()
    info = _run_json(folder)
    theirs = str(((info.get("config") or {}).get("dataset") or {}).get("name", ""))
    if theirs != str(dataset):
        raise SShaDeError(f"compare_with: {folder} is a run on dataset {theirs!r}, this one on {dataset!r}")
    if settings is not None:
        other = run_settings(info.get("config") if isinstance(info.get("config"), dict) else {})
        for k, v in settings.items():
            if other.get(k) != v:
                raise SShaDeError(f"compare_with: {folder} was made with {k}={other.get(k)!r}, this run with "
                                  f"{k}={v!r}: its rows are not comparable (run both with the same {k})")
    git = info.get("git") if isinstance(info.get("git"), dict) else {}
    commit = git.get("commit")
    out = ComparedRun(folder=folder, label=label, commit=(commit[:12] + ("+dirty" if git.get("dirty") else ""))
                      if isinstance(commit, str) else None,
                      machine=f"{info.get('platform', '?')}, {info.get('cpu_count', '?')} cores")
    for c in cases:
        d = store.root / safe_name(c.name)
        names = sorted(n for n in os.listdir(d) if n.endswith(".json")) if d.is_dir() else []
        if not names:
            out.missing.append(c.name)
            continue
        ours = case_identity(c, dataset=dataset, seed=seed)
        for n in names:
            out.rows.append(_one_row(store, d / n, c.name, ours, out))
    if not out.rows:
        raise SShaDeError(f"compare_with: {folder} holds no record of this run's cases ({cases[0].name}, ...); "
                          "compare runs on the same cases")
    return out


def _one_row(store: ResultStore, p: Path, case: str, ours: dict, out: ComparedRun) -> dict:
    """The row of record file ``p`` of ``case``, checked, marked with its run."""
    try:
        method = read_json(p).get("method")
    except (OSError, ValueError, AttributeError):
        method = None
    found = store.read(case, str(method)) if isinstance(method, str) else None
    if found is None or found.record is None:
        why = found.why if found is not None else "unreadable"
        raise SShaDeError(f"compare_with: {p} is not a valid record ({why}); its rows cannot be compared")
    rec = found.record
    problem = _identity_problem((rec.get("key_fields") or {}).get("case"), ours)
    if problem:
        raise SShaDeError(f"compare_with: {p} was made on other data than this run's case {case} ({problem}): "
                          "another build of the dataset? Compare runs on the same cases")
    if method not in out.methods:
        out.methods.append(method)
    git = rec.get("git") if isinstance(rec.get("git"), dict) else {}
    commit = (git["commit"][:12] + ("+dirty" if git.get("dirty") else "")) if isinstance(git.get("commit"), str) \
        else out.commit  # the record's own commit: a table's rows may come from several
    return {**rec["row"], "method": method, "run": out.label, "run_commit": commit, "run_machine": out.machine,
            "time_other_run": True}


def compared_rows(runs: list[ComparedRun], ours: list[str]) -> list[dict]:
    """The rows of ``runs``, each method named as in its run, or ``NAME (label)`` when
    that name is taken by one of ``ours`` (this run's methods) or an earlier compared
    run (checked against :data:`sshade.method_interface.NAME_RULE`; SShaDeError when it cannot be
    made a valid name)."""
    taken = {n.lower() for n in ours}
    rows = []
    for r in runs:
        rename = {}
        for m in r.methods:
            new = m if m.lower() not in taken else f"{m} ({Path(r.label).name or r.label})"
            rename[m] = check_name(new, where=f"compare_with {r.label}")
            taken.add(rename[m].lower())
        rows += [{**row, "method": rename[row["method"]]} for row in r.rows]
    return rows


def _rows_digest(rows: list) -> str:
    return hashlib.sha256(json.dumps(rows, sort_keys=True, allow_nan=True).encode()).hexdigest()


def write_compared(out_dir, df) -> Path:
    """Write the compared rows ``df`` (pandas DataFrame, one row per (case, method) of an
    earlier run, :func:`compared_rows`) as ``compared.csv`` and their record
    ``compared.json`` (:data:`COMPARED_RECORD`) in ``out_dir``. Returns the CSV's path;
    OSError propagates."""
    out_dir = Path(out_dir)
    rows = json_safe(df.to_dict("records"))
    with atomic_write(out_dir / COMPARED_RECORD, "w") as fh:
        fh.write(json.dumps({"version": 1, "rows": rows, "digest": _rows_digest(rows)}, indent=1) + "\n")
    with atomic_write(out_dir / COMPARED_CSV, "w", newline="") as fh:
        df.to_csv(fh, index=False)
    return out_dir / COMPARED_CSV


def checked_compared(run_dir):
    """The rows of ``run_dir``'s ``compared.csv`` (a pandas DataFrame) when they are those
    its run read and checked (:data:`COMPARED_RECORD`, its digest holding); None when the
    run compared no rows. Raises SShaDeError naming the file: unreadable, not a regular
    file, without its record (written by a version before it had one), or a row that
    disagrees with it (an edit)."""
    p, rec_p = Path(run_dir) / COMPARED_CSV, Path(run_dir) / COMPARED_RECORD
    if not os.path.lexists(p):
        return None
    try:
        df, rec = read_cases(p), read_json(rec_p)
    except (OSError, ValueError) as e:
        raise SShaDeError(f"{p}: cannot be checked against {COMPARED_RECORD} ({getattr(e, 'strerror', None) or e}); "
                          "run the comparison again (python -m eval ... compare_with=[...])") from None
    rows = rec.get("rows") if isinstance(rec, dict) else None
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows) \
            or rec.get("digest") != _rows_digest(rows):
        raise SShaDeError(f"{rec_p}: not the record of the compared rows (edited, or another file)")
    problems = _compared_problems(df.to_dict("records"), rows)
    if problems:
        raise SShaDeError(f"{p}: {'; '.join(problems[:MAX_LISTED])}"
                          f"{f' (and {len(problems) - MAX_LISTED} more)' if len(problems) > MAX_LISTED else ''}: "
                          f"its rows disagree with {COMPARED_RECORD}; nothing is made from them")
    return df


def _compared_problems(got: list, rows: list) -> list[str]:
    """What differs between the rows read back from ``compared.csv`` and the recorded ones."""
    if len(got) != len(rows):
        return [f"{len(got)} rows, {len(rows)} recorded"]
    out = []
    for a, b in zip(got, rows):
        diff = [k for k in sorted(set(a) | set(b)) if cell_differs(a.get(k), b.get(k))]
        if diff:
            k = diff[0]
            out.append(f"{b.get('case')} / {b.get('method')}: {k} {shown_cell(a.get(k))} in {COMPARED_CSV}, "
                       f"{shown_cell(b.get(k))} recorded")
    return out

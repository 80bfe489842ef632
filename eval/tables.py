"""Per-case results -> per-method tables (CSV, Markdown, LaTeX), written atomically.
Floor 3 of eval/ (above present/, tests/test_layering.py); notes: docs/implementation.md.

Input: a pandas DataFrame with one row per (case, method) as produced by
:mod:`eval.app`: identifiers (``case``, ``subject``, ``pose``, ``method``), sizes
(``n_vertices``, ``n_handles``, ``n_static``), the metrics of :mod:`eval.metrics.measures`
(``volume_err_pct``, ``area_err_pct``, ``edge_err_pct``, ``angle_err_deg``,
``angle_err_rel_pct``, ``handle_err_pct``, ``gt_vertex_mean_pct``,
``gt_vertex_max_pct``, ``hausdorff``, ``chamfer``), ``time_s`` (seconds of the
``deform`` call), method info (``iterations``, ``remesh_s``, ...) and ``error``
(empty or missing when the method succeeded)."""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from eval.present.breakdown import write_breakdown
from eval.present.intervals import interval_table
from eval.present.rows import method_order_key, methods_in, ok_mask
from eval.present.stops import PROTOCOL_TEXT, stop_lines
from eval.present.table_markup import EXTRA_COLUMNS, TABLE_COLUMNS, to_latex, to_markdown
from eval.run.compared import COMPARED_CSV, COMPARED_RECORD, SETTINGS, checked_compared, write_compared
from eval.run.outdir import refuse_results
from eval.run.pending_rows import marked_pending, pending_markdown, pending_title, strip_pending
from eval.run.row_check import check_rows, checked_cases
from eval.run.stale_rows import CommitTrees, folder_states, row_machines, settings_marks
from harness.command import run_command
from sshade.command_errors import ArgumentParser
from sshade.files import atomic_write
from sshade.json_file import read_json, read_prefix

if TYPE_CHECKING:  # pandas is imported where a table is built: not when `python -m eval` only refuses a config
    import pandas as pd

__all__ = ["summarize", "write_tables", "retabulate", "to_markdown", "to_latex", "ok_mask", "common_cases", "compare",
           "all_note", "Comparison", "comparison_markdown", "main_note", "failure_lines", "ALL_CASES_HEADING",
           "COMMON_CASES_HEADING", "INTERVAL_COLUMNS", "case_intervals", "common_case_values", "compared_lines",
           "TABLE_COLUMNS", "EXTRA_COLUMNS", "method_order_key", "stop_lines", "PROTOCOL_TEXT", "machines_line"]

#: Columns never averaged (identifiers, seeds).
_ID_COLUMNS = ("case", "subject", "pose", "method", "error", "case_seed", "seeds", "seed")

#: Heading of table.md's second table.
ALL_CASES_HEADING = "All cases each method ran on"
#: Heading of table.md's main table when a second table follows and no title is given.
COMMON_CASES_HEADING = "Cases every method succeeded on"
#: (column, header, decimals) of the main table's columns given intervals
#: (:func:`case_intervals`): its error measures (the time is a cost, not an error) and
#: the distance to the ground truth, with the headers and decimals of the table.
INTERVAL_COLUMNS = (*((c, h, d) for c, h, _, d, _ in TABLE_COLUMNS if c != "time_s"),
                    *(x for x in EXTRA_COLUMNS if x[0] == "gt_vertex_mean_pct"))


def _numeric_columns(df: pd.DataFrame) -> list[str]:
    """Columns averaged by :func:`summarize`: numeric or boolean ones holding a value, and
    object ones that convert to float (e.g. booleans mixed with NaN where a method
    failed), except identifiers (:data:`_ID_COLUMNS`); ``time_s`` always (empty without
    times). A column of no value is left out whether it comes as None (a run's rows) or as
    NaN (``cases.csv`` read back), so :func:`retabulate` gives the run's table."""
    import pandas as pd
    num_cols = []
    for c in df.columns:
        if c in _ID_COLUMNS:
            continue
        s = df[c]
        if c == "time_s":
            num_cols.append(c)  # a Time column of no time (results scored without times) stays, empty
        elif pd.api.types.is_bool_dtype(s) or pd.api.types.is_numeric_dtype(s):
            if s.notna().any():  # a column of no value read back from cases.csv is no mean, as in the run
                num_cols.append(c)
        elif s.dtype == object and len(s.dropna()):
            try:
                s.dropna().astype(float)
            except (TypeError, ValueError):
                continue
            num_cols.append(c)
    return num_cols


def summarize(df: pd.DataFrame, *, cases=None) -> pd.DataFrame:
    """Per-method means over successful cases.

    Parameters
    ----------
    df : per-case rows (see module docstring); needs a ``method`` column.
    cases : optional collection of case names (values of the ``case`` column): average
        only the successful rows of these cases (e.g. :func:`common_cases`). Default
        None: every successful row, as before (each method over its own cases).

    Returns
    -------
    DataFrame, one row per method (ordered ARAP, Elastic, SShaDe, others), columns
    ``method``, ``n_cases`` (successful rows averaged), ``n_failed`` (failed rows of
    the method over all the cases it was run on, also with ``cases``) and the mean of
    every numeric (or boolean) column except identifiers. A method with no successful
    row averaged has NaN means.
    """
    import pandas as pd
    if "method" not in df.columns:
        raise ValueError("results have no 'method' column")
    if cases is not None and "case" not in df.columns:
        raise ValueError("summarize(cases=...) needs a 'case' column")
    ok = ok_mask(df)
    use = ok if cases is None else ok & df["case"].isin(list(cases))
    num_cols = _numeric_columns(df)
    rows = []
    for m in methods_in(df):
        sel = df["method"] == m
        good = df[sel & use]
        row = {"method": m, "n_cases": int(len(good)), "n_failed": int((sel & ~ok).sum())}
        for c in num_cols:
            v = good[c].dropna().astype(float)
            row[c] = float(v.mean()) if len(v) else float("nan")
        rows.append(row)
    return pd.DataFrame(rows, columns=["method", "n_cases", "n_failed", *num_cols])


def common_cases(df: pd.DataFrame) -> list | None:
    """The cases on which every method of ``df`` that succeeded somewhere has a
    successful row (a method that failed on every case it ran on is not asked: it is
    reported apart, :func:`failed_everywhere`, and its row averages no case).

    Parameters
    ----------
    df : per-case rows with ``case``, ``method`` and (optional) ``error`` columns.

    Returns
    -------
    list of case names in order of first appearance (empty when no case qualifies), or
    None when ``df`` has no ``case`` column.
    """
    if "case" not in df.columns or "method" not in df.columns:
        return None
    good = df[ok_mask(df)]
    # a method that failed everywhere is left out here, else it would empty the set
    # (it keeps its row, 0 cases and a note: failed_everywhere, comparison_markdown)
    per_method = [set(good.loc[good["method"] == m, "case"]) for m in good["method"].unique()]
    common = set.intersection(*per_method) if per_method else set()
    return [c for c in dict.fromkeys(df["case"]) if c in common]


@dataclass(frozen=True)
class Comparison:
    """What :func:`compare` found.

    Attributes
    ----------
    main : the main table (:func:`summarize` layout): means over ``cases`` when that is
        non-empty, else (fallback) each method's means over its own successful cases.
    all : each method's means over all its own successful cases, when that differs from
        ``main`` for some method (it succeeded on cases outside the common set); else None.
    cases : the common set (case names), empty when no case qualifies, None when the
        frame has no ``case`` column (then ``main`` is the plain per-method summary).
    methods : the methods of the frame, in table order.
    ref_cases : how many of ``cases`` have reference columns (``ref_mean_pct``) in a
        successful row; None without that column (``reference.cases`` may cover a
        subset, and the note then says so).
    ref_cases_all : as ``ref_cases`` over every successful row's case (the ``all`` table).
    n_cases_all : the number of distinct cases with a successful row.
    """
    main: pd.DataFrame
    all: pd.DataFrame | None
    cases: list | None
    methods: list
    ref_cases: int | None = None
    ref_cases_all: int | None = None
    n_cases_all: int | None = None

    @property
    def same_cases(self) -> bool:
        """Whether ``main`` may bold its best values: its rows average the same cases
        (the common set), or the frame has no ``case`` column (legacy summary, bolded as
        before). False in the empty-common-set fallback."""
        return self.cases is None or bool(self.cases)


def compare(df: pd.DataFrame) -> Comparison:
    """Main and all-cases tables of ``df`` (per-case rows, see the module docstring).

    Returns a :class:`Comparison`: ``main`` averages every method over the common set
    (:func:`common_cases`); ``all`` (or None) each method over its own successful cases,
    given only when some method succeeded on a case outside the common set. With an empty
    common set ``main`` is the per-method summary and ``all`` is None.
    """
    methods = methods_in(df) if "method" in df.columns else []
    cases = common_cases(df)
    own = summarize(df)
    if not cases:
        return Comparison(main=own, all=None, cases=cases, methods=methods)
    ok = ok_mask(df)
    common = set(cases)
    extra = bool((ok & ~df["case"].isin(list(common))).any())
    ref = ref_all = None
    if "ref_mean_pct" in df.columns:
        has_ref = ok & df["ref_mean_pct"].notna()
        ref = int(df.loc[has_ref & df["case"].isin(list(common)), "case"].nunique())
        ref_all = int(df.loc[has_ref, "case"].nunique())
    return Comparison(main=summarize(df, cases=cases), all=own if extra else None, cases=cases, methods=methods,
                      ref_cases=ref, ref_cases_all=ref_all, n_cases_all=int(df.loc[ok, "case"].nunique()))


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _own_counts(summary: pd.DataFrame) -> str:
    """``"ARAP 2, SShaDe 4"``: each method's number of averaged cases."""
    return ", ".join(f"{r['method']} {int(r['n_cases'])}" for _, r in summary.iterrows())


def main_note(comp: Comparison) -> str | None:
    """One sentence saying which cases the main table's rows average (None: no ``case``
    column, the legacy per-method summary)."""
    if comp.cases is None:
        return None
    if not comp.cases:
        return (f"No case on which every method ({', '.join(map(str, comp.methods))}) succeeded: each row is "
                f"that method's mean over its own successful cases ({_own_counts(comp.main)}), not comparable "
                "across rows.")
    dead = _dead(comp)
    alive = [m for m in comp.methods if m not in dead]
    who = "the method" if len(alive) == 1 else f"every method ({', '.join(map(str, alive))})"
    note = f"Mean over the {_plural(len(comp.cases), 'case')} on which {who} succeeded."
    if comp.ref_cases is not None and 0 < comp.ref_cases < len(comp.cases):
        note += (f" Ref mean, Ref max and E gap: over the {comp.ref_cases} of them with a reference solution "
                 "(reference.cases).")
    if dead:
        note += (f" {', '.join(map(str, dead))} failed on every case {'it' if len(dead) == 1 else 'they'} ran on: "
                 f"{'its row averages' if len(dead) == 1 else 'their rows average'} no case.")
    return note


def all_note(comp: Comparison) -> str:
    """The note of the all-cases table (``comp.all``): its rows average different cases,
    and the reference columns only the cases with a reference solution, when those are
    fewer than the cases."""
    note = ("Each row: that method's mean over all its own successful cases (Cases), so rows may average "
            "different cases and nothing is bold; compare methods in the table above.")
    if comp.ref_cases_all is not None and comp.n_cases_all and 0 < comp.ref_cases_all < comp.n_cases_all:
        note += (f" Ref mean, Ref max and E gap: over the {comp.ref_cases_all} of the {comp.n_cases_all} cases "
                 "with a reference solution (reference.cases), not over Cases.")
    return note


def _dead(comp: Comparison) -> list:
    """Methods of ``comp.main`` that failed on every case they ran on (failed runs, no
    successful one: a row averaging no case)."""
    t = comp.main
    if "n_failed" not in t.columns:
        return []
    return [r["method"] for _, r in t.iterrows() if int(r["n_failed"]) > 0 and int(r["n_cases"]) == 0]


def _reason(msg: str) -> str:
    """A failure message reduced to its kind (``handles not reached``; others as they
    are, on one line, at most 160 characters) to count failures per method."""
    msg = " ".join(str(msg).split())
    if msg.startswith("handles not reached"):
        return "handles not reached"
    return msg if len(msg) <= 160 else msg[:157] + "..."


def failure_lines(df: pd.DataFrame) -> list[str]:
    """One line per method with failed runs: how many of its runs failed and why, e.g.
    ``"Mine: 2 of 3 cases failed: handles not reached (1); timed out after 60 s (1)"``.
    Failed runs are left out of every mean and of the bold (:func:`ok_mask`)."""
    if "method" not in df.columns or "error" not in df.columns:
        return []
    ok = ok_mask(df)
    lines = []
    for m in methods_in(df):
        sel = df["method"] == m
        bad = df.loc[sel & ~ok, "error"]
        if not len(bad):
            continue
        counts = bad.map(_reason).value_counts(sort=True)
        why = "; ".join(f"{r} ({int(c)})" for r, c in counts.items())
        lines.append(f"{m}: {int(len(bad))} of {_plural(int(sel.sum()), 'case')} failed: {why}")
    return lines


def common_case_values(df: pd.DataFrame, comp: Comparison, column: str) -> dict:
    """Each method's (the main table's, in its order) ``column`` over the common cases'
    successful rows: ``{method: Series}`` indexed by case in case-name order, so what is
    computed from them (an interval's resamples) does not depend on the rows' order;
    values as numbers (NaN where missing); methods without such a row left out."""
    import pandas as pd
    rows = df[ok_mask(df) & df["case"].isin(list(comp.cases or []))]
    out = {}
    for m in comp.main["method"]:
        g = rows[rows["method"] == m].drop_duplicates("case").sort_values("case", kind="stable").set_index("case")
        if len(g):
            out[m] = pd.to_numeric(g[column], errors="coerce")
    return out


def case_intervals(df: pd.DataFrame, comp: Comparison) -> str:
    """The main table's intervals: per method (table order) and error column
    (:data:`INTERVAL_COLUMNS` present in ``df``) the bootstrap interval of its mean over
    the common cases (:func:`eval.present.intervals.interval_table`), each over the cases
    whose value the mean averages (:func:`common_case_values`, missing values left out);
    empty with fewer than 2 common cases."""
    if not comp.cases or len(comp.cases) < 2:
        return ""
    columns = [x for x in INTERVAL_COLUMNS if x[0] in df.columns]
    per: dict = {}
    for c, _, _ in columns:
        for m, v in common_case_values(df, comp, c).items():
            per.setdefault(m, {})[c] = v.dropna().to_numpy(float)
    return interval_table(per, columns, len(comp.cases))


def comparison_markdown(comp: Comparison, *, title: str | None = None, stops: list[str] | None = None,
                        failures: list[str] | None = None, checked: str | None = None,
                        intervals: str | None = None) -> str:
    """``table.md``'s text for a :class:`Comparison`.

    The main table (bold: best per column, all rows on the same cases) under ``title``
    and a one-line note naming the common set's size and that ``Failed`` counts failed
    runs over all the cases a method was run on; then, when ``comp.all`` is given, the
    second table ``"All cases each method ran on"``: each method's means over its own
    successful cases, without bold, since its rows average different cases (the fair
    comparison is the first table). Without ``title`` the main table is headed
    :data:`COMMON_CASES_HEADING` when the second table follows. With an empty common
    set: the note says so and the (per-method, fallback) main table has no bold.
    ``failures`` (:func:`failure_lines`): a "Failed runs" list under the main table.
    ``checked``: the sentence saying whether the rows were checked against the result
    store (:meth:`eval.run.row_check.RowCheck.line`), under the main table.
    ``intervals``: the main table's confidence intervals (:func:`case_intervals`), right
    under it.
    """
    if title is None and comp.all is not None:
        title = COMMON_CASES_HEADING
    note = main_note(comp)
    if note and comp.cases and (comp.main["n_failed"] > 0).any():
        note += " Failed: failed runs over all the cases the method was run on."
    text = to_markdown(comp.main, title=title, note=note, bold=comp.same_cases)
    if intervals:
        text += "\n" + intervals
    if checked:
        text += f"\n{checked}\n"
    if stops:
        text += "\nHow each method stopped:\n\n" + "".join(f"- {s}\n" for s in stops)
    if failures:
        text += ("\nFailed runs (left out of every mean and of the bold):\n\n"
                 + "".join(f"- {s}\n" for s in failures))
    if comp.all is not None:
        text += "\n" + to_markdown(
            comp.all, title=ALL_CASES_HEADING, bold=False, note=all_note(comp))
    return text


def write_cases(df: pd.DataFrame, out_dir) -> Path:
    """Write ``cases.csv`` atomically; returns its path."""
    p = Path(out_dir) / "cases.csv"
    with atomic_write(p, "w", newline="") as fh:
        df.to_csv(fh, index=False)
    return p


def _write_csv(summary: pd.DataFrame, p: Path) -> Path:
    with atomic_write(p, "w", newline="") as fh:
        summary.to_csv(fh, index=False, float_format="%.6g")
    return p


def _write_text(text: str, p: Path) -> Path:
    with atomic_write(p, "w") as fh:
        fh.write(text)
    return p


def compared_lines(compared: pd.DataFrame | None) -> list[str]:
    """One line per earlier run whose rows stand in the table (``compare_with``,
    :mod:`eval.run.compared`): its folder, commit, machine, methods and record count."""
    if compared is None or not len(compared) or "run" not in compared.columns:
        return []
    out = []
    for run, g in compared.groupby("run", sort=False):
        first = g.iloc[0]
        commits = g["run_commit"].map(lambda c: c if isinstance(c, str) else "unknown").value_counts(sort=False)
        words = (f"commit {commits.index[0]}" if len(commits) == 1 else
                 "commits " + ", ".join(f"{c} ({n} records)" for c, n in commits.items()))
        out.append(f"{', '.join(methods_in(g))}: {len(g)} record(s) read from {run} ({words}; "
                   f"{first.get('run_machine', '?')}), "
                   "not recomputed: each record's digest and case identity checked against this run's cases, "
                   f"and its run's {', '.join(SETTINGS)} against this run's")
    return out


def write_tables(df: pd.DataFrame, out_dir, *, title: str | None = None, cases: bool = True,
                 compared: pd.DataFrame | None = None, pending=()) -> dict[str, Path]:
    """Write ``cases.csv``, ``table.csv``, ``table.md``, ``table.tex`` and, when some
    method has successful cases outside the common set, ``table_all.csv`` into ``out_dir``
    (see the module docstring and :func:`compare`).

    Every file is written to a temporary file and renamed into place
    (:func:`sshade.files.atomic_write`), so a crash never leaves a half-written table.
    A ``table_all.csv`` left by an earlier run into the same folder is removed when this
    run has no second table, so it never describes other results. ``table.md`` says
    whether every row matches its record in the folder's result store
    (:func:`eval.run.row_check.check_rows`; a warning is logged when one does not).

    With ``cases=False`` the rows are not written back (``cases.csv`` is the input, see
    :func:`retabulate`). ``compared``: rows read from earlier runs (``compare_with``,
    :mod:`eval.run.compared`), tabulated beside ``df``'s, kept in ``compared.csv`` (not
    in ``cases.csv``, which holds this run's rows only) and listed under the table.
    ``pending``: the states of the folder's stored rows (:func:`eval.run.stale_rows.folder_states`)
    when some may be made by older code: for the rows of ``df``, the title gives their count
    and ``table.md`` lists them (:mod:`eval.run.pending_rows`).

    Returns
    -------
    dict name -> path of every file written (``cases``, ``table_csv``, ``table_md``,
    ``table_tex``, and ``table_all_csv`` when written).
    """
    import pandas as pd
    out_dir = Path(out_dir)
    paths = {"cases": write_cases(df, out_dir)} if cases else {}
    ours = df
    if compared is not None and len(compared):
        if cases:
            paths["compared"] = write_compared(out_dir, compared)
        df = pd.concat([df, compared], ignore_index=True)
    elif cases:
        for name in (COMPARED_CSV, COMPARED_RECORD):  # never rows of an earlier run's comparison
            (out_dir / name).unlink(missing_ok=True)
    comp = compare(df)
    paths["table_csv"] = _write_csv(comp.main, out_dir / "table.csv")
    p_all = out_dir / "table_all.csv"
    if comp.all is not None:
        paths["table_all_csv"] = _write_csv(comp.all, p_all)
    else:
        p_all.unlink(missing_ok=True)
    stops, checked = stop_lines(df), check_rows(ours, out_dir)
    if not checked.ok and checked.has_store:
        logging.getLogger("eval").warning("warning: %s: %s", out_dir / "cases.csv", checked.line().replace("**", ""))
    line = checked.line()
    others = compared_lines(compared)
    if others:
        line += "\n\nRows from other runs:\n\n" + "".join(f"- {x}\n" for x in others)
    tabled = set(zip(ours["case"].astype(str), ours["method"].astype(str))) if len(ours) else set()
    pending = [st for st in pending if (st.case, st.method) in tabled]  # the states of this table's rows
    marks = pending_markdown(pending)
    if marks:
        line += "\n\n" + marks
    machines = machines_line(row_machines([out_dir], pairs=tabled))
    if machines:
        line += "\n\n" + machines
    title = pending_title(title, pending)
    paths["table_md"] = _write_text(comparison_markdown(comp, title=title, stops=stops, failures=failure_lines(df),
                                                        checked=line, intervals=case_intervals(df, comp)),
                                    out_dir / "table.md")
    note = " ".join(x for x in [main_note(comp), "; ".join(stop_lines(df, short=True))] if x) or None
    paths["table_tex"] = _write_text(to_latex(comp.main, note=note, bold=comp.same_cases), out_dir / "table.tex")
    return paths


def machines_line(machines: dict[str, int]) -> str | None:
    """The line ``table.md`` gets when its rows' records were timed on more than one machine
    (``machines``: :func:`eval.run.stale_rows.row_machines` of its rows), else None: their
    Time columns are not one machine's.

    >>> machines_line({"AMD EPYC, avx2, 2 cores": 3})
    >>> two = machines_line({"AMD EPYC, avx2, 2 cores": 3, "Intel Xeon, avx512f, 2 cores": 1})
    >>> two[:93]
    '**Timed on 2 machines**: 3 rows on AMD EPYC, avx2, 2 cores; 1 on Intel Xeon, avx512f, 2 cores'
    """
    if len(machines) < 2:
        return None
    ranked = sorted(machines.items(), key=lambda kv: (-kv[1], kv[0]))
    made = "; ".join(f"{n} rows on {w}" if i == 0 else f"{n} on {w}" for i, (w, n) in enumerate(ranked))
    return (f"**Timed on {len(machines)} machines**: {made} (each row's record names its machine): their times "
            "are not one machine's, so a Time compares only within one.")


def _written_title(run_dir: Path) -> str | None:
    """The main table's title the run wrote: the first line of its ``table.md`` when it
    is a ``### `` heading (at most 4096 characters read), else None."""
    try:
        first = read_prefix(run_dir / "table.md", 4096).decode("utf-8", errors="replace").split("\n", 1)[0]
    except OSError:
        return None
    return strip_pending(first[4:]) if first.startswith("### ") and len(first) > 4 else None


def retabulate(run_dir) -> dict[str, Path]:
    """Rebuild the tables of a finished evaluator run from its ``cases.csv`` (e.g. after
    a change of the table layout), without rerunning any method; ``cases.csv`` itself
    is left as it is. The title is the one the run wrote (the first heading of its
    ``table.md``), else made from its ``run.json`` when present. Stored rows made by older
    code (:mod:`eval.run.stale_rows`) are marked pending: counted in the title, listed
    under the table with their commit (:mod:`eval.run.pending_rows`). A breakdown the run wrote
    (``breakdown.csv``, ``breakdown.md``) is made again too; its figure is kept.

    ``python -m eval.tables RUN_DIR [RUN_DIR ...]`` does the same from the shell.

    Parameters
    ----------
    run_dir : str or Path, a folder written by ``python -m eval`` (with ``cases.csv``).

    Returns
    -------
    dict name -> path of the tables written (see :func:`write_tables`).

    Raises
    ------
    SShaDeError when ``run_dir/cases.csv`` cannot be read or a row of it disagrees with
    its record (:func:`eval.run.row_check.checked_cases`), or a row of ``compared.csv``
    with the record of the compared rows (:func:`eval.run.compared.checked_compared`).
    """


    run_dir = Path(run_dir)
    refuse_results(run_dir, "python -m eval.tables rebuilds the tables of runs outside it")
    df = checked_cases(run_dir)  # a table is made from the store's rows, never from rows that disagree with it
    compared = checked_compared(run_dir)
    title = _written_title(run_dir)
    if title is None:
        try:
            cfg = read_json(run_dir / "run.json").get("config", {})
            exp, ds = cfg.get("experiment", {}).get("name"), cfg.get("dataset", {}).get("name")
            if exp:
                title = f"{exp}: {df['case'].nunique()} {ds or ''} case(s)".replace("  ", " ")
        except (OSError, ValueError, AttributeError):
            pass
    with CommitTrees() as trees:  # the stored rows made by older code (or settings) are marked pending
        states = settings_marks(folder_states(run_dir, trees), marked_pending(run_dir))
    paths = write_tables(df, run_dir, title=title, cases=False, compared=compared, pending=states)
    if (run_dir / "breakdown.csv").is_file():  # the run wrote its breakdown: made again from the same rows
        paths.update(write_breakdown(df, run_dir, figure=False))
    return paths


def main(argv=None) -> int:
    """``python -m eval.tables RUN_DIR [...]``: :func:`retabulate` each folder.

    Every folder is checked (a folder holding ``cases.csv``) before any table is written.

    Returns
    -------
    0; 2 after one ``error: ...`` line (no folder given, a folder without ``cases.csv``,
    an unknown option, an OSError such as a full disk: ``error: cannot write ...``);
    130 after ``interrupted`` on Ctrl-C. ``--help`` prints the usage (``SystemExit(0)``).
    """
    import sys

    ap = ArgumentParser(prog="python -m eval.tables",
                        description="Rebuild table.{csv,md,tex} of finished evaluator runs from their cases.csv "
                                    "(no method is rerun).")
    ap.add_argument("dirs", nargs="*", metavar="RUN_DIR", help="a folder written by python -m eval")
    a = ap.parse_args(list(sys.argv[1:] if argv is None else argv))
    if not a.dirs:
        print("usage: python -m eval.tables RUN_DIR [RUN_DIR ...] (--help for details)", file=sys.stderr)
        return 2
    missing = [d for d in a.dirs if not (Path(d) / "cases.csv").is_file()]
    if missing:
        print(f"error: no cases.csv in {', '.join(missing)} (python -m eval.tables takes folders written by "
              "python -m eval)", file=sys.stderr)
        return 2

    def work():
        for d in a.dirs:
            try:
                paths = retabulate(d)
            except OSError as e:  # e.g. ENOSPC from a write names no file: name the folder
                if e.filename is None:
                    e.filename = str(d)
                raise
            print(f"{d}: wrote {', '.join(p.name for p in paths.values())}")
    return run_command(work)


if __name__ == "__main__":
    raise SystemExit(main())

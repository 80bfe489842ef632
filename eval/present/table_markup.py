"""The tables' columns and their text: Markdown (:func:`to_markdown`) and the paper's
Table 1 layout in LaTeX (:func:`to_latex`), from a per-method summary
(:func:`eval.tables.summarize` layout: ``method``, ``n_cases``, ``n_failed`` and metric
columns); the lowest value of each column in bold where the rows average the same cases."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from eval.present.measures import EXTRA, MAIN, MEASURES, label

if TYPE_CHECKING:  # pandas is imported where a table is built
    import pandas as pd

__all__ = ["TABLE_COLUMNS", "EXTRA_COLUMNS", "NO_BOLD", "REPORTED_NOTE", "OTHER_RUN_NOTE", "time_marks", "time_notes",
           "to_markdown", "to_latex", "tex_escape"]

#: (column, Markdown header, LaTeX header, decimals, LaTeX unit suffix) of the main table
#: (:data:`eval.present.measures.MAIN`).
TABLE_COLUMNS = tuple((k, MEASURES[k].label, MEASURES[k].latex, MEASURES[k].decimals, MEASURES[k].tex_unit)
                      for k in MAIN)
#: (column, Markdown header, decimals) shown in Markdown only, when present
#: (:data:`eval.present.measures.EXTRA`).
EXTRA_COLUMNS = tuple((k, MEASURES[k].label, MEASURES[k].decimals) for k in EXTRA)
#: The line under a table with a reported Time.
REPORTED_NOTE = ("(reported): the time the method reported for itself, on its own machine (the times file of "
                 "its scored results); not measured in this run, so never compared in bold with one that was.")
#: The line under a table with a Time measured by another run (``compare_with``).
OTHER_RUN_NOTE = ("(other run): measured by the run the row was read from, on its machine (see \"Rows from other "
                  "runs\"); never compared in bold with this run's times.")
#: Columns where the lowest value is not "best": never bold.
NO_BOLD = tuple(k for k, m in MEASURES.items() if not m.best_lowest)


def _fmt(v, dec: int) -> str:
    return "--" if v is None or not math.isfinite(float(v)) else f"{float(v):.{dec}f}"


def _best(values: list[float], dec: int) -> set[int]:
    """Indices of the lowest value after rounding to ``dec`` decimals (ties: all)."""
    r = [round(float(v), dec) if v is not None and math.isfinite(float(v)) else None for v in values]
    fin = [x for x in r if x is not None]
    if len(fin) < 2:
        return set()
    lo = min(fin)
    return {i for i, x in enumerate(r) if x == lo}


def to_markdown(summary: pd.DataFrame, *, title: str | None = None, bold: bool = True,
                note: str | None = None) -> str:
    """Markdown table of the main columns.

    Parameters
    ----------
    summary : per-method table (:func:`eval.tables.summarize` layout: ``method``, ``n_cases``,
        ``n_failed`` and metric columns).
    title : ``### title`` line above the table. note : a paragraph between the title and
        the table (e.g. which cases the rows average).
    bold : mark the best (lowest) value per column in bold; pass False when the rows
        average different cases (the comparison would not be fair).
    """
    import pandas as pd
    cols = [(c, h, d) for c, h, _, d, _ in TABLE_COLUMNS if c in summary.columns]
    cols += [(c, h, d) for c, h, d in EXTRA_COLUMNS if c in summary.columns]
    failed = (summary.get("n_failed", pd.Series(dtype=int)) > 0).any()
    head = ["Method", label("n_cases"), *([label("n_failed")] if failed else []), *[h for _, h, _ in cols]]
    lines = []
    if title:
        lines += [f"### {title}", ""]
    if note:
        lines += [note, ""]
    lines += ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    reported = time_marks(summary)
    best = {c: _best(_compared(summary, c, reported), d) if bold and c not in NO_BOLD else set() for c, _, d in cols}
    for i, (_, r) in enumerate(summary.iterrows()):
        cells = [str(r["method"]), str(int(r["n_cases"]))]
        if failed:
            cells.append(str(int(r["n_failed"])))
        for c, _, d in cols:
            if MEASURES.get(c) is not None and MEASURES[c].fraction:  # mean of a boolean: show as k/n
                v = r[c]
                s = "--" if v is None or not math.isfinite(float(v)) else \
                    f"{int(round(float(v) * int(r['n_cases'])))}/{int(r['n_cases'])}"
            else:
                s = _fmt(r[c], d)
                if c == "time_s" and i in reported and s != "--":
                    s += " " + reported[i]
            cells.append(f"**{s}**" if i in best[c] else s)
        lines.append("| " + " | ".join(cells) + " |")
    for n in time_notes(summary):
        lines += ["", n]
    return "\n".join(lines) + "\n"


def _positive(v) -> bool:
    try:
        return float(v) > 0
    except (TypeError, ValueError):
        return False


def time_marks(summary) -> dict[int, str]:
    """Position -> mark of the rows whose Time was not measured in this run: the method
    reported it itself (``time_reported``: computed elsewhere,
    :class:`eval.exchange.scored.ScoredResults`; ``(reported)``) or another run measured
    it (``time_other_run``: a ``compare_with`` row, :mod:`eval.run.compared`; ``(other run)``)."""
    out = {}
    for col, mark in (("time_other_run", "(other run)"), ("time_reported", "(reported)")):
        if col in summary.columns:
            out.update({i: mark for i, v in enumerate(summary[col]) if _positive(v)})
    return out


def time_notes(summary) -> list[str]:
    """The notes a table with Time cells not measured in this run needs (:data:`REPORTED_NOTE`,
    :data:`OTHER_RUN_NOTE`), in that order."""
    marks = set(time_marks(summary).values())
    return [n for m, n in (("(reported)", REPORTED_NOTE), ("(other run)", OTHER_RUN_NOTE)) if m in marks]


def _compared(summary, c: str, reported: set[int]) -> list:
    """Column ``c``'s values for the bold: a reported time is never compared with one
    measured here (another machine, another clock)."""
    return [None if c == "time_s" and i in reported else v for i, v in enumerate(summary[c])]


def to_latex(summary: pd.DataFrame, *, note: str | None = None, bold: bool = True) -> str:
    """The paper's Table 1 layout: ``Method & Volume & Area & EL & FA & Time``.

    Percentages with ``\\%``, FA in degrees with ``\\textdegree``, time in seconds;
    lowest value per column in ``\\textbf`` (unless ``bold`` is False); ``--`` where a
    value is missing. ``note`` (plain text, escaped here): a footnote-size row below
    the table and a ``%`` comment line on top, e.g. the number of cases averaged.
    """
    cols = list(TABLE_COLUMNS)
    reported = time_marks(summary)
    best = {c: _best(_compared(summary, c, reported) if c in summary.columns and bold else [], d)
            for c, _, _, d, _ in cols}
    out = ["% Generated by eval.tables: mean over successful cases; needs \\usepackage{booktabs}"]
    if note:
        out.append(f"% {note}")
    out += ["\\begin{tabular}{l cccc c}", "\\toprule",
            "Method & " + " & ".join(t for _, _, t, _, _ in cols) + " \\\\", "\\midrule"]
    for i, (_, r) in enumerate(summary.iterrows()):
        cells = [tex_escape(str(r["method"]))]
        for c, _, _, d, unit in cols:
            v = r[c] if c in summary.columns else float("nan")
            s = _fmt(v, d)
            if s != "--":
                s += unit
                if c == "time_s" and i in reported:
                    s += "$^r$" if reported[i] == "(reported)" else "$^o$"
                if i in best[c]:
                    s = f"\\textbf{{{s}}}"
            cells.append(s)
        out.append(" & ".join(cells) + " \\\\")
    out.append("\\bottomrule")
    for n in time_notes(summary):
        note = (f"{note} " if note else "") + n.replace("(reported):", "r:").replace("(other run):", "o:")
    if note:
        # a paragraph cell, so a long note wraps instead of widening the table
        out.append(f"\\multicolumn{{{1 + len(cols)}}}{{p{{0.9\\columnwidth}}}}"
                   f"{{\\footnotesize {tex_escape(note)}}} \\\\")
    out.append("\\end{tabular}")
    return "\n".join(out) + "\n"


def tex_escape(s: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("_", r"\_"), ("#", r"\#")):
        s = s.replace(a, b)
    return s

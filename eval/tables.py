"""Per-case results -> per-method tables (CSV, Markdown, LaTeX), written atomically.

Input: a pandas DataFrame with one row per (case, method) as produced by
:mod:`eval.app`: identifiers (``case``, ``subject``, ``pose``, ``method``), sizes
(``n_vertices``, ``n_handles``, ``n_static``), the metrics of :mod:`eval.metrics`
(``volume_err_pct``, ``area_err_pct``, ``edge_err_pct``, ``angle_err_deg``,
``angle_err_rel_pct``, ``handle_err_pct``, ``gt_vertex_mean_pct``,
``gt_vertex_max_pct``, ``hausdorff``, ``chamfer``), ``time_s`` (seconds of the
``deform`` call), method info (``iterations``, ``remesh_s``, ...) and ``error``
(empty when the method succeeded).

Outputs (in ``out_dir``):

- ``cases.csv``: the rows as given;
- ``table.csv``: per-method means over the successful cases of every numeric column,
  with ``n_cases`` (successful) and ``n_failed``;
- ``table.md``: the main columns as a Markdown table;
- ``table.tex``: the paper's Table 1 layout (Method | Volume | Area | EL | FA | Time),
  booktabs, best (lowest) value per column in bold. Needs ``\\usepackage{booktabs}``.

Rows are ordered ARAP, Elastic, SShaDe, then any other method by name.
"""
from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from defaust.meshio import atomic_write

__all__ = ["summarize", "write_tables", "to_markdown", "to_latex", "METHOD_ORDER", "TABLE_COLUMNS"]

METHOD_ORDER = ("ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "SShaDe")

#: Columns never averaged (identifiers, seeds).
_ID_COLUMNS = ("case", "subject", "pose", "method", "error", "case_seed", "seeds", "seed")

#: (column, Markdown header, LaTeX header, decimals, LaTeX unit suffix) of the main table.
TABLE_COLUMNS = (
    ("volume_err_pct", "Volume (%)", "Volume", 2, r"\%"),
    ("area_err_pct", "Area (%)", "Area", 2, r"\%"),
    ("edge_err_pct", "EL (%)", "EL", 2, r"\%"),
    ("angle_err_deg", "FA (deg)", "FA", 3, r"\textdegree"),
    ("time_s", "Time (s)", "Time", 2, "s"),
)
#: Extra columns shown in Markdown only (when present).
_MD_EXTRA = (
    ("angle_err_rel_pct", "FA rel (%)", 2),
    ("handle_err_pct", "Handle (%)", 3),
    ("gt_vertex_mean_pct", "GT mean (%)", 2),
    ("chamfer", "Chamfer", 5),
)


def _order_key(m: str):
    return (METHOD_ORDER.index(m), "") if m in METHOD_ORDER else (len(METHOD_ORDER), m)


def summarize(df: pd.DataFrame) -> pd.DataFrame:
    """Per-method means over successful cases.

    Parameters
    ----------
    df : per-case rows (see module docstring); needs a ``method`` column.

    Returns
    -------
    DataFrame, one row per method (ordered ARAP, Elastic, SShaDe, others), columns
    ``method``, ``n_cases``, ``n_failed`` and the mean of every numeric (or boolean)
    column except identifiers. A method that failed everywhere has NaN means.
    """
    if "method" not in df.columns:
        raise ValueError("results have no 'method' column")
    err = df["error"].fillna("").astype(str) if "error" in df.columns else pd.Series("", index=df.index)
    ok = err.str.len() == 0
    num_cols = []
    for c in df.columns:
        if c in _ID_COLUMNS:
            continue
        s = df[c]
        if pd.api.types.is_bool_dtype(s) or pd.api.types.is_numeric_dtype(s):
            num_cols.append(c)
        elif s.dtype == object and len(s.dropna()):
            # e.g. booleans mixed with NaN where a method failed
            try:
                s.dropna().astype(float)
            except (TypeError, ValueError):
                continue
            num_cols.append(c)
    rows = []
    for m in sorted(df["method"].unique(), key=_order_key):
        sel = df["method"] == m
        good = df[sel & ok]
        row = {"method": m, "n_cases": int(len(good)), "n_failed": int((sel & ~ok).sum())}
        for c in num_cols:
            v = good[c].dropna().astype(float)
            row[c] = float(v.mean()) if len(v.dropna()) else float("nan")
        rows.append(row)
    return pd.DataFrame(rows, columns=["method", "n_cases", "n_failed", *num_cols])


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


def to_markdown(summary: pd.DataFrame, *, title: str | None = None) -> str:
    """Markdown table of the main columns (best per column in bold)."""
    cols = [(c, h, d) for c, h, _, d, _ in TABLE_COLUMNS if c in summary.columns]
    cols += [(c, h, d) for c, h, d in _MD_EXTRA if c in summary.columns]
    head = ["Method", "Cases", *[h for _, h, _ in cols]]
    if (summary.get("n_failed", pd.Series(dtype=int)) > 0).any():
        head.insert(2, "Failed")
    lines = []
    if title:
        lines += [f"### {title}", ""]
    lines += ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    best = {c: _best(list(summary[c]), d) for c, _, d in cols}
    for i, (_, r) in enumerate(summary.iterrows()):
        cells = [str(r["method"]), str(int(r["n_cases"]))]
        if "Failed" in head:
            cells.append(str(int(r["n_failed"])))
        for c, _, d in cols:
            s = _fmt(r[c], d)
            cells.append(f"**{s}**" if i in best[c] else s)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def to_latex(summary: pd.DataFrame) -> str:
    """The paper's Table 1 layout: ``Method & Volume & Area & EL & FA & Time``.

    Percentages with ``\\%``, FA in degrees with ``\\textdegree``, time in seconds;
    lowest value per column in ``\\textbf``; ``--`` where a value is missing.
    """
    cols = list(TABLE_COLUMNS)
    best = {c: _best(list(summary[c]) if c in summary.columns else [], d) for c, _, _, d, _ in cols}
    out = ["% Generated by eval.tables: mean over successful cases; needs \\usepackage{booktabs}",
           "\\begin{tabular}{l cccc c}", "\\toprule",
           "Method & " + " & ".join(t for _, _, t, _, _ in cols) + " \\\\", "\\midrule"]
    for i, (_, r) in enumerate(summary.iterrows()):
        cells = [_tex_escape(str(r["method"]))]
        for c, _, _, d, unit in cols:
            v = r[c] if c in summary.columns else float("nan")
            s = _fmt(v, d)
            if s != "--":
                s += unit
                if i in best[c]:
                    s = f"\\textbf{{{s}}}"
            cells.append(s)
        out.append(" & ".join(cells) + " \\\\")
    out += ["\\bottomrule", "\\end{tabular}"]
    return "\n".join(out) + "\n"


def _tex_escape(s: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("&", r"\&"), ("%", r"\%"), ("_", r"\_"), ("#", r"\#")):
        s = s.replace(a, b)
    return s


def write_cases(df: pd.DataFrame, out_dir) -> Path:
    """Write ``cases.csv`` atomically; returns its path."""
    p = Path(out_dir) / "cases.csv"
    with atomic_write(p, "w", newline="") as fh:
        df.to_csv(fh, index=False)
    return p


def write_tables(df: pd.DataFrame, out_dir, *, title: str | None = None) -> dict[str, Path]:
    """Write ``cases.csv``, ``table.csv``, ``table.md`` and ``table.tex`` into ``out_dir``.

    Every file is written to a temporary file and renamed into place
    (:func:`defaust.meshio.atomic_write`), so a crash never leaves a half-written table.

    Returns
    -------
    dict name -> path (``cases``, ``table_csv``, ``table_md``, ``table_tex``); the
    per-method means themselves come from :func:`summarize`.
    """
    out_dir = Path(out_dir)
    paths = {"cases": write_cases(df, out_dir)}
    summ = summarize(df)
    p = out_dir / "table.csv"
    with atomic_write(p, "w", newline="") as fh:
        summ.to_csv(fh, index=False, float_format="%.6g")
    paths["table_csv"] = p
    p = out_dir / "table.md"
    with atomic_write(p, "w") as fh:
        fh.write(to_markdown(summ, title=title))
    paths["table_md"] = p
    p = out_dir / "table.tex"
    with atomic_write(p, "w") as fh:
        fh.write(to_latex(summ))
    paths["table_tex"] = p
    return paths


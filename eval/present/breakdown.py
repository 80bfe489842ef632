"""Breakdowns of an evaluator run next to its ``table.md``: per target pose
and per subject, and a paired comparison of SShaDe with Elastic.
Floor 2 of eval/ (eval/present/, tests/test_layering.py); notes: docs/implementation.md.

Input: the per-case rows of ``cases.csv`` (columns ``case``, ``subject``, ``pose``,
``method``, ``error`` and the metrics; :mod:`eval.experiments.cases.cases_experiment`). Only successful
rows (:func:`eval.tables.ok_mask`) with a finite value of a metric count for it."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from baselines.fullres_arap import Elastic
from eval.present.figures import distribution_figure, safe_figure
from eval.present.intervals import CI, bootstrap_ci, interval_text, interval_words
from eval.present.measures import BROKEN_DOWN, label
from eval.present.rows import method_order_key, ok_mask
from sshade.files import atomic_write
from sshade.pipeline import SShaDe

__all__ = ["BREAKDOWN_METRICS", "group_breakdown", "paired_comparison", "breakdown_markdown", "write_breakdown"]

#: (column, label) of the metrics broken down, in this order (when present):
#: :data:`eval.present.measures.BROKEN_DOWN`.
BREAKDOWN_METRICS = tuple((k, label(k)) for k in BROKEN_DOWN)


def _metrics(df: pd.DataFrame) -> list[tuple[str, str]]:
    return [(c, lab) for c, lab in BREAKDOWN_METRICS if c in df.columns]


def group_breakdown(df: pd.DataFrame, by=("pose", "subject")) -> pd.DataFrame:
    """Per-group statistics of every metric per method.

    Parameters
    ----------
    df : per-case rows (``cases.csv``). by : the grouping columns, each on its own.

    Returns
    -------
    DataFrame with columns ``by``, ``group``, ``method``, ``metric``, ``n``, ``mean``,
    ``std`` (ddof 1, NaN for n = 1), ``median``, ``min``, ``max``, ``ci_lo``, ``ci_hi``
    (the mean's interval over the group's cases, :func:`eval.present.intervals.bootstrap_ci`
    of the values in case order; NaN for n = 1); methods in table order; groups sorted.
    Empty (those columns) when nothing qualifies.
    """
    cols = ["by", "group", "method", "metric", "n", "mean", "std", "median", "min", "max", "ci_lo", "ci_hi"]
    ok = df[ok_mask(df)] if len(df) else df
    out = []
    for b in by:
        if b not in ok.columns or ok[b].isna().all():
            continue
        for col, _ in _metrics(ok):
            v = ok[[b, "method", col, *(["case"] if "case" in ok.columns else [])]].copy()
            v[col] = pd.to_numeric(v[col], errors="coerce")
            v = v[np.isfinite(v[col])]
            if "case" in v.columns:
                v = v.sort_values("case", kind="stable")
            for (g, m), x in v.groupby([b, "method"], sort=True)[col]:
                ci = bootstrap_ci(x.to_numpy(float)) or (math.nan, math.nan)
                out.append([b, g, m, col, len(x), x.mean(), x.std(ddof=1) if len(x) > 1 else math.nan,
                            x.median(), x.min(), x.max(), *ci])
    res = pd.DataFrame(out, columns=cols)
    if len(res):
        order = [c for c, _ in BREAKDOWN_METRICS]
        res["_b"] = res["by"].map(list(by).index)
        res["_m"] = res["metric"].map(order.index)
        res["_k"] = res["method"].map(method_order_key)
        res = res.sort_values(["_b", "_m", "group", "_k"], kind="stable").drop(columns=["_b", "_m", "_k"])
    return res.reset_index(drop=True)


def paired_comparison(df: pd.DataFrame, a: str = SShaDe.name, b: str = Elastic.name,
                      metric: str = "volume_err_pct") -> dict | None:
    """Method ``a`` against ``b`` on their common successful cases (finite ``metric``).

    Returns
    -------
    None when either method or the metric is absent or they share no case; else a dict
    with ``a``, ``b``, ``metric``, ``n`` (common cases), ``n_a_lower`` (cases where a's
    value is below b's), ``n_ties``, ``median_diff`` (median of a - b, the metric's
    unit), ``ci_lo``, ``ci_hi`` (the percentile bootstrap of that median over the cases,
    :func:`eval.present.intervals.bootstrap_ci`), ``n_boot``, ``seed``, ``level`` (its
    :data:`eval.present.intervals.CI`; ``ci_lo = ci_hi = median_diff`` for one case).

    >>> d = pd.DataFrame({"case": ["c1", "c2", "c1", "c2"], "method": ["SShaDe"] * 2 + ["Elastic"] * 2,
    ...                   "error": "", "volume_err_pct": [1.0, 3.0, 2.0, 2.0]})
    >>> r = paired_comparison(d); (r["n"], r["n_a_lower"], r["median_diff"])
    (2, 1, 0.0)
    """
    if metric not in df.columns or "method" not in df.columns:
        return None
    ok = df[ok_mask(df)]
    vals = {}
    for m in (a, b):
        x = ok[ok["method"] == m].drop_duplicates("case").set_index("case")[metric]
        vals[m] = pd.to_numeric(x, errors="coerce")
    j = pd.concat([vals[a].rename("a"), vals[b].rename("b")], axis=1, join="inner").dropna()
    j = j[np.isfinite(j["a"]) & np.isfinite(j["b"])]
    if not len(j):
        return None
    d = (j["a"] - j["b"]).to_numpy(float)
    lo, hi = bootstrap_ci(d, np.median) or (float(np.median(d)),) * 2
    level, n_boot, seed = CI
    return {"a": a, "b": b, "metric": metric, "n": len(d), "n_a_lower": int((d < 0).sum()),
            "n_ties": int((d == 0).sum()), "median_diff": float(np.median(d)), "ci_lo": float(lo),
            "ci_hi": float(hi), "n_boot": int(n_boot), "seed": int(seed), "level": float(level)}


def _cell(r) -> str:
    if r is None:
        return "-"
    s = f"{r['mean']:.3g}"
    ci = interval_text((r.get("ci_lo", math.nan), r.get("ci_hi", math.nan)), ".3g")
    return (s + (f" ± {r['std']:.2g}" if r["std"] == r["std"] else "") + (f" (n={r['n']})" if r["n"] != 1 else "")
            + (f" [{ci}]" if ci else ""))


def _paired_text(p: dict | None, a: str, b: str, metric: str) -> list[str]:
    if p is None:
        return [f"No case where both {a} and {b} succeeded with a {metric} value: no paired comparison."]
    return [f"On {p['n']} case(s) where both succeeded, {a}'s {p['metric']} is below {b}'s on {p['n_a_lower']}"
            f" ({p['n_ties']} tie(s)). Median of the differences {a} - {b}: {p['median_diff']:.4g}"
            f" ({p['level']:.0%} bootstrap interval {p['ci_lo']:.4g} .. {p['ci_hi']:.4g}; "
            f"{p['n_boot']} resamples of the cases, seed {p['seed']})."]


def breakdown_markdown(df: pd.DataFrame, br: pd.DataFrame | None = None, *, a: str = SShaDe.name, b: str = Elastic.name,
                       metric: str = "volume_err_pct") -> str:
    """``breakdown.md``'s text: per (``by``, metric) a table of "mean ± std (n)" with the
    groups as rows and the methods (table order) as columns, then the paired comparison."""
    br = group_breakdown(df) if br is None else br
    lines = ["# Breakdowns", "", "Mean ± sample standard deviation (n cases when not 1) over the successful cases "
             f"of each group, and in brackets its {interval_words()}.", ""]
    labels = dict(BREAKDOWN_METRICS)
    for (by, col), t in br.groupby(["by", "metric"], sort=False):
        methods = sorted(t["method"].unique(), key=method_order_key)
        lines += [f"## Per {by}: {labels.get(col, col)}", "", "| " + " | ".join([by, *methods]) + " |",
                  "|" + "---|" * (len(methods) + 1)]
        for g, tg in t.groupby("group", sort=True):
            by_m = {r["method"]: r for r in tg.to_dict("records")}
            lines.append("| " + " | ".join([str(g), *[_cell(by_m.get(m)) for m in methods]]) + " |")
        lines.append("")
    lines += [f"## Paired comparison: {a} vs {b} ({metric})", ""]
    lines += _paired_text(paired_comparison(df, a, b, metric), a, b, metric)
    return "\n".join(lines) + "\n"


def write_breakdown(df: pd.DataFrame, out_dir, *, figure: bool = False) -> dict[str, Path]:
    """Write ``breakdown.csv`` and ``breakdown.md`` (atomically) into ``out_dir`` and,
    with ``figure``, ``breakdown.png`` (never raises for the figure: a warning is
    logged). Returns name -> path of the files written (``breakdown_csv``,
    ``breakdown_md``, ``breakdown_png``)."""
    out_dir = Path(out_dir)
    br = group_breakdown(df)
    paths = {}
    with atomic_write(out_dir / "breakdown.csv", "w", newline="") as fh:
        br.to_csv(fh, index=False, float_format="%.6g")
    paths["breakdown_csv"] = out_dir / "breakdown.csv"
    with atomic_write(out_dir / "breakdown.md", "w") as fh:
        fh.write(breakdown_markdown(df, br))
    paths["breakdown_md"] = out_dir / "breakdown.md"
    ok = df[ok_mask(df)] if len(df) else df
    if figure and len(ok):
        p = safe_figure("distribution", distribution_figure, ok, out_dir / "breakdown.png",
                        metrics=_metrics(ok), methods=sorted(ok["method"].unique(), key=method_order_key))
        if p is not None:
            paths["breakdown_png"] = Path(p)
    return paths

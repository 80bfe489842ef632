"""Confidence intervals over cases: the percentile bootstrap every table, breakdown and
leaderboard of the evaluator states its intervals with (:data:`CI`,
:func:`bootstrap_ci`), and the lines that show them under a table
(:func:`interval_table`).

A benchmark over a few dozen cases ranks methods whose means differ by less than the draw
of the cases; an interval over the cases says how far each mean would move with another
draw of as many cases. The cases are resampled with replacement (Efron & Tibshirani 1993,
§13.3, the percentile interval), seeded, so a table is the same at every rendering.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["CI", "bootstrap_ci", "interval_text", "interval_words", "interval_table"]

#: (level, resamples, seed) of every interval the evaluator states.
CI = (0.95, 2000, 0)


def bootstrap_ci(values, stat=np.mean) -> tuple[float, float] | None:
    """The :data:`CI` percentile-bootstrap interval of ``stat`` (a numpy reduction taking
    ``axis``; default the mean) of ``values`` ((c,) float, one per case; the cases
    resampled with replacement, seeded), or None for fewer than 2 values.

    >>> bootstrap_ci([1.0, 1.0, 1.0])
    (1.0, 1.0)
    >>> lo, hi = bootstrap_ci([1.0, 2.0, 3.0, 4.0]); 1.0 <= lo < 2.5 < hi <= 4.0
    True
    """
    v = np.asarray(values, float)
    if len(v) < 2:
        return None
    level, n, seed = CI
    boots = stat(v[np.random.default_rng(seed).integers(0, len(v), (n, len(v)))], axis=1)
    lo, hi = np.quantile(boots, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def interval_text(ci, spec: str) -> str | None:
    """An interval ``(lo, hi)`` as ``"lo .. hi"``, each bound in the format ``spec``
    (e.g. ``".2f"``); None for None or a bound that is not finite.

    >>> interval_text((1.234, 2.5), ".2f"), interval_text(None, ".2f")
    ('1.23 .. 2.50', None)
    """
    if ci is None or not all(math.isfinite(float(x)) for x in ci):
        return None
    return f"{ci[0]:{spec}} .. {ci[1]:{spec}}"


def interval_words(what: str = "mean", cases: int | None = None) -> str:
    """How :func:`bootstrap_ci` makes an interval, in words (for a table's note), over
    ``cases`` cases when given.

    >>> interval_words(cases=40)
    '95% percentile-bootstrap interval of the mean over the 40 cases (2000 resamples, seed 0)'
    """
    level, n, seed = CI
    over = "the cases" if cases is None else f"the {cases} cases"
    return f"{level:.0%} percentile-bootstrap interval of the {what} over {over} ({n} resamples, seed {seed})"


def interval_table(per_case: dict, columns, cases: int) -> str:
    """A Markdown table of each method's :func:`bootstrap_ci` per column, under a line
    saying what they are; empty with fewer than 2 cases.

    Parameters
    ----------
    per_case : ``{method: {column: (c,) float values, one per case}}``, in table order.
    columns : (column, header, decimals) of the columns to show, in order.
    cases : the number of cases c the values are over.

    >>> print(interval_table({"A": {"x": [1.0, 2.0]}}, [("x", "X (%)", 1)], 2).splitlines()[2])
    | Method | X (%) |
    """
    if cases < 2 or not per_case:
        return ""
    lines = [f"Each mean's {interval_words(cases=cases)}:", "",
             "| Method | " + " | ".join(h for _, h, _ in columns) + " |",
             "|---|" + "---:|" * len(columns)]
    for m, cols in per_case.items():
        cells = [interval_text(bootstrap_ci(cols[c]) if c in cols else None, f".{dec}f") or "--"
                 for c, _, dec in columns]
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

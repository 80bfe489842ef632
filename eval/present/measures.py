"""The measures a result is scored by, each described once: its column in ``cases.csv``,
its label with its unit, its decimals, its LaTeX header, whether lower is better and how a
table shows it (:class:`Measure`, :data:`MEASURES`). The tables (:mod:`eval.tables`,
:mod:`eval.present.table_markup`), the breakdown, the browser report and the leaderboard
take their headers from here (:func:`label`), so a measure is added or renamed in one
place. What each metric measures: :mod:`eval.metrics.measures`; notes: docs/experiments.md.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Measure", "MEASURES", "MAIN", "EXTRA", "BROKEN_DOWN", "label"]


@dataclass(frozen=True)
class Measure:
    """One measure.

    Attributes
    ----------
    key : its column in ``cases.csv`` (a metric of :mod:`eval.metrics` or a method's info).
    label : its Markdown header, with its unit (``"Volume (%)"``).
    decimals : the decimals a table shows it with.
    latex : its header in the paper's Table 1 layout (None: not a Table 1 column).
    tex_unit : the LaTeX suffix of its values there (``r"\\%"``).
    best_lowest : the lowest value is the best (bold in a table of the same cases); False
        for a count or a stopping state, never bold.
    fraction : a mean of booleans, shown as ``k/n`` cases.
    """

    key: str
    label: str
    decimals: int
    latex: str | None = None
    tex_unit: str = ""
    best_lowest: bool = True
    fraction: bool = False


MEASURES = {m.key: m for m in (
    Measure("volume_err_pct", "Volume (%)", 2, "Volume", r"\%"),
    Measure("area_err_pct", "Area (%)", 2, "Area", r"\%"),
    Measure("edge_err_pct", "EL (%)", 2, "EL", r"\%"),
    Measure("angle_err_deg", "FA (deg)", 3, "FA", r"\textdegree"),
    Measure("time_s", "Time (s)", 2, "Time", "s"),
    Measure("angle_err_rel_pct", "FA rel (%)", 2),
    Measure("handle_err_pct", "Handle (%)", 3),
    Measure("handle_pre_pct", "Handle pre (%)", 3),
    Measure("gt_vertex_mean_pct", "GT mean (%)", 2),
    Measure("chamfer", "Chamfer", 5),
    Measure("ref_mean_pct", "Ref mean (%)", 3),
    Measure("ref_max_pct", "Ref max (%)", 2),
    Measure("energy_gap", "E gap", 4),
    Measure("iterations", "Iters", 0, best_lowest=False),
    Measure("converged", "Converged", 0, best_lowest=False, fraction=True),
)}

#: The main table's measures (the paper's Table 1), in order.
MAIN = ("volume_err_pct", "area_err_pct", "edge_err_pct", "angle_err_deg", "time_s")
#: The measures shown after them in Markdown and HTML tables (when present), in order.
EXTRA = ("angle_err_rel_pct", "handle_err_pct", "handle_pre_pct", "gt_vertex_mean_pct", "chamfer", "ref_mean_pct",
         "ref_max_pct", "energy_gap", "iterations", "converged")
#: The measures a breakdown per pose and subject shows, in order.
BROKEN_DOWN = ("volume_err_pct", "area_err_pct", "edge_err_pct", "angle_err_deg", "gt_vertex_mean_pct")


def label(key: str) -> str:
    """The header of measure ``key`` (:data:`MEASURES`); the key itself for a column that is
    not a measure.

    >>> label("edge_err_pct"), label("n_low")
    ('EL (%)', 'n_low')
    """
    m = MEASURES.get(key)
    return key if m is None else m.label

"""The measures a result is scored by, each described once: its column in ``cases.csv``,
its label with its unit, its decimals, its LaTeX header, whether lower is better and how a
table shows it (:class:`Measure`, :data:`MEASURES`); and every other column a table shows,
the experiments' own tables' included (:class:`Column`, :data:`COUNTS`, :data:`TABLES`).
The tables (:mod:`eval.tables`, :mod:`eval.present.table_markup`), the breakdown, the
browser report, the leaderboard and the experiments take their headers from here
(:func:`label`, :func:`columns`), so a column is added or renamed in one place. What each
metric measures: :mod:`eval.metrics.measures`; notes: docs/implementation.md and docs/layout.md.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Measure", "MEASURES", "MAIN", "EXTRA", "BROKEN_DOWN", "Column", "COUNTS", "TABLES", "label",
           "measure_column", "columns"]


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


@dataclass(frozen=True)
class Column:
    """A column of a summary table that is not one of :data:`MEASURES` as the main tables
    show it: a count, an experiment's own quantity, or a measure an experiment shows with
    its own header and precision.

    Attributes
    ----------
    key : its column in the table's rows.
    label : its Markdown header, with its unit.
    fmt : the ``str.format`` of a cell (``"{:.2f}"``), or None where the table writes the
        cell itself (a range of two columns).
    """

    key: str
    label: str
    fmt: str | None


def _measure(key: str) -> Column:
    """Measure ``key`` (:data:`MEASURES`) as a column, with its own label and decimals."""
    m = MEASURES[key]
    return Column(key, m.label, f"{{:.{m.decimals}f}}")


#: The count columns of every summary table (cases of a row, and how many of them failed).
COUNTS = (Column("n_cases", "Cases", "{:.0f}"), Column("n_failed", "Failed", "{:.0f}"))

#: The shape-correspondence tables' distances (TOSCA, pose transfer): the ground-truth
#: errors there are 10-100 times smaller than a deformation's, hence their own headers
#: (``% diag``) and decimals beside the main tables' ``GT mean (%)``.
_HAUSDORFF, _CHAMFER = Column("hausdorff", "d_H", "{:.3e}"), Column("chamfer", "d_C", "{:.3e}")
_VERTEX_MAX = Column("gt_vertex_max_pct", "Vertex max (% diag)", "{:.3f}")

#: The experiments' own tables: experiment -> its columns, in order (:func:`columns`).
TABLES = {
    "tosca": (
        Column("n_vertices", "Vertices", "{:.0f}"), *COUNTS, Column("n_low", "n_low", "{:.0f}"),
        _HAUSDORFF, _CHAMFER,
        Column("gt_vertex_mean_pct", "Vertex mean (% diag)", "{:.4f}"), _VERTEX_MAX,
        Column("rest_hausdorff", "d_H rest vs pose", "{:.3e}"),
        Column("gt_stretch_pct", "GT stretch (%)", "{:.2f}"),
        _measure("time_s")),
    "pose_transfer": (
        *COUNTS,
        Column("gt_vertex_mean_pct", "Vertex mean (% diag)", "{:.3f}"), _VERTEX_MAX,
        _HAUSDORFF, _CHAMFER,
        Column("stretch_vs_S_pct", "Stretch vs S (%)", "{:.2f}"),
        _measure("time_s")),
    "animation": (
        COUNTS[0],
        Column("n_frames", "Frames", "{:.0f}"),
        Column("frame_median_s", "Frame (s, median)", "{:.3f}"),
        Column("frame_min_s", "Fastest (s)", "{:.3f}"),
        Column("frame_max_s", "Slowest (s)", "{:.3f}"),
        Column("gt_mean_pct", "GT error (% diag, mean over frames)", "{:.3f}"),
        Column("gt_last_pct", "GT error at the last frame (% diag)", "{:.3f}"),
        Column("jitter_pct", "Jitter (% diag)", "{:.4f}"),
        Column("n_converged", "Converged frames", "{:.0f}")),
    "scaling": (
        Column("vertices", "Vertices", "{:.0f}"),
        Column("n_low", "n_low", "{:.0f}"),
        Column("k", "k", "{:.0f}"),
        Column("remesh_s", "Remesh (s)", "{:.2f}"),
        Column("repair_rounds_max", "Repair rounds (max)", "{:.0f}"),
        Column("repair_seeds", "Repair seeds", "{:.0f}"),
        Column("lowres_arap_s", "Low-res ARAP (s)", "{:.2f}"),
        Column("lowres_iters_first", "Iters (first / warm mean)", None),
        Column("transfer_s", "Transfer (s)", "{:.2f}"),
        Column("sshade_total_s", "SShaDe total (s, median)", "{:.2f}"),
        Column("sshade_total_min_s", "Range (s)", None),
        Column("first_call_s", "First call (s, median)", "{:.2f}"),
        Column("first_call_min_s", "First call range (s)", None),
        Column("sshade_compile_s", "Compile (s)", "{:.2f}"),
        Column("peak_mem_mb", "Peak mem (MB)", "{:.0f}"),
        Column("call_mem_mb", "Call mem (MB)", "{:.0f}"),
        Column("sshade_volume_err_pct", "Vol (%)", "{:.2f}"),
        Column("sshade_edge_err_pct", MEASURES["edge_err_pct"].label, "{:.2f}"),
        Column("sshade_angle_err_deg", MEASURES["angle_err_deg"].label, "{:.3f}"),
        Column("seed_spread_pct", "Seed spread (% diag)", "{:.3f}"),
        Column("elastic_precompute_s", "Elastic precompute (s)", "{:.2f}"),
        Column("elastic_s_per_iter", "Elastic s/iter", "{:.3f}"),
        Column("elastic_iters", "Elastic iters", "{:.0f}"),
        Column("elastic_total_s", "Elastic total (s)", "{:.1f}"),
        Column("speedup", "Speed-up", "{:.1f}x")),
}


def label(key: str) -> str:
    """The header of measure ``key`` (:data:`MEASURES`) or count column (:data:`COUNTS`);
    the key itself for any other column.

    >>> label("edge_err_pct"), label("n_failed"), label("n_low")
    ('EL (%)', 'Failed', 'n_low')
    """
    m = MEASURES.get(key)
    if m is not None:
        return m.label
    return next((c.label for c in COUNTS if c.key == key), key)


def measure_column(key: str) -> tuple[str, str, str]:
    """Measure ``key`` as a table column ``(key, label, fmt)``, its decimals its own.

    >>> measure_column("time_s")
    ('time_s', 'Time (s)', '{:.2f}')
    """
    c = _measure(key)
    return c.key, c.label, c.fmt


def columns(table: str) -> tuple[tuple[str, str, str | None], ...]:
    """The columns of experiment ``table``'s own table (:data:`TABLES`) as ``(key, label,
    fmt)``, in order. KeyError for a table that is not there.

    >>> columns("pose_transfer")[0]
    ('n_cases', 'Cases', '{:.0f}')
    """
    return tuple((c.key, c.label, c.fmt) for c in TABLES[table])

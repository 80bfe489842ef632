"""What a built DeFAUST folder holds, case by case (``python -m defaust describe``): sizes,
handles, and how far the ground truth is from volume- and area-preserving, measured on the
files (docs/defaust.md §4, known limitations). The ground truth of an ANNY or synthetic
build is the linear blend skinning of the target pose (paper appendix A), which does not
preserve volume: a perfect result's volume error (paper §4) is this change, not zero.

Example::

    rows = describe("data/defaust", resolution="high")
    rows[0]["gt_volume_change_pct"], summary(rows)["gt_volume_change_pct"]
"""
from __future__ import annotations

import numpy as np

from .dataset import load, read_manifest

__all__ = ["COLUMNS", "describe", "summary", "markdown"]

#: The columns of :func:`describe`, in order, with what each holds.
COLUMNS = {
    "case": "case name s{subject}_p{pose}",
    "pose_name": "the target pose's name",
    "n_vertices": "vertices of the mesh read",
    "n_handles": "handles kept after the snap",
    "n_static": "of them static",
    "n_dropped": "handles dropped (a nearer handle took their vertex)",
    "gt_volume_change_pct": ("signed volume of the ground truth minus the rest's, % of the rest's "
                             "(empty: no ground truth)"),
    "gt_area_change_pct": "surface area of the ground truth minus the rest's, % of the rest's",
    "self_intersecting_faces_high": "faces of the high-res ground truth that intersect another (the builder's count)",
}


def _volume_area(V: np.ndarray, F: np.ndarray) -> tuple[float, float]:
    """(signed enclosed volume, surface area) by trimesh: the divergence theorem over the
    faces (outward orientation positive) and the sum of triangle areas."""
    import trimesh
    m = trimesh.Trimesh(vertices=V, faces=F, process=False, validate=False)
    return float(m.volume), float(m.area)


def describe(root, resolution: str = "high") -> list[dict]:
    """One row per case of the build at ``root`` (columns :data:`COLUMNS`).

    Parameters
    ----------
    root : a DeFAUST build folder. resolution : ``"high"`` or ``"low"`` (as :func:`load`).

    Returns
    -------
    list of dicts; the ground-truth columns are None for a case without ground truth
    (a FAUST build made before its high-res ground truth, at high resolution). Volumes
    and areas are of the (n, 3) vertices in metres; the changes are relative, so
    unitless (%).

    Raises
    ------
    SShaDeError as :func:`defaust.load` (missing folder, manifest or file).
    """
    m = read_manifest(root)
    items = m.get("items", {})
    rows, rest = [], {}
    held = (m.get("parameters") or {}).get("subjects")  # a build of some subjects: those it holds
    for c in load(root, resolution=resolution, subjects=held if isinstance(held, list) else None):
        if c.subject not in rest:
            rest[c.subject] = _volume_area(c.V, c.F)
        vol0, area0 = rest[c.subject]
        row = {"case": c.name, "pose_name": c.pose_name, "n_vertices": int(len(c.V)), "n_handles": int(len(c.handles)),
               "n_static": int(np.sum(c.static)), "n_dropped": int(c.n_dropped),
               "gt_volume_change_pct": None, "gt_area_change_pct": None}
        if c.V_gt is not None:
            vol, area = _volume_area(c.V_gt, c.F)
            row["gt_volume_change_pct"] = 100.0 * (vol - vol0) / abs(vol0)
            row["gt_area_change_pct"] = 100.0 * (area - area0) / area0
        info = items.get(f"subject_{c.subject:02d}/pose_{c.pose:02d}", {}).get("info", {})
        row["self_intersecting_faces_high"] = info.get("n_self_intersecting_faces_high")
        rows.append(row)
    return rows


def summary(rows: list[dict]) -> dict:
    """Per numeric column of ``rows`` (:func:`describe`): ``{"min", "median", "max",
    "mean_abs", "n"}`` over the cases that have a value."""
    out = {}
    for col in COLUMNS:
        x = np.array([r[col] for r in rows if isinstance(r.get(col), (int, float)) and not isinstance(r[col], bool)],
                     float)
        if len(x):
            out[col] = {"min": float(x.min()), "median": float(np.median(x)), "max": float(x.max()),
                        "mean_abs": float(np.abs(x).mean()), "n": int(len(x))}
    return out


def markdown(rows: list[dict]) -> str:
    """``rows`` (:func:`describe`) as a Markdown table, then a line per ground-truth
    column with its range over the cases."""
    def cell(v):
        return "--" if v is None else f"{v:.2f}" if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(cell(r.get(c)) for c in COLUMNS) + " |" for r in rows]
    s = summary(rows)
    ranges = [f"- {col}: min {v['min']:.2f}, median {v['median']:.2f}, max {v['max']:.2f}, mean |.| "
              f"{v['mean_abs']:.2f} over {v['n']} case(s)"
              for col, v in s.items() if col in ("gt_volume_change_pct", "gt_area_change_pct")]
    return "\n".join(lines + ([""] + ranges if ranges else [])) + "\n"

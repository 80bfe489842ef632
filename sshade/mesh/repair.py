"""Opt-in mesh repair with pymeshlab's filters that never move a vertex (``python -m
sshade deform --repair``; :func:`repair_mesh`): duplicate vertices and faces, null
(zero-area) faces, non-manifold edges and vertices, unreferenced vertices; faces are never
re-wound and no hole is filled. Every output vertex is an input vertex (``origin``), so
per-vertex data carries over. Reference: P. Cignoni et al., "MeshLab: an open-source mesh
processing tool" (2008); pymeshlab (Muntoni & Cignoni). The filters in detail:
docs/implementation.md ("Implementation notes: sshade/mesh/repair.py").
"""
from __future__ import annotations

import numpy as np

from ..errors import SShaDeError
from .validate import zero_area_faces

__all__ = ["repair_mesh", "REPAIR_FILTERS"]

#: (pymeshlab filter, keyword arguments, what it changes) in the order they run.
REPAIR_FILTERS = (
    ("meshing_remove_duplicate_vertices", {}, "duplicate vertices merged"),
    ("meshing_remove_duplicate_faces", {}, "duplicate faces removed"),
    ("meshing_remove_null_faces", {}, "zero-area faces removed"),
    ("meshing_repair_non_manifold_edges", {"method": "Remove Faces"}, "faces removed on non-manifold edges"),
    ("meshing_repair_non_manifold_vertices", {"vertdispratio": 0.0}, "vertices split at non-manifold vertices"),
    ("meshing_remove_unreferenced_vertices", {}, "unreferenced vertices removed"),
)


#: The report's line for the faces removed by :func:`sshade.mesh.validate.zero_area_faces`.
NEAR_ZERO = "zero-area faces removed (area at most AREA_TOL x diagonal squared, as validate_mesh)"


def repair_mesh(V, F) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[str, int, int]]]:
    """Apply :data:`REPAIR_FILTERS` to ``(V, F)``.

    Parameters
    ----------
    V : (n, 3) float64 vertex positions (mesh units); F : (m, 3) int faces, indices in
    ``[0, n)``.

    Returns
    -------
    V2 : (n2, 3) float64; F2 : (m2, 3) int64; origin : (n2,) int64, for each new vertex an
    input vertex at the same position (``V2 == V[origin]``); report : list of
    ``(what, vertex count change, face count change)`` per filter (signed, new - old).

    Raises
    ------
    SShaDeError on NaN/inf coordinates or face indices out of range (pymeshlab would
    crash or silently drop them), or if pymeshlab fails.

    Examples
    --------
    Example::

        V2, F2, origin, report = repair_mesh(V, F)
    """
    import pymeshlab
    from scipy.spatial import cKDTree
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise SShaDeError(f"repair: V must be (n, 3) and F (m, 3), got {V.shape} and {F.shape}")
    if not np.isfinite(V).all():
        raise SShaDeError("repair: NaN/inf vertex coordinates cannot be repaired")
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise SShaDeError(f"repair: face indices out of range [0, {len(V)})")
    ms = pymeshlab.MeshSet()
    keep = ~zero_area_faces(V, F)
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F[keep].astype(np.int32)))
    report = [] if keep.all() else [(NEAR_ZERO, 0, -int((~keep).sum()))]
    for filt, kw, what in REPAIR_FILTERS:
        nv, nf = ms.current_mesh().vertex_number(), ms.current_mesh().face_number()
        try:
            getattr(ms, filt)(**kw)
        except Exception as e:  # pymeshlab.PyMeshLabException and friends
            raise SShaDeError(f"repair: {filt} failed ({' '.join(str(e).split())})") from None
        m = ms.current_mesh()
        report.append((what, m.vertex_number() - nv, m.face_number() - nf))
    m = ms.current_mesh()
    V2 = np.ascontiguousarray(m.vertex_matrix(), np.float64)
    F2 = np.ascontiguousarray(m.face_matrix(), np.int64)
    d, origin = cKDTree(V).query(V2)
    scale = max(float(np.abs(V).max()), 1.0)
    if len(V2) and d.max() > 1e-6 * scale:  # a filter moved a vertex: refuse rather than guess
        raise SShaDeError(f"repair: a vertex moved by {d.max():.3g}; per-vertex data cannot follow it")
    origin = origin.astype(np.int64)
    return V[origin], F2, origin, report  # the input's exact coordinates

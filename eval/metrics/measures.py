"""Deformation-quality metrics of the paper (§4.1 ARAP errors, §4.2 Hausdorff/Chamfer).
Floor 1 of eval/ (eval/metrics/, tests/test_layering.py); notes: docs/implementation.md.

Examples
--------
>>> import numpy as np
>>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
>>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
>>> round(volume(V, F), 6)
0.166667
>>> round(volume_error(V, 2 * V, F), 6)
700.0"""
from __future__ import annotations

import numpy as np

from eval.metrics.meshes import (
    RestMesh,
    TargetMesh,
    bbox_diagonal,
    corner_angles,
    face_areas,
    mesh_volume,
    squared_distances,
    unique_edges,
    unit_sphere_transform,
)
from sshade.errors import SShaDeError
from sshade.guard import handle_error
from sshade.mesh.validate import check_faces as _faces
from sshade.mesh.validate import check_points as _points

__all__ = [
    "volume", "surface_area", "volume_error", "area_error", "edge_length_error",
    "face_angle_error", "normalize_unit_sphere", "point_surface_distance",
    "hausdorff", "chamfer", "deformation_metrics", "ground_truth_metrics", "RestMesh", "TargetMesh",
]


# ----------------------------------------------------------------------------- checks
def _mesh(V, F, name: str = "V") -> tuple[np.ndarray, np.ndarray]:
    V = _points(V, name)
    return V, _faces(F, len(V))


def _pair(V, Vd, F, names=("V (rest)", "Vd (deformed)")) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two vertex arrays of the same mesh: same shape, shared faces."""
    V = _points(V, names[0])
    Vd = _points(Vd, names[1])
    if V.shape != Vd.shape:
        raise SShaDeError(f"vertex arrays differ in shape: {names[0]} {V.shape} vs {names[1]} {Vd.shape} "
                          "(the metrics need a 1:1 vertex correspondence)")
    return V, Vd, _faces(F, len(V))


def _pct_change(a: float, b: float, what: str) -> float:
    if a == 0 or not np.isfinite(a):
        raise SShaDeError(f"rest {what} is {a}; the relative {what} error is undefined "
                          f"(is the mesh {'closed' if what == 'volume' else 'non-degenerate'}?)")
    return 100.0 * abs(a - b) / abs(a)


# ----------------------------------------------------------------------------- basic quantities
def volume(V, F) -> float:
    """Signed volume enclosed by a triangle mesh (divergence theorem).

    ``sum_f dot(v0, cross(v1, v2)) / 6``: positive for a closed, outward-oriented mesh,
    translation invariant only when the mesh is closed. Not ``igl.volume`` (that is for
    tetrahedra). Source: the ``V_M`` of paper eq. (eq:surf-vol-err).

    Parameters
    ----------
    V : (n, 3) float, vertex positions in some length unit L.
    F : (m, 3) int, triangles.

    Returns
    -------
    float, in L^3.

    Raises
    ------
    SShaDeError on wrong shapes, NaN/inf coordinates or out-of-range indices.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> round(volume(V, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]), 6)
    0.166667
    """
    V, F = _mesh(V, F)
    return _volume(V, F)


# centring at the mean vertex reduces cancellation; the result is unchanged for a closed
# mesh (and for an open one it is the cone volume about that point)
_volume, _face_areas, _angles, _diag = mesh_volume, face_areas, corner_angles, bbox_diagonal


def surface_area(V, F) -> float:
    """Total area of a triangle mesh.

    Source: the ``A_M`` of paper eq. (eq:surf-vol-err).

    Parameters
    ----------
    V : (n, 3) float, vertex positions in length unit L.
    F : (m, 3) int, triangles.

    Returns
    -------
    float, in L^2.

    Raises
    ------
    SShaDeError on wrong shapes, NaN/inf coordinates or out-of-range indices.

    Examples
    --------
    >>> surface_area(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]]), [[0, 1, 2]])
    0.5
    """
    V, F = _mesh(V, F)
    return float(_face_areas(V, F).sum())


# ----------------------------------------------------------------------------- deformation errors
def volume_error(V, Vd, F) -> float:
    """Relative volume change, ``100 |vol(V) - vol(Vd)| / |vol(V)|`` in %.

    Source: paper eq. (eq:surf-vol-err), ``E_vol`` times 100.

    Parameters
    ----------
    V, Vd : (n, 3) float, rest and deformed vertices (same connectivity ``F``).
    F : (m, 3) int, triangles (closed mesh for a meaningful volume).

    Returns
    -------
    float, percent.

    Raises
    ------
    SShaDeError on shape mismatch, NaN/inf, bad indices, or a zero rest volume.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> round(volume_error(V, 2 * V, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]), 6)
    700.0
    """
    V, Vd, F = _pair(V, Vd, F)
    return _pct_change(_volume(V, F), _volume(Vd, F), "volume")


def area_error(V, Vd, F) -> float:
    """Relative surface-area change, ``100 |A(V) - A(Vd)| / A(V)`` in %.

    Source: paper eq. (eq:surf-vol-err), ``E_area`` times 100.

    Parameters
    ----------
    V, Vd : (n, 3) float, rest and deformed vertices; F : (m, 3) int triangles.

    Returns
    -------
    float, percent.

    Raises
    ------
    SShaDeError on shape mismatch, NaN/inf, bad indices, or a zero rest area.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> area_error(V, 2 * V, [[0, 1, 2]])
    300.0
    """
    V, Vd, F = _pair(V, Vd, F)
    return _pct_change(float(_face_areas(V, F).sum()), float(_face_areas(Vd, F).sum()), "area")


def edge_length_error(V, Vd, F) -> float:
    """Mean absolute edge-length change in % of the longest rest edge.

    ``100 / |E| * sum_{(u,v) in E} | ||u - v|| - ||u' - v'|| | / max_e ||e||`` over the
    unique undirected edges ``E`` of ``F``. Source: paper eq. (eq:edge-error) times 100.

    Parameters
    ----------
    V, Vd : (n, 3) float, rest and deformed vertices; F : (m, 3) int triangles.

    Returns
    -------
    float, percent of the longest rest edge.

    Raises
    ------
    SShaDeError on shape mismatch, NaN/inf, bad indices, or all rest edges of length 0.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> round(edge_length_error(V, 2 * V, [[0, 1, 2]]), 6)  # mean(1, 1, sqrt2) / sqrt2
    80.473785
    """
    V, Vd, F = _pair(V, Vd, F)
    E = unique_edges(F, len(V))
    l0 = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    return _edge_error(l0, float(l0.max()), E, Vd)


def _edge_error(l0: np.ndarray, lmax: float, E: np.ndarray, Vd: np.ndarray) -> float:
    """:func:`edge_length_error` from the rest lengths ``l0`` of edges ``E``, their maximum."""
    if lmax == 0:
        raise SShaDeError("all rest edges have zero length; the edge length error is undefined")
    l1 = np.linalg.norm(Vd[E[:, 0]] - Vd[E[:, 1]], axis=1)
    return float(100.0 * np.mean(np.abs(l0 - l1)) / lmax)


def face_angle_error(V, Vd, F) -> tuple[float, float]:
    """Internal-angle distortion between rest and deformed triangles.

    Returns ``(mean_deg, rel_pct)``: the mean over the ``3 |T|`` corners of
    ``|angle - angle'|`` in degrees (what the paper's tables report as FA), and the
    relative form of paper eq. (eq:angle-error), ``mean |angle - angle'| / angle``,
    times 100.

    Parameters
    ----------
    V, Vd : (n, 3) float, rest and deformed vertices; F : (m, 3) int triangles.

    Returns
    -------
    (float degrees, float percent).

    Raises
    ------
    SShaDeError on shape mismatch, NaN/inf, bad indices, or a rest triangle with a zero
    internal angle (degenerate; the relative error is undefined).

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> face_angle_error(V, 3 * V + 1, [[0, 1, 2]])
    (0.0, 0.0)
    """
    V, Vd, F = _pair(V, Vd, F)
    return _angle_error(_angles(V, F), Vd, F)


def _angle_error(a0: np.ndarray, Vd: np.ndarray, F: np.ndarray) -> tuple[float, float]:
    """:func:`face_angle_error` from the rest angles ``a0``."""
    a1 = _angles(Vd, F)
    if (a0 <= 0).any():
        f = int(np.flatnonzero((a0 <= 0).any(axis=1))[0])
        raise SShaDeError(f"rest face {f} is degenerate (a zero internal angle); "
                          "the relative angle error is undefined")
    d = np.abs(a0 - a1)
    return float(np.degrees(d.mean())), float(100.0 * np.mean(d / a0))


# ----------------------------------------------------------------------------- surface distances
def normalize_unit_sphere(V, ref=None) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre at ``ref``'s bounding-box centre and scale so ``ref`` fits the unit sphere.

    The same transform ``(V - center) / scale`` is applied to ``V`` (paper §4.2: "we
    center all the shapes at the origin ... and rescale them to fit inside the unit
    sphere").

    Parameters
    ----------
    V : (n, 3) float, points to transform.
    ref : (k, 3) float or None, the shape defining the transform (default ``V``).

    Returns
    -------
    V_normalized : (n, 3) float64; center : (3,) float64; scale : float, the largest
    distance from ``center`` to a ``ref`` point (so ``ref`` ends with radius 1).

    Raises
    ------
    SShaDeError on wrong shapes, NaN/inf, or a ``ref`` that is a single point.

    Examples
    --------
    >>> Vn, c, s = normalize_unit_sphere(np.array([[0., 0, 0], [2, 0, 0]]))
    >>> Vn.tolist(), c.tolist(), s
    ([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [1.0, 0.0, 0.0], 1.0)
    """
    V = _points(V, "V")
    center, scale = unit_sphere_transform(V if ref is None else _points(ref, "ref"))
    return (V - center) / scale, center, scale


def point_surface_distance(P, V, F) -> np.ndarray:
    """Euclidean distance from each point to the nearest point of a triangle surface.

    The ``d(v, S)`` of paper §4.2, via ``igl.point_mesh_squared_distance``.

    Parameters
    ----------
    P : (k, 3) float, query points; V : (n, 3) float, F : (m, 3) int, the surface.

    Returns
    -------
    (k,) float64 distances, same unit as ``P`` and ``V``.

    Raises
    ------
    SShaDeError on wrong shapes, NaN/inf, or bad indices.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> point_surface_distance([[0.2, 0.2, 0.5]], V, [[0, 1, 2]]).tolist()
    [0.5]
    """
    P = _points(P, "P")
    V, F = _mesh(V, F)
    return _root(squared_distances(P, V, F))


def _root(sq: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(sq, 0.0))


def _two_way(VX, FX, VY, FY, normalize: bool) -> tuple[np.ndarray, np.ndarray]:
    VX, FX = _mesh(VX, FX, "VX")
    VY, FY = _mesh(VY, FY, "VY")
    if normalize:
        c, s = unit_sphere_transform(VY)
        VX, VY = (VX - c) / s, (VY - c) / s
    return _root(squared_distances(VX, VY, FY)), _root(squared_distances(VY, VX, FX))


def _hausdorff_chamfer(dxy: np.ndarray, dyx: np.ndarray) -> tuple[float, float]:
    """:func:`hausdorff` and :func:`chamfer` from the two one-way distances."""
    return float(max(dxy.max(), dyx.max())), float(np.mean(dxy ** 2) + np.mean(dyx ** 2))


def hausdorff(VX, FX, VY, FY, normalize: bool = True) -> float:
    """Symmetric vertex-to-surface Hausdorff distance (paper §4.2, ``d_H``).

    ``max(max_{x in V_X} d(x, Y), max_{y in V_Y} d(y, X))``.

    Parameters
    ----------
    VX, FX : the evaluated mesh X; VY, FY : the reference mesh Y ((n, 3) float, (m, 3) int).
    normalize : bool, if True both meshes are first centred and scaled by the
        :func:`normalize_unit_sphere` transform of Y (so a scaled X is not hidden),
        and the result is in units of Y's enclosing-sphere radius; otherwise in the
        meshes' own unit.

    Returns
    -------
    float.

    Raises
    ------
    SShaDeError on wrong shapes, NaN/inf, or bad indices.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]]); F = [[0, 1, 2]]
    >>> hausdorff(V + [0, 0, 0.25], F, V, F, normalize=False)
    0.25
    """
    return _hausdorff_chamfer(*_two_way(VX, FX, VY, FY, normalize))[0]


def chamfer(VX, FX, VY, FY, normalize: bool = True) -> float:
    """Vertex-to-surface Chamfer distance (paper §4.2, ``d_C``).

    ``mean_{x in V_X} d(x, Y)^2 + mean_{y in V_Y} d(y, X)^2``.

    Parameters
    ----------
    VX, FX : the evaluated mesh X; VY, FY : the reference mesh Y.
    normalize : bool, as in :func:`hausdorff` (normalisation of Y applied to both).

    Returns
    -------
    float, squared length unit.

    Raises
    ------
    SShaDeError on wrong shapes, NaN/inf, or bad indices.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]]); F = [[0, 1, 2]]
    >>> chamfer(V + [0, 0, 0.25], F, V, F, normalize=False)
    0.125
    """
    return _hausdorff_chamfer(*_two_way(VX, FX, VY, FY, normalize))[1]


# ----------------------------------------------------------------------------- bundles
def deformation_metrics(V, Vd, F, handles=None, targets=None, *, rest: RestMesh | None = None) -> dict:
    """All §4.1 errors of a deformation ``V -> Vd`` (same connectivity ``F``).

    Parameters
    ----------
    V, Vd : (n, 3) float, rest and deformed vertices; F : (m, 3) int triangles.
    handles, targets : optional (h,) int and (h, 3) float handle constraints.
    rest : :class:`~eval.metrics.meshes.RestMesh` of ``(V, F)`` or None: what the errors
        need of the rest mesh, computed once for every result on it (same numbers).

    Returns
    -------
    dict with float values: ``volume_err_pct``, ``area_err_pct``, ``edge_err_pct``,
    ``angle_err_deg``, ``angle_err_rel_pct``, and ``handle_err_pct`` (in % of the rest
    bounding-box diagonal) only when ``handles`` is given.

    Raises
    ------
    SShaDeError as the individual metrics, ``targets`` missing when ``handles`` is
    given, or a ``rest`` of another mesh.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
    >>> deformation_metrics(V, V + 1, F)["volume_err_pct"]
    0.0
    """
    V, Vd, F = _pair(V, Vd, F)
    if rest is None:
        rest = RestMesh(V, F)
    elif not rest.matches(V, F):
        raise SShaDeError("deformation_metrics: rest is a RestMesh of another mesh than (V, F)")
    deg, rel = _angle_error(rest.angles, Vd, F)
    out = {
        "volume_err_pct": _pct_change(rest.volume, _volume(Vd, F), "volume"),
        "area_err_pct": _pct_change(rest.area, float(_face_areas(Vd, F).sum()), "area"),
        "edge_err_pct": _edge_error(rest.lengths, rest.longest, rest.edges, Vd),
        "angle_err_deg": deg,
        "angle_err_rel_pct": rel,
    }
    if handles is not None or targets is not None:
        if handles is None or targets is None:
            raise SShaDeError("handle error needs both handles and targets")
        out["handle_err_pct"] = handle_error(Vd, handles, targets, rest.diagonal)
    return out


def ground_truth_metrics(Vd, F, Vgt, *, target: TargetMesh | None = None) -> dict:
    """Errors of a deformed mesh against a ground-truth pose with the same vertices.

    Parameters
    ----------
    Vd : (n, 3) float, deformed vertices; F : (m, 3) int triangles shared by both;
    Vgt : (n, 3) float, ground-truth vertices in 1:1 correspondence with ``Vd``.
    target : :class:`~eval.metrics.meshes.TargetMesh` of ``(Vgt, F)`` or None: what the
        errors need of the ground truth (diagonal, normalisation, AABB tree), computed
        once for every result compared with it (same numbers).

    Returns
    -------
    dict: ``gt_vertex_mean_pct`` / ``gt_vertex_max_pct`` (mean / max of
    ``||Vd - Vgt||`` in % of Vgt's bounding-box diagonal), ``hausdorff`` and
    ``chamfer`` (paper §4.2, normalised by Vgt's unit sphere).

    Raises
    ------
    SShaDeError on shape mismatch, NaN/inf, bad indices, a one-point ``Vgt``, or a
    ``target`` of another mesh.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> ground_truth_metrics(V, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], V)["hausdorff"]
    0.0
    """
    Vgt, Vd, F = _pair(Vgt, Vd, F, ("Vgt (ground truth)", "Vd (deformed)"))
    if target is None:
        target = TargetMesh(Vgt, F)
    elif not target.matches(Vgt, F):
        raise SShaDeError("ground_truth_metrics: target is a TargetMesh of another mesh than (Vgt, F)")
    d = np.linalg.norm(Vd - Vgt, axis=1)
    # hausdorff(Vd, F, Vgt, F) and chamfer(Vd, F, Vgt, F) from one pair of one-way distances
    Vn = (Vd - target.center) / target.scale
    dxy = _root(squared_distances(Vn, target.normalized, F, tree=target.tree))
    dyx = _root(squared_distances(target.normalized, Vn, F, order=target.order))
    h, c = _hausdorff_chamfer(dxy, dyx)
    return {
        "gt_vertex_mean_pct": float(100.0 * d.mean() / target.diagonal),
        "gt_vertex_max_pct": float(100.0 * d.max() / target.diagonal),
        "hausdorff": h,
        "chamfer": c,
    }

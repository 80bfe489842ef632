"""Deformation-quality metrics of the paper (§4.1 ARAP errors, §4.2 Hausdorff/Chamfer).

Pure numpy (and libigl for point-to-surface distances) functions over ``(V, F)``
arrays. Percentages are returned as percentages (``12.5`` means 12.5 %), angles in
degrees. Every function checks its inputs and raises
:class:`~sshade.errors.SShaDeError` with a clear message on wrong shapes, mismatched
vertex arrays, NaN/inf coordinates or out-of-range face indices.

Examples
--------
>>> import numpy as np
>>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
>>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
>>> round(volume(V, F), 6)
0.166667
>>> round(volume_error(V, 2 * V, F), 6)
700.0
"""
from __future__ import annotations

import numpy as np

from sshade.errors import SShaDeError
from sshade.guard import handle_error
from sshade.mesh.validate import check_faces as _faces
from sshade.mesh.validate import check_points as _points

__all__ = [
    "volume", "surface_area", "volume_error", "area_error", "edge_length_error",
    "face_angle_error", "handle_error", "normalize_unit_sphere", "point_surface_distance",
    "hausdorff", "chamfer", "deformation_metrics", "ground_truth_metrics",
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


def _volume(V: np.ndarray, F: np.ndarray) -> float:
    # centring at the mean vertex reduces cancellation; the result is unchanged for a
    # closed mesh (and for an open one it is the cone volume about that point)
    c = V.mean(axis=0)
    a, b, d = V[F[:, 0]] - c, V[F[:, 1]] - c, V[F[:, 2]] - c
    return float(np.einsum("ij,ij->", a, np.cross(b, d)) / 6.0)


def _face_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


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


def _edges(F: np.ndarray) -> np.ndarray:
    """Unique undirected edges (e, 2) of the faces."""
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=0)
    return np.unique(np.sort(he, axis=1), axis=0)


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
    E = _edges(F)
    l0 = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    l1 = np.linalg.norm(Vd[E[:, 0]] - Vd[E[:, 1]], axis=1)
    lmax = float(l0.max())
    if lmax == 0:
        raise SShaDeError("all rest edges have zero length; the edge length error is undefined")
    return float(100.0 * np.mean(np.abs(l0 - l1)) / lmax)


def _angles(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m, 3) internal angles in radians, column k at corner ``F[:, k]`` (atan2 form,
    accurate for tiny and near-straight angles)."""
    P = V[F]                                   # (m, 3, 3)
    a = np.roll(P, -1, axis=1) - P             # to next corner
    b = np.roll(P, 1, axis=1) - P              # to previous corner
    s = np.linalg.norm(np.cross(a, b), axis=2)
    c = np.einsum("ijk,ijk->ij", a, b)
    return np.arctan2(s, c)


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
    a0 = _angles(V, F)
    a1 = _angles(Vd, F)
    if (a0 <= 0).any():
        f = int(np.flatnonzero((a0 <= 0).any(axis=1))[0])
        raise SShaDeError(f"rest face {f} is degenerate (a zero internal angle); "
                          "the relative angle error is undefined")
    d = np.abs(a0 - a1)
    return float(np.degrees(d.mean())), float(100.0 * np.mean(d / a0))


def _diag(V: np.ndarray) -> float:
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


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
    R = V if ref is None else _points(ref, "ref")
    center = 0.5 * (R.min(axis=0) + R.max(axis=0))
    scale = float(np.linalg.norm(R - center, axis=1).max())
    if scale == 0:
        raise SShaDeError("normalize_unit_sphere: the reference shape is a single point")
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
    import igl
    P = _points(P, "P")
    V, F = _mesh(V, F)
    sq = igl.point_mesh_squared_distance(P, V, F)[0]
    return np.sqrt(np.maximum(np.asarray(sq, np.float64), 0.0))


def _two_way(VX, FX, VY, FY, normalize: bool) -> tuple[np.ndarray, np.ndarray]:
    VX, FX = _mesh(VX, FX, "VX")
    VY, FY = _mesh(VY, FY, "VY")
    if normalize:
        _, c, s = normalize_unit_sphere(VY)
        VX, VY = (VX - c) / s, (VY - c) / s
    return point_surface_distance(VX, VY, FY), point_surface_distance(VY, VX, FX)


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
    dxy, dyx = _two_way(VX, FX, VY, FY, normalize)
    return float(max(dxy.max(), dyx.max()))


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
    dxy, dyx = _two_way(VX, FX, VY, FY, normalize)
    return float(np.mean(dxy ** 2) + np.mean(dyx ** 2))


# ----------------------------------------------------------------------------- bundles
def deformation_metrics(V, Vd, F, handles=None, targets=None) -> dict:
    """All §4.1 errors of a deformation ``V -> Vd`` (same connectivity ``F``).

    Parameters
    ----------
    V, Vd : (n, 3) float, rest and deformed vertices; F : (m, 3) int triangles.
    handles, targets : optional (h,) int and (h, 3) float handle constraints.

    Returns
    -------
    dict with float values: ``volume_err_pct``, ``area_err_pct``, ``edge_err_pct``,
    ``angle_err_deg``, ``angle_err_rel_pct``, and ``handle_err_pct`` (in % of the rest
    bounding-box diagonal) only when ``handles`` is given.

    Raises
    ------
    SShaDeError as the individual metrics, or ``targets`` missing when ``handles`` is
    given.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
    >>> deformation_metrics(V, V + 1, F)["volume_err_pct"]
    0.0
    """
    V, Vd, F = _pair(V, Vd, F)
    deg, rel = face_angle_error(V, Vd, F)
    out = {
        "volume_err_pct": volume_error(V, Vd, F),
        "area_err_pct": area_error(V, Vd, F),
        "edge_err_pct": edge_length_error(V, Vd, F),
        "angle_err_deg": deg,
        "angle_err_rel_pct": rel,
    }
    if handles is not None or targets is not None:
        if handles is None or targets is None:
            raise SShaDeError("handle error needs both handles and targets")
        out["handle_err_pct"] = handle_error(Vd, handles, targets, _diag(V))
    return out


def ground_truth_metrics(Vd, F, Vgt) -> dict:
    """Errors of a deformed mesh against a ground-truth pose with the same vertices.

    Parameters
    ----------
    Vd : (n, 3) float, deformed vertices; F : (m, 3) int triangles shared by both;
    Vgt : (n, 3) float, ground-truth vertices in 1:1 correspondence with ``Vd``.

    Returns
    -------
    dict: ``gt_vertex_mean_pct`` / ``gt_vertex_max_pct`` (mean / max of
    ``||Vd - Vgt||`` in % of Vgt's bounding-box diagonal), ``hausdorff`` and
    ``chamfer`` (paper §4.2, normalised by Vgt's unit sphere).

    Raises
    ------
    SShaDeError on shape mismatch, NaN/inf, bad indices, or a one-point ``Vgt``.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> ground_truth_metrics(V, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], V)["hausdorff"]
    0.0
    """
    Vgt, Vd, F = _pair(Vgt, Vd, F, ("Vgt (ground truth)", "Vd (deformed)"))
    diag = _diag(Vgt)
    if diag == 0:
        raise SShaDeError("ground truth vertices all coincide; bounding-box diagonal is 0")
    d = np.linalg.norm(Vd - Vgt, axis=1)
    return {
        "gt_vertex_mean_pct": float(100.0 * d.mean() / diag),
        "gt_vertex_max_pct": float(100.0 * d.max() / diag),
        "hausdorff": hausdorff(Vd, F, Vgt, F),
        "chamfer": chamfer(Vd, F, Vgt, F),
    }

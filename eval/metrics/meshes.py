"""What the metrics of :mod:`eval.metrics.measures` need of a mesh, computed once:
:class:`RestMesh` (rest side) and :class:`TargetMesh` (ground-truth side), and their kernels.
Floor 1 of eval/ (eval/metrics/, tests/test_layering.py); notes: docs/implementation.md.

Examples
--------
>>> import numpy as np
>>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
>>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
>>> r = RestMesh(V, F)
>>> round(r.volume, 6), len(r.edges)
(0.166667, 6)"""
from __future__ import annotations

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.validate import check_faces, check_points

__all__ = ["RestMesh", "TargetMesh", "CaseMeshes", "mesh_volume", "face_areas", "unique_edges", "corner_angles",
           "bbox_diagonal", "unit_sphere_transform", "squared_distances"]


# ----------------------------------------------------------------------------- kernels
def mesh_volume(V: np.ndarray, F: np.ndarray) -> float:
    """Signed enclosed volume of checked ``(V, F)`` (divergence theorem, centred at the mean
    vertex to reduce cancellation; :func:`eval.metrics.measures.volume`)."""
    c = V.mean(axis=0)
    a, b, d = V[F[:, 0]] - c, V[F[:, 1]] - c, V[F[:, 2]] - c
    return float(np.einsum("ij,ij->", a, np.cross(b, d)) / 6.0)


def face_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m,) triangle areas of checked ``(V, F)``."""
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def unique_edges(F: np.ndarray, n: int) -> np.ndarray:
    """(e, 2) unique undirected edges ``(i, j)``, ``i < j``, of faces into ``n`` vertices, in
    lexicographic order: ``np.unique(np.sort(half_edges, axis=1), axis=0)``, through one
    integer key ``i * n + j`` per edge (same order, a plain sort instead of a row sort)."""
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=0)
    he.sort(axis=1)
    n = max(int(n), 1)
    key = np.unique(he[:, 0] * n + he[:, 1])
    return np.stack([key // n, key % n], axis=1)


def corner_angles(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m, 3) internal angles in radians, column k at corner ``F[:, k]`` (atan2 form,
    accurate for tiny and near-straight angles)."""
    P = V[F]                                   # (m, 3, 3)
    a = np.roll(P, -1, axis=1) - P             # to next corner
    b = np.roll(P, 1, axis=1) - P              # to previous corner
    s = np.linalg.norm(np.cross(a, b), axis=2)
    c = np.einsum("ijk,ijk->ij", a, b)
    return np.arctan2(s, c)


def bbox_diagonal(V: np.ndarray) -> float:
    """Length of the axis-aligned bounding box's diagonal."""
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def unit_sphere_transform(R: np.ndarray) -> tuple[np.ndarray, float]:
    """``(center, scale)`` of :func:`eval.metrics.measures.normalize_unit_sphere`: ``R``'s
    bounding-box centre and its largest distance from it; SShaDeError for a single point."""
    center = 0.5 * (R.min(axis=0) + R.max(axis=0))
    scale = float(np.linalg.norm(R - center, axis=1).max())
    if scale == 0:
        raise SShaDeError("normalize_unit_sphere: the reference shape is a single point")
    return center, scale


def _spatial_order(P: np.ndarray) -> np.ndarray:
    """A permutation of the points along a Morton (Z-order) curve of a 1024^3 grid: nearby
    queries one after the other, so the AABB tree's nodes stay in cache."""
    lo, hi = P.min(axis=0), P.max(axis=0)
    q = ((P - lo) / np.where(hi > lo, hi - lo, 1.0) * 1023).astype(np.int64)
    key = np.zeros(len(P), np.int64)
    for bit in range(10):
        for d in range(3):
            key |= ((q[:, d] >> bit) & 1) << (3 * bit + d)
    return np.argsort(key, kind="stable")


def squared_distances(P: np.ndarray, V: np.ndarray, F: np.ndarray, tree=None, order=None) -> np.ndarray:
    """(k,) squared distance of each checked point ``P`` to the surface ``(V, F)``:
    ``igl.point_mesh_squared_distance``'s values, bit for bit (each query is independent of
    the others), with the queries asked in :func:`_spatial_order` (or ``order``) and ``tree``
    an ``igl.AABB`` already built on ``(V, F)`` (None: built here)."""
    import igl
    if tree is None:
        tree = igl.AABB()
        tree.init(V, F)
    order = _spatial_order(P) if order is None else order
    sq = np.empty(len(P), np.float64)
    sq[order] = np.asarray(tree.squared_distance(V, F, np.ascontiguousarray(P[order]))[0], np.float64)
    return sq


# ----------------------------------------------------------------------------- per-mesh state
class RestMesh:
    """The rest mesh of :func:`eval.metrics.measures.deformation_metrics`, with what its errors need
    of it computed once.

    Attributes
    ----------
    V : (n, 3) float64, F : (m, 3) int64, checked (``V`` / ``F`` themselves when they were
        already float64 / int64 and contiguous).
    volume : float, signed volume. area : float, surface area.
    edges : (e, 2) int64 unique undirected edges; lengths : (e,) their rest lengths;
    longest : float, the largest of them.
    angles : (m, 3) rest internal angles (radians). diagonal : float, bounding-box diagonal.
    """

    def __init__(self, V, F):
        self.V = check_points(V, "V (rest)")
        self.F = check_faces(F, len(self.V))
        self.volume = mesh_volume(self.V, self.F)
        self.area = float(face_areas(self.V, self.F).sum())
        self.edges = unique_edges(self.F, len(self.V))
        self.lengths = np.linalg.norm(self.V[self.edges[:, 0]] - self.V[self.edges[:, 1]], axis=1)
        self.longest = float(self.lengths.max())
        self.angles = corner_angles(self.V, self.F)
        self.diagonal = bbox_diagonal(self.V)

    def matches(self, V, F) -> bool:
        """Whether this is the rest mesh ``(V, F)``: the same arrays, or equal ones."""
        same = (V is self.V or np.array_equal(V, self.V)) and (F is self.F or np.array_equal(F, self.F))
        return bool(same)


class TargetMesh:
    """The ground-truth mesh of :func:`eval.metrics.measures.ground_truth_metrics`, with its
    bounding-box diagonal, its unit-sphere transform (:func:`unit_sphere_transform`), its
    normalised vertices ``normalized``, their query order and (on first use) the AABB tree
    of the normalised surface, computed once.

    Raises
    ------
    SShaDeError on wrong shapes, NaN/inf, bad indices or ``V`` all one point.
    """

    def __init__(self, V, F):
        self.V = check_points(V, "Vgt (ground truth)")
        self.F = check_faces(F, len(self.V))
        self.diagonal = bbox_diagonal(self.V)
        if self.diagonal == 0:
            raise SShaDeError("ground truth vertices all coincide; bounding-box diagonal is 0")
        self.center, self.scale = unit_sphere_transform(self.V)
        self.normalized = (self.V - self.center) / self.scale
        self.order = _spatial_order(self.normalized)
        self._tree = None

    @property
    def tree(self):
        """``igl.AABB`` of the normalised surface, built on first use."""
        if self._tree is None:
            import igl
            self._tree = igl.AABB()
            self._tree.init(self.normalized, self.F)
        return self._tree

    def matches(self, V, F) -> bool:
        """Whether this is the ground truth ``(V, F)``: the same arrays, or equal ones."""
        same = (V is self.V or np.array_equal(V, self.V)) and (F is self.F or np.array_equal(F, self.F))
        return bool(same)


class CaseMeshes:
    """The :class:`RestMesh` and :class:`TargetMesh` of the case being scored, each built on
    first use and kept while later results (another method on the case, another case on
    the same rest mesh) ask for the same mesh; the evaluator's one per run."""

    def __init__(self):
        self._rest: RestMesh | None = None
        self._target: TargetMesh | None = None

    def rest(self, V, F) -> RestMesh:
        """The :class:`RestMesh` of ``(V, F)``: the kept one when it matches, else a new one."""
        if self._rest is None or not self._rest.matches(V, F):
            self._rest = None  # the old one is freed before the new one is built
            self._rest = RestMesh(V, F)
        return self._rest

    def target(self, Vgt, F) -> TargetMesh:
        """The :class:`TargetMesh` of ``(Vgt, F)``: the kept one when it matches, else a new one."""
        if self._target is None or not self._target.matches(Vgt, F):
            self._target = None
            self._target = TargetMesh(Vgt, F)
        return self._target

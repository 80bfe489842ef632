"""Projection of every high-res vertex onto the triangle fan of its own Voronoi seed
(paper §3.1, eq. for the O(|V_M|) cost).

Vertex v in Voronoi region R_s is projected onto the closest point of the low-res
triangles incident to seed s only, never onto all low-res triangles: about 6-7
candidate triangles per vertex, so the whole projection is O(|V_M|), and each region
lands in the right part of N even where distant parts of the surface are close in space.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .errors import SShaDeError
from .mesh.bounds import bbox_diagonal

__all__ = ["Projection", "project_to_fans", "vertex_fans", "closest_point_triangle", "TIE"]

#: Fan triangles whose closest points lie within ``TIE`` times the low-res bounding-box
#: diagonal of each other's distance count as equally near, and the lowest-numbered one
#: is taken: a vertex over a fan's edge or seed (equally near both sides, exactly) gets
#: the same triangle whatever the rounding, so a moved or scaled mesh gets the same
#: projection (:mod:`sshade.mesh.unit_frame`). Far above float64's rounding of a distance
#: in a unit-sized frame (1e-16), far below any distance the transfer can tell apart.
TIE = 1e-10


@dataclass
class Projection:
    """The map P : V_M -> T_N with barycentric coordinates.

    Attributes
    ----------
    tri : (n,) int64, low-res triangle P(v) of each high-res vertex.
    bary : (n, 3) float64, barycentric coordinates of the closest point in ``tri``.
    dist : (n,) float64, distance from the vertex to that point (mesh units).
    """

    tri: np.ndarray
    bary: np.ndarray
    dist: np.ndarray


def vertex_fans(FN: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR list of the low-res faces incident to each low-res vertex.

    Parameters
    ----------
    FN : (t, 3) int64 low-res faces; k : number of low-res vertices.

    Returns
    -------
    ptr : (k + 1,) int64; faces : (3t,) int64, faces of vertex i in ``faces[ptr[i]:ptr[i+1]]``.
    """
    flat = FN.ravel()
    order = np.argsort(flat, kind="stable")
    faces = (order // 3).astype(np.int64)
    ptr = np.zeros(k + 1, np.int64)
    np.cumsum(np.bincount(flat, minlength=k), out=ptr[1:])
    return ptr, faces


@njit(cache=True, inline="always")
def _closest(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """Closest point on triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5).
    Returns barycentric (u, v, w) with point = u a + v b + w c. Scalar arguments: numba
    then keeps everything in registers (array views of the corners cost ~2x)."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return 1.0, 0.0, 0.0
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return 0.0, 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return 1.0 - v, v, 0.0
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return 1.0 - w, 0.0, w
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 0.0, 1.0 - w, w
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return 1.0 - v - w, v, w


@njit(cache=True)
def _project(V, label, G, ptr, faces, tri, bary, dist, tie):
    """Closest point of every vertex i in the fan of its seed ``label[i]``: the fan's
    triangles are ``faces[ptr[s]:ptr[s + 1]]`` (ascending), their corner coordinates the
    rows of ``G`` (a0 a1 a2 b0 b1 b2 c0 c1 c2) at the same positions, read in sequence.
    A later triangle replaces the best so far only when nearer by more than ``tie``
    (distance units), so of triangles equally near (a closest point on their shared
    edge or corner) the lowest-numbered one is kept, whatever the rounding."""
    n = V.shape[0]
    for i in range(n):
        s = label[i]
        best = np.inf
        below = np.inf  # a squared distance below this is nearer than best by more than tie
        bt = -1
        bu = bv = bw = 0.0
        p0, p1, p2 = V[i, 0], V[i, 1], V[i, 2]
        for j in range(ptr[s], ptr[s + 1]):
            a0, a1, a2 = G[j, 0], G[j, 1], G[j, 2]
            b0, b1, b2 = G[j, 3], G[j, 4], G[j, 5]
            c0, c1, c2 = G[j, 6], G[j, 7], G[j, 8]
            u, v, w = _closest(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2)
            q0 = u * a0 + v * b0 + w * c0 - p0
            q1 = u * a1 + v * b1 + w * c1 - p1
            q2 = u * a2 + v * b2 + w * c2 - p2
            d = q0 * q0 + q1 * q1 + q2 * q2
            if d < below:
                best = d
                r = np.sqrt(d) - tie
                below = r * r if r > 0.0 else -1.0
                bt = faces[j]
                bu, bv, bw = u, v, w
        tri[i] = bt
        bary[i, 0] = bu
        bary[i, 1] = bv
        bary[i, 2] = bw
        dist[i] = np.sqrt(best)


def closest_point_triangle(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (3,) of the point of triangle abc closest to p (all (3,))."""
    p, a, b, c = (np.asarray(x, np.float64) for x in (p, a, b, c))
    return np.array(_closest(*p, *a, *b, *c))


def project_to_fans(V: np.ndarray, label: np.ndarray, VN: np.ndarray, FN: np.ndarray) -> Projection:
    """Project each high-res vertex onto its own seed's triangle fan in N (paper §3.1).

    Parameters
    ----------
    V : (n, 3) float64 high-res positions.
    label : (n,) int64 Voronoi region of each vertex = its seed's low-res vertex index.
    VN : (k, 3) float64 low-res positions. FN : (t, 3) int64 low-res faces.

    Returns
    -------
    Projection (tri, bary, dist), O(n) work. Of fan triangles equally near a vertex
    (within :data:`TIE` of the diagonal) the lowest-numbered one.

    Raises
    ------
    SShaDeError if some seed has no incident low-res face (not a valid remesh).

    Examples
    --------
    Example::

        P = project_to_fans(V, rm.label, V[rm.seeds], rm.F)
    """
    k = len(VN)
    ptr, faces = vertex_fans(FN, k)
    if (np.diff(ptr) == 0).any():
        raise SShaDeError(f"projection: low-res vertex {int(np.flatnonzero(np.diff(ptr) == 0)[0])} has no faces")
    n = len(V)
    tri = np.empty(n, np.int64)
    bary = np.empty((n, 3), np.float64)
    dist = np.empty(n, np.float64)
    VN = np.asarray(VN, np.float64)
    FN = np.asarray(FN, np.int64)
    G = VN[FN[faces]].reshape(-1, 9)  # corners of each fan triangle, in fan order
    tie = TIE * bbox_diagonal(VN)
    _project(np.ascontiguousarray(V, np.float64), np.ascontiguousarray(label, np.int64), G, ptr, faces,
             tri, bary, dist, tie)
    return Projection(tri=tri, bary=bary, dist=dist)

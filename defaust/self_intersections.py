"""Self-intersecting faces of a triangle mesh, the same on every machine and in every process.

:func:`self_intersections` finds the faces that cross another face that is not their
neighbour. The builder checks posed bodies with it (a pose that self-intersects is refused,
a sampled draw redrawn) and records the count of the high-resolution meshes in the
manifest, so its answer is part of a build's bytes. pymeshlab's
``compute_selection_by_self_intersections_per_face`` answered differently for the same
mesh in the same process after other pymeshlab calls (30 and 31 faces; docs/defaust.md §8),
so the builder uses this test instead: a uniform grid of the faces' bounding boxes, then
exact-sign segment-triangle tests in float64, in a fixed order, with no tolerance.
"""
from __future__ import annotations

import numpy as np

from sshade.errors import SShaDeError

__all__ = ["self_intersections"]


def self_intersections(V, F) -> np.ndarray:
    """Faces of a triangle mesh that cross another face which shares no edge with them.

    Two faces sharing no vertex intersect when an edge of one crosses the other (its
    endpoints strictly on both sides of the other's plane, the crossing strictly inside
    it); two faces sharing one vertex when the edge of one opposite that vertex crosses
    the other. Faces sharing an edge are neighbours and never counted; a touch (a zero
    orientation) and coplanar overlaps are not crossings.

    Parameters
    ----------
    V : (n, 3) float, vertex positions (any unit).
    F : (m, 3) int, triangles indexing ``V``.

    Returns
    -------
    (k,) int64 sorted face indices (empty: no self-intersection).

    Raises
    ------
    SShaDeError when ``V`` or ``F`` has the wrong shape, a face indexes outside ``V`` or
    a position is not finite.

    Source
    ------
    Orientation predicates (Shewchuk, "Adaptive precision floating-point arithmetic and
    fast robust geometric predicates", 1997, without the adaptive stage); a segment
    crosses a triangle when the signed volumes of its endpoints differ in sign and the
    three volumes of the segment with the triangle's edges agree.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.]])
    >>> self_intersections(V, np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])).size
    0
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise SShaDeError(f"self_intersections: need V (n, 3) and F (m, 3), got {V.shape} and {F.shape}")
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise SShaDeError(f"self_intersections: a face indexes outside the {len(V)} vertices")
    if not np.isfinite(V).all():
        raise SShaDeError("self_intersections: a vertex position is not finite")
    if not len(F):
        return np.zeros(0, np.int64)
    F = np.ascontiguousarray(F, np.int64)
    A, B, C = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]  # each face's box: its corners' least and greatest coordinates
    lo, hi = np.minimum(np.minimum(A, B), C), np.maximum(np.maximum(A, B), C)
    c0, c1, dims, count = _grid(lo, hi)
    face, key = _cell_entries(c0, c1, dims, count)
    order = np.argsort(key, kind="stable")  # by cell, faces ascending within a cell
    flags = _crossing_faces(np.ascontiguousarray(V), F, lo, hi, c0, dims, face[order], key[order])
    return np.flatnonzero(flags).astype(np.int64)


#: The grid's cells hold at most this many (cell, face) entries per face on average: the
#: cell size starts at twice the median face box and doubles until they fit.
_ENTRIES_PER_FACE = 8


def _grid(lo, hi):
    """A uniform grid over the face boxes ``lo``, ``hi`` (m, 3): ``(c0, c1, dims, entries)``,
    ``c0``, ``c1`` (m, 3) int64 the cells of each box's low and high corner, ``dims`` (3,)
    int64 the cells per axis, ``entries`` the number of (cell, face) pairs of every box in
    every cell it overlaps. The cell size is twice the median box extent, doubled while
    there are more than :data:`_ENTRIES_PER_FACE` entries a face (at the largest box's
    extent a box overlaps at most 2 x 2 x 2 cells) or the cells' count overflows."""
    ext = (hi - lo).max(axis=1)
    h_max = float(ext.max())
    h = 2.0 * float(np.median(ext))
    if not h > 0.0:
        h = h_max if h_max > 0.0 else 1.0
    origin = lo.min(axis=0)
    while True:
        c0 = np.floor((lo - origin) / h).astype(np.int64)
        c1 = np.floor((hi - origin) / h).astype(np.int64)
        dims = c1.max(axis=0) + 1
        fits = float(dims[0]) * float(dims[1]) * float(dims[2]) < 2.0 ** 62
        count = int(np.prod(c1 - c0 + 1, axis=1).sum())
        if fits and (count <= _ENTRIES_PER_FACE * len(lo) or h >= h_max):
            return c0, c1, dims, count
        if not fits and h >= h_max:
            raise SShaDeError("self_intersections: the mesh spans too many cells of its largest face's size")
        h *= 2.0


def _orient(V, a, b, c, d) -> float:
    """det[V[b] - V[a], V[c] - V[a], V[d] - V[a]], in a fixed order of float64 operations."""
    x1, y1, z1 = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
    x2, y2, z2 = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
    x3, y3, z3 = V[d, 0] - V[a, 0], V[d, 1] - V[a, 1], V[d, 2] - V[a, 2]
    return x1 * (y2 * z3 - z2 * y3) - y1 * (x2 * z3 - z2 * x3) + z1 * (x2 * y3 - y2 * x3)


def _crosses(V, p, q, a, b, c) -> bool:
    """Whether segment ``V[p] V[q]`` crosses triangle ``V[a] V[b] V[c]`` strictly."""
    d1, d2 = _orient(V, a, b, c, p), _orient(V, a, b, c, q)
    if not ((d1 > 0.0 and d2 < 0.0) or (d1 < 0.0 and d2 > 0.0)):
        return False
    e1, e2, e3 = _orient(V, p, q, a, b), _orient(V, p, q, b, c), _orient(V, p, q, c, a)
    return (e1 > 0.0 and e2 > 0.0 and e3 > 0.0) or (e1 < 0.0 and e2 < 0.0 and e3 < 0.0)


def _pair(V, F, i, j) -> bool:
    """Whether faces ``i`` and ``j`` cross (:func:`self_intersections`' rule)."""
    shared, si, sj = 0, -1, -1
    for u in range(3):
        for w in range(3):
            if F[i, u] == F[j, w]:
                shared += 1
                si, sj = u, w
    if shared >= 2:
        return False
    if shared == 1:  # the edge opposite the shared vertex, each way
        return (_crosses(V, F[i, (si + 1) % 3], F[i, (si + 2) % 3], F[j, 0], F[j, 1], F[j, 2])
                or _crosses(V, F[j, (sj + 1) % 3], F[j, (sj + 2) % 3], F[i, 0], F[i, 1], F[i, 2]))
    for u in range(3):
        if _crosses(V, F[i, u], F[i, (u + 1) % 3], F[j, 0], F[j, 1], F[j, 2]):
            return True
        if _crosses(V, F[j, u], F[j, (u + 1) % 3], F[i, 0], F[i, 1], F[i, 2]):
            return True
    return False


def _cell_entries(c0, c1, dims, count):
    """``(face, key)`` (count,) int64: every face (ascending) in every cell its box
    overlaps, ``key`` the cell's index ``(cx dims[1] + cy) dims[2] + cz``."""
    face = np.empty(count, np.int64)
    key = np.empty(count, np.int64)
    t = 0
    for f in range(c0.shape[0]):
        for cx in range(c0[f, 0], c1[f, 0] + 1):
            for cy in range(c0[f, 1], c1[f, 1] + 1):
                for cz in range(c0[f, 2], c1[f, 2] + 1):
                    face[t] = f
                    key[t] = (cx * dims[1] + cy) * dims[2] + cz
                    t += 1
    return face, key


def _crossing_faces(V, F, lo, hi, c0, dims, face, key):
    """(m,) uint8, 1 for a face that crosses another: in each cell of the grid, every two
    faces whose boxes overlap and whose boxes' common low corner lies in this cell (so a
    pair sharing several cells is tested in one), ``face``/``key`` sorted by cell, faces
    ascending within a cell. A pair whose faces are both flagged already is not tested
    again: the flags are the same whatever order the pairs come in."""
    m = F.shape[0]
    flags = np.zeros(m, np.uint8)
    n = key.shape[0]
    s = 0
    while s < n:
        k = key[s]
        e = s
        while e < n and key[e] == k:
            e += 1
        cz = k % dims[2]
        cy = (k // dims[2]) % dims[1]
        cx = k // (dims[1] * dims[2])
        for a in range(s, e):
            i = face[a]
            for b in range(a + 1, e):
                j = face[b]
                if flags[i] and flags[j]:
                    continue
                if (lo[j, 0] > hi[i, 0] or lo[i, 0] > hi[j, 0] or lo[j, 1] > hi[i, 1]
                        or lo[i, 1] > hi[j, 1] or lo[j, 2] > hi[i, 2] or lo[i, 2] > hi[j, 2]):
                    continue
                if (max(c0[i, 0], c0[j, 0]) != cx or max(c0[i, 1], c0[j, 1]) != cy
                        or max(c0[i, 2], c0[j, 2]) != cz):
                    continue  # the pair's common low corner is in another cell, tested there
                if _pair(V, F, i, j):
                    flags[i] = 1
                    flags[j] = 1
        s = e
    return flags


try:  # compiled: a high-resolution body has 340k faces
    import numba as _nb

    _orient = _nb.njit(cache=True, fastmath=False)(_orient)
    _crosses = _nb.njit(cache=True, fastmath=False)(_crosses)
    _pair = _nb.njit(cache=True, fastmath=False)(_pair)
    _cell_entries = _nb.njit(cache=True)(_cell_entries)
    _crossing_faces = _nb.njit(cache=True, fastmath=False)(_crossing_faces)
except ImportError:  # pragma: no cover - numba is a dependency
    pass

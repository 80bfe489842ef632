"""Half-edge connectivity of a triangle mesh from one sort (shared by validation and
remeshing).

Half-edge ``h = 3 f + k`` of face ``f`` goes from ``F[f, k]`` to ``F[f, (k+1) % 3]``.
Sorting the undirected keys of all half-edges puts the (at most two, on a manifold)
half-edges of each edge next to each other, which gives in one pass: the unique edges,
the number of faces on each edge, the twin of every half-edge and the orientation check.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = ["HalfEdges", "halfedges", "vertex_fan_count", "boundary_loops"]


@dataclass
class HalfEdges:
    """Connectivity of ``F`` (m faces, n vertices).

    Attributes
    ----------
    E : (e, 2) int64 unique undirected edges, ``E[:, 0] < E[:, 1]``.
    FE : (m, 3) int64 edge index of half-edge ``3 f + k``.
    count : (e,) int64 number of half-edges (faces) on each edge.
    twin : (3m,) int64 the opposite half-edge, -1 on a boundary (or non-manifold) edge.
    misoriented : int, number of interior edges whose two half-edges run the same way.
    """

    E: np.ndarray
    FE: np.ndarray
    count: np.ndarray
    twin: np.ndarray
    misoriented: int


def halfedges(F: np.ndarray, n: int) -> HalfEdges:
    """Build :class:`HalfEdges` for faces ``F`` (m, 3) int64 over ``n`` vertices; O(m log m)."""
    a = F.ravel()
    b = np.roll(F, -1, axis=1).ravel()
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * n + hi
    order = np.argsort(key, kind="stable")
    sk = key[order]
    start = np.empty(len(sk), bool)
    start[0] = True
    np.not_equal(sk[1:], sk[:-1], out=start[1:])
    eid_sorted = np.cumsum(start) - 1
    FE = np.empty(len(key), np.int64)
    FE[order] = eid_sorted
    first = np.flatnonzero(start)
    count = np.diff(np.append(first, len(sk)))
    uk = sk[first]
    E = np.stack([uk // n, uk % n], axis=1)
    twin = np.full(len(key), -1, np.int64)
    two = np.flatnonzero(count == 2)
    h1 = order[first[two]]
    h2 = order[first[two] + 1]
    twin[h1] = h2
    twin[h2] = h1
    mis = int((a[h1] == a[h2]).sum())
    return HalfEdges(E=E, FE=FE.reshape(-1, 3), count=count, twin=twin, misoriented=mis)


@njit(cache=True)
def _fan_count(F, twin, n):
    m3 = twin.shape[0]
    parent = np.arange(m3)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for h in range(m3):
        t = twin[h]
        if t < h:
            continue
        f, k = h // 3, h % 3
        g, j = t // 3, t % 3
        # h: F[f,k] -> F[f,k+1]; t: F[g,j] -> F[g,j+1] = reversed
        # corner of f at F[f,k] ~ corner of g at F[g,(j+1)%3]; corner at F[f,k+1] ~ corner of g at F[g,j]
        pairs = ((3 * f + k, 3 * g + (j + 1) % 3), (3 * f + (k + 1) % 3, 3 * g + j))
        for p in pairs:
            ra, rb = find(p[0]), find(p[1])
            if ra != rb:
                parent[ra] = rb
    fans = np.zeros(n, np.int64)
    seen = np.full(m3, -1, np.int64)  # root -> last vertex counted for it
    for c in range(m3):
        r = find(c)
        v = F[c // 3, c % 3]
        if seen[r] != v:
            # a root belongs to one vertex only (corners are linked at a shared vertex)
            seen[r] = v
            fans[v] += 1
    return fans


def vertex_fan_count(F: np.ndarray, he: HalfEdges, n: int) -> np.ndarray:
    """(n,) int64 number of face fans around each vertex (1 on a manifold vertex)."""
    return _fan_count(F, he.twin, n)


def boundary_loops(F: np.ndarray, he: HalfEdges) -> list[np.ndarray]:
    """Boundary loops as vertex arrays, each following its boundary half-edges
    (``F``'s orientation). Assumes a manifold mesh (one outgoing boundary half-edge per
    boundary vertex)."""
    bh = np.flatnonzero(he.twin < 0)
    if len(bh) == 0:
        return []
    a = F.ravel()[bh]
    b = np.roll(F, -1, axis=1).ravel()[bh]
    nxt = {int(x): int(y) for x, y in zip(a, b)}
    loops, seen = [], set()
    for s in a.tolist():
        if s in seen:
            continue
        loop = [s]
        seen.add(s)
        v = nxt[s]
        while v != s:
            loop.append(v)
            seen.add(v)
            v = nxt[v]
        loops.append(np.array(loop, np.int64))
    return loops

"""Half-edge connectivity of a triangle mesh (shared by validation and remeshing).

Half-edge ``h = 3 f + k`` of face ``f`` goes from ``F[f, k]`` to ``F[f, (k+1) % 3]``.
Sorting the undirected keys ``(lo, hi)`` of all half-edges puts the (at most two, on a
manifold) half-edges of each edge next to each other, which gives in one pass: the unique
edges, the number of faces on each edge, the twin of every half-edge and the orientation
check. The sort is a bucket sort by ``lo`` (stable, O(m)), then an insertion sort by ``hi``
in each bucket (a merge sort, as loops, in buckets of more than 32), compiled with numba:
the order of a stable argsort of ``lo * n + hi``, about 15x faster at 200k vertices. While
the kernels are deferred (:func:`defer_kernels`: a first call on a small mesh at a cold numba
cache), meshes under :data:`KERNEL_MIN_FACES` faces take NumPy/SciPy twins, which give the
same integers and floats (the same operations in the same order) without compiling.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

__all__ = ["HalfEdges", "halfedges", "vertex_fan_count", "boundary_loops", "count_components",
           "count_pinched_vertices", "vertex_normals", "KERNEL_MIN_FACES", "large_mesh", "takes_kernels",
           "defer_kernels", "warm_kernels"]

#: While the kernels of this module and of :mod:`sshade.mesh.validate` are deferred
#: (:func:`defer_kernels`), meshes with fewer faces take their NumPy/SciPy paths (the same
#: results, 2-8x slower warm: a few ms at this size), which compile nothing; larger meshes
#: always take the kernels (benchmarks/records/cold_compile.md).
KERNEL_MIN_FACES = 20_000
_DEFERRED = [False]


def large_mesh(F) -> bool:
    """Whether faces ``F`` (m, 3) number at least :data:`KERNEL_MIN_FACES` (anything without a
    length, unchecked input, counts as small)."""
    try:
        return len(F) >= KERNEL_MIN_FACES
    except TypeError:
        return False


def takes_kernels(F) -> bool:
    """Whether a call on faces ``F`` (m, 3) takes the compiled kernels: always, but for a small
    mesh (:func:`large_mesh`) while they are deferred (:func:`defer_kernels`)."""
    return not _DEFERRED[0] or large_mesh(F)


def defer_kernels(defer: bool) -> None:
    """Let small meshes take the NumPy/SciPy paths (``defer`` True) or the kernels again, in
    this process. Set by :func:`sshade.kernel_cache.compile_kernels`: deferred while the kernels
    are neither compiled nor in numba's cache after a first call on a small mesh, so that it
    compiles none of them. The results do not depend on it (the paths agree bit for bit)."""
    _DEFERRED[0] = bool(defer)


@dataclass
class HalfEdges:
    """Connectivity of ``F`` (m faces, n vertices).

    Attributes
    ----------
    E : (e, 2) int64 unique undirected edges, ``E[:, 0] < E[:, 1]``, sorted by
        ``(E[:, 0], E[:, 1])``.
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


@njit(cache=True)
def _merge_sort(key, order, s, e, tmp_k, tmp_o):
    """Sort ``key[s:e]`` ascending and ``order[s:e]`` with it, stably (bottom-up merge
    sort through the scratch arrays ``tmp_k``, ``tmp_o`` of at least ``e - s`` entries)."""
    width = 1
    while width < e - s:
        for lo in range(s, e, 2 * width):
            mid = min(lo + width, e)
            hi = min(lo + 2 * width, e)
            i, j, k = lo, mid, lo
            while i < mid and j < hi:
                if key[j] < key[i]:  # strict: equal keys keep their order
                    tmp_k[k - s] = key[j]
                    tmp_o[k - s] = order[j]
                    j += 1
                else:
                    tmp_k[k - s] = key[i]
                    tmp_o[k - s] = order[i]
                    i += 1
                k += 1
            while i < mid:
                tmp_k[k - s] = key[i]
                tmp_o[k - s] = order[i]
                i += 1
                k += 1
            while j < hi:
                tmp_k[k - s] = key[j]
                tmp_o[k - s] = order[j]
                j += 1
                k += 1
        for p in range(s, e):
            key[p] = tmp_k[p - s]
            order[p] = tmp_o[p - s]
        width *= 2


@njit(cache=True)
def _halfedges(F, n):
    """Kernel of :func:`halfedges`: returns (E, FE, count, twin, misoriented)."""
    m = F.shape[0]
    m3 = 3 * m
    # stable bucket sort of the half-edges by lo = min(end points) ...
    start = np.zeros(n + 1, np.int64)
    for f in range(m):
        for k in range(3):
            start[min(F[f, k], F[f, (k + 1) % 3]) + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    order = np.empty(m3, np.int64)  # 2 h + (1 if h runs hi -> lo), in sorted order
    key = np.empty(m3, np.int64)  # their hi = max(end points)
    pos = start[:n].copy()
    big = 0  # the largest bucket, the merge sort's scratch
    for v in range(n):
        big = max(big, start[v + 1] - start[v])
    tmp_k = np.empty(big if big > 32 else 0, np.int64)
    tmp_o = np.empty(big if big > 32 else 0, np.int64)
    for f in range(m):
        for k in range(3):
            a = F[f, k]
            b = F[f, (k + 1) % 3]
            lo = min(a, b)
            p = pos[lo]
            pos[lo] += 1
            order[p] = 2 * (3 * f + k) + (a > b)
            key[p] = max(a, b)
    # ... then a stable sort by hi inside each bucket
    for v in range(n):
        s, e = start[v], start[v + 1]
        if e - s <= 32:
            for i in range(s + 1, e):  # insertion sort; strict > keeps equal keys in order
                h = order[i]
                kh = key[i]
                j = i - 1
                while j >= s and key[j] > kh:
                    order[j + 1] = order[j]
                    key[j + 1] = key[j]
                    j -= 1
                order[j + 1] = h
                key[j + 1] = kh
        else:  # a high-degree vertex: a stable merge sort
            _merge_sort(key, order, s, e, tmp_k, tmp_o)
    # one sweep over the sorted half-edges: a new edge starts where (lo, hi) changes
    ne = 0
    for v in range(n):
        for p in range(start[v], start[v + 1]):
            if p == start[v] or key[p] != key[p - 1]:
                ne += 1
    E = np.empty((ne, 2), np.int64)
    count = np.zeros(ne, np.int64)
    FE = np.empty(m3, np.int64)
    twin = np.full(m3, -1, np.int64)
    mis = 0
    eid = -1
    for v in range(n):
        for p in range(start[v], start[v + 1]):
            if p == start[v] or key[p] != key[p - 1]:
                eid += 1
                E[eid, 0] = v
                E[eid, 1] = key[p]
                # exactly two half-edges: twins (the first two in sorted order)
                if p + 1 < start[v + 1] and key[p + 1] == key[p] and (p + 2 == start[v + 1] or key[p + 2] != key[p]):
                    h1 = order[p] >> 1
                    h2 = order[p + 1] >> 1
                    twin[h1] = h2
                    twin[h2] = h1
                    if (order[p] & 1) == (order[p + 1] & 1):  # both run the same way
                        mis += 1
            FE[order[p] >> 1] = eid
            count[eid] += 1
    return E, FE.reshape(m, 3), count, twin, mis


def halfedges(F: np.ndarray, n: int) -> HalfEdges:
    """Build :class:`HalfEdges` for faces ``F`` (m, 3) int over ``n`` vertices; O(m)
    (plus O(d log d) per vertex of degree d > 32)."""
    F = np.ascontiguousarray(F, np.int64)
    E, FE, count, twin, mis = (_halfedges if takes_kernels(F) else _halfedges_numpy)(F, int(n))
    return HalfEdges(E=E, FE=FE, count=count, twin=twin, misoriented=int(mis))


def _halfedges_numpy(F, n):
    """:func:`_halfedges` in NumPy: a stable sort by ``(lo, hi)`` gives the same order."""
    m3 = 3 * len(F)
    a, b = F.reshape(-1), np.roll(F, -1, axis=1).reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((hi, lo))  # stable: equal edges keep half-edge order, as the kernel's sort
    slo, shi = lo[order], hi[order]
    new = np.ones(m3, bool)
    new[1:] = (slo[1:] != slo[:-1]) | (shi[1:] != shi[:-1])
    starts = np.flatnonzero(new)
    E = np.stack([slo[starts], shi[starts]], axis=1)
    count = np.diff(np.append(starts, m3)).astype(np.int64)
    FE = np.empty(m3, np.int64)
    FE[order] = np.cumsum(new) - 1
    twin = np.full(m3, -1, np.int64)
    p = starts[count == 2]
    h1, h2 = order[p], order[p + 1]
    twin[h1], twin[h2] = h2, h1
    mis = int(np.count_nonzero((a[h1] > b[h1]) == (a[h2] > b[h2])))
    return E, FE.reshape(-1, 3), count, twin, mis


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
    if takes_kernels(F):
        return _fan_count(F, he.twin, n)
    return _fan_count_numpy(np.ascontiguousarray(F, np.int64), he.twin, int(n))


def _fan_count_numpy(F, twin, n):
    """:func:`_fan_count` in NumPy/SciPy: the same corner links, their components, and each
    component counted where its run of corners (in corner order) changes vertex."""
    m3 = twin.shape[0]
    h = np.flatnonzero(twin > np.arange(m3))
    t = twin[h]
    f, k, g, j = h // 3, h % 3, t // 3, t % 3
    rows = np.concatenate([3 * f + k, 3 * f + (k + 1) % 3])
    cols = np.concatenate([3 * g + (j + 1) % 3, 3 * g + j])
    links = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(m3, m3))
    label = connected_components(links, directed=False)[1]
    corners = np.argsort(label, kind="stable")
    lab, v = label[corners], F.reshape(-1)[corners]
    new = np.ones(m3, bool)
    new[1:] = (lab[1:] != lab[:-1]) | (v[1:] != v[:-1])
    return np.bincount(v[new], minlength=n).astype(np.int64)


@njit(cache=True)
def _pinched(F, twin, n):
    """Number of vertices whose faces form more than one fan, for an oriented mesh whose
    edges have at most two faces (``twin`` an involution). The outgoing half-edges of a
    vertex are chained by h -> twin(half-edge into the vertex in h's face); every fan is
    one chain (from a half-edge without twin) or one cycle of that map. Each half-edge is
    visited once: chains first, then the cycles among the rest. (On other inputs it
    terminates, with a meaningless count.)"""
    m3 = twin.shape[0]
    fans = np.zeros(n, np.int32)
    seen = np.zeros(m3, np.bool_)
    for cycles in (False, True):
        for h0 in range(m3):
            if seen[h0] or (not cycles and twin[h0] >= 0):
                continue
            fans[F[h0 // 3, h0 % 3]] += 1
            h = h0
            while True:
                seen[h] = True
                h = twin[3 * (h // 3) + (h % 3 + 2) % 3]
                if h < 0 or seen[h]:  # end of a chain, back at h0 (or a bad input)
                    break
    bad = 0
    for v in range(n):
        if fans[v] > 1:
            bad += 1
    return bad


def count_pinched_vertices(F: np.ndarray, he: HalfEdges, n: int) -> int:
    """Number of non-manifold (pinch) vertices of an oriented mesh whose edges all have
    one or two faces; O(m). Same verdict as ``(vertex_fan_count(F, he, n) > 1).sum()``
    on such meshes, about 10x faster."""
    return int(_pinched(np.ascontiguousarray(F, np.int64), he.twin, int(n)))


@njit(cache=True)
def _components(E, n):
    parent = np.arange(n)
    ncomp = n
    for i in range(E.shape[0]):
        a = E[i, 0]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        b = E[i, 1]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            parent[a] = b
            ncomp -= 1
    return ncomp


def count_components(E: np.ndarray, n: int) -> int:
    """Connected components of the graph with ``n`` vertices and edges ``E`` (e, 2)
    (isolated vertices count); union-find, O(e) (SciPy's for fewer than
    ``1.5 * KERNEL_MIN_FACES`` edges, a small mesh's, while the kernels are deferred)."""
    E = np.ascontiguousarray(E, np.int64).reshape(-1, 2)
    if not _DEFERRED[0] or 2 * len(E) >= 3 * KERNEL_MIN_FACES:
        return int(_components(E, int(n)))
    graph = coo_matrix((np.ones(len(E), np.int8), (E[:, 0], E[:, 1])), shape=(int(n), int(n)))
    return int(connected_components(graph, directed=False)[0])


@njit(cache=True, nogil=True)
def _vertex_normals(V, F):
    N = np.zeros_like(V)
    for f in range(F.shape[0]):
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        e10, e11, e12 = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
        e20, e21, e22 = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
        n0 = e11 * e22 - e12 * e21
        n1 = e12 * e20 - e10 * e22
        n2 = e10 * e21 - e11 * e20
        for v in (a, b, c):
            N[v, 0] += n0
            N[v, 1] += n1
            N[v, 2] += n2
    for v in range(V.shape[0]):
        r = np.sqrt(N[v, 0] * N[v, 0] + N[v, 1] * N[v, 1] + N[v, 2] * N[v, 2])
        if r > 0:
            N[v, 0] /= r
            N[v, 1] /= r
            N[v, 2] /= r
    return N


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(n, 3) float64 area-weighted unit vertex normals (sum of the incident faces'
    cross products, normalised; libigl's default weighting, equal up to round-off)."""
    V, F = np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int64)
    return (_vertex_normals if takes_kernels(F) else _vertex_normals_numpy)(V, F)


def _vertex_normals_numpy(V, F):
    """:func:`_vertex_normals` in NumPy: the same products, summed into each vertex in the
    kernel's order (``np.add.at`` adds in index order) and normalised alike."""
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1, e2 = b - a, c - a
    fn = np.stack([e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1], e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2],
                   e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]], axis=1)
    N = np.zeros_like(V)
    np.add.at(N, F.reshape(-1), np.repeat(fn, 3, axis=0))
    r = np.sqrt(N[:, 0] * N[:, 0] + N[:, 1] * N[:, 1] + N[:, 2] * N[:, 2])
    pos = r > 0
    N[pos] /= r[pos, None]
    return N


def tetrahedron() -> tuple[np.ndarray, np.ndarray]:
    """The unit corner tetrahedron, the smallest closed mesh, on which warm-ups compile kernels.

    Returns
    -------
    V : (4, 3) float64, the origin and the three unit points.
    F : (4, 3) int64, faces oriented outward (positive signed volume).
    """
    V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    return V, F


def warm_kernels() -> None:
    """Compile (or load from numba's cache) this module's kernels that the mesh checks and the
    remesh take (:func:`takes_kernels`), on :func:`tetrahedron`."""
    V, F = tetrahedron()
    E, _, _, twin, _ = _halfedges(F, 4)
    _fan_count(F, twin, 4)
    _components(E, 4)
    _vertex_normals(V, F)


@njit(cache=True)
def _boundary_loops(F, twin):
    """Boundary loops as one array ``verts`` plus loop offsets ``ptr``, in the order of
    their first boundary half-edge."""
    m3 = twin.shape[0]
    nb = 0
    for h in range(m3):
        if twin[h] < 0:
            nb += 1
    bh = np.empty(nb, np.int64)
    i = 0
    for h in range(m3):
        if twin[h] < 0:
            bh[i] = h
            i += 1
    # next boundary vertex of each boundary vertex (manifold: one outgoing boundary half-edge)
    src = np.empty(nb, np.int64)
    for i in range(nb):
        h = bh[i]
        src[i] = F[h // 3, h % 3]
    order = np.argsort(src, kind="mergesort")
    ssrc = src[order]
    verts = np.empty(nb, np.int64)
    ptr = [0]
    seen = np.zeros(nb, np.bool_)
    w = 0
    for i in range(nb):
        if seen[i]:
            continue
        s = src[i]
        v = s
        j = i
        while True:
            seen[j] = True
            verts[w] = v
            w += 1
            h = bh[j]
            v = F[h // 3, (h % 3 + 1) % 3]
            if v == s:
                break
            j = order[np.searchsorted(ssrc, v)]
            if seen[j]:  # not a manifold boundary: stop this loop
                break
        ptr.append(w)
    return verts[:w], np.array(ptr, np.int64)


def boundary_loops(F: np.ndarray, he: HalfEdges) -> list[np.ndarray]:
    """Boundary loops as vertex arrays, each following its boundary half-edges
    (``F``'s orientation), in the order of their first boundary half-edge. Assumes a
    manifold mesh (one outgoing boundary half-edge per boundary vertex)."""
    if not (he.twin < 0).any():
        return []
    verts, ptr = _boundary_loops(np.ascontiguousarray(F, np.int64), he.twin)
    return [verts[ptr[i]:ptr[i + 1]].copy() for i in range(len(ptr) - 1)]

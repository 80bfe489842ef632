"""Geodesic farthest-point sampling and Voronoi regions on the edge graph (paper §3.1;
Peyré & Cohen 2006 front propagation; ReMatching, Maggioli et al. 2023).

Distances are shortest paths on the edge graph (Euclidean edge lengths); each new seed
runs an incremental Dijkstra over the vertices it takes over (:class:`VoronoiState`,
numba), in a cache-friendly vertex order (:func:`locality_order`). Labels, distances and
the farthest point (the smallest index among exact ties) depend neither on the vertex
order nor on the queue. Speed: docs/implementation.md ("Implementation notes:
sshade/mesh/geodesic.py").
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ..unique import unique_int

__all__ = ["edge_graph", "edge_graph_from_edges", "locality_order", "VoronoiState", "farthest_point_sampling"]


@njit(cache=True, nogil=True)
def _csr_from_edges(V, E, rank):
    """Symmetric CSR (indptr int64, indices int32, weights float32) of the undirected
    edges ``E`` with the vertices renumbered by ``rank`` (old -> new). Row i lists the
    edges of vertex i in the order of ``E``: for E sorted by (E[:, 0], E[:, 1]) and the
    identity ``rank``, every row is sorted."""
    n = V.shape[0]
    indptr = np.zeros(n + 1, np.int64)
    for i in range(E.shape[0]):
        indptr[rank[E[i, 0]] + 1] += 1
        indptr[rank[E[i, 1]] + 1] += 1
    for v in range(n):
        indptr[v + 1] += indptr[v]
    indices = np.empty(indptr[n], np.int32)
    weights = np.empty(indptr[n], np.float32)
    pos = indptr[:n].copy()
    for i in range(E.shape[0]):
        a, b = E[i, 0], E[i, 1]
        d0, d1, d2 = V[a, 0] - V[b, 0], V[a, 1] - V[b, 1], V[a, 2] - V[b, 2]
        w = np.float32(np.sqrt(d0 * d0 + d1 * d1 + d2 * d2))
        ra, rb = rank[a], rank[b]
        indices[pos[ra]] = rb
        weights[pos[ra]] = w
        pos[ra] += 1
        indices[pos[rb]] = ra
        weights[pos[rb]] = w
        pos[rb] += 1
    return indptr, indices, weights


def edge_graph_from_edges(V: np.ndarray, E: np.ndarray, order: np.ndarray | None = None
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR edge graph (see :func:`edge_graph`) from unique undirected edges E (e, 2).

    With ``order`` (n,) (a permutation, e.g. :func:`locality_order`), vertex ``i`` of the
    graph is mesh vertex ``order[i]`` (rows then in edge order, not sorted: the
    propagation does not depend on the order of a row)."""
    n = len(V)
    rank = np.arange(n) if order is None else _inverse(order)
    return _csr_from_edges(np.ascontiguousarray(V, np.float64), np.ascontiguousarray(E, np.int64), rank)


def edge_graph(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR adjacency of the mesh edge graph with Euclidean edge lengths.

    Parameters
    ----------
    V : (n, 3) float64. F : (m, 3) int64.

    Returns
    -------
    indptr : (n + 1,) int64; indices : (2e,) int32 neighbour vertices;
    weights : (2e,) float32 edge lengths (mesh units). Compact types keep the working
    set of the propagation in cache (two concurrent samplings otherwise thrash L3;
    distances still accumulate in float64).

    Examples
    --------
    >>> V = np.eye(3); F = np.array([[0, 1, 2]])
    >>> indptr, idx, w = edge_graph(V, F)
    >>> indptr.tolist()
    [0, 2, 4, 6]
    """
    n = len(V)
    F = np.asarray(F, np.int64)
    a = F.ravel()
    b = np.roll(F, -1, axis=1).ravel()
    key = unique_int(np.minimum(a, b) * n + np.maximum(a, b))
    E = np.stack([key // n, key % n], axis=1)
    return edge_graph_from_edges(V, E)


def _inverse(order: np.ndarray) -> np.ndarray:
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    return rank


#: (shift, mask) steps spreading the 10 bits of a coordinate to every third bit
_SPREAD = ((16, 0x030000FF), (8, 0x0300F00F), (4, 0x030C30C3), (2, 0x09249249))


def locality_order(V: np.ndarray) -> np.ndarray:
    """(n,) int64 permutation of the vertices along a Morton (Z-order) curve of their
    positions: graph neighbours get nearby indices, so propagations touch few cache
    lines. Meshes from remeshers often number their vertices almost at random
    (mean index gap of an edge ~ n/4 on the 200k armadillo), which costs ~1.5x.

    The 30-bit Morton code takes 10 bits per axis of the bounding box's largest side
    (``q = int((x - lo) * 1023 / extent)``, bit ``b`` of axis ``k`` to bit ``3 b + k``);
    ties keep the vertices' order. numpy, not a numba kernel: nothing to compile on the
    first call."""
    V = np.ascontiguousarray(V, np.float64)
    n = len(V)
    if n == 0:
        return np.zeros(0, np.int64)
    lo, hi = V.min(0), V.max(0)
    ext = float(max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]))
    s = 1023.0 / ext if ext > 0 else 0.0
    code = np.zeros(n, np.int64)
    for k in range(3):
        q = np.clip(((V[:, k] - lo[k]) * s).astype(np.int64), 0, 1023)
        for shift, mask in _SPREAD:
            q = (q | (q << shift)) & mask
        code |= q << k
    if n >= 1 << 31:  # the index does not fit beside the code
        return np.argsort(code, kind="stable")
    key = (code << 31) | np.arange(n, dtype=np.int64)  # unique keys: an unstable sort keeps ties in order
    key.sort()
    return key & np.int64((1 << 31) - 1)


# ---------------------------------------------------------------- numba queues
# Binary min-heaps over parallel arrays (keys, values) with preallocated capacity: the
# callers guarantee room (growth is checked once per propagation, not per push).
@njit(cache=True, inline="always")
def _push(hk, hv, size, k, v):
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= k:
            break
        hk[i] = hk[p]
        hv[i] = hv[p]
        i = p
    hk[i] = k
    hv[i] = v
    return size + 1


@njit(cache=True, inline="always")
def _pop(hk, hv, size):
    """Remove and return the smallest (key, value); bottom-up: move the hole at the
    root down to a leaf along the smaller children (one branch-free comparison per
    level), then sift the last entry up from there."""
    k0 = hk[0]
    v0 = hv[0]
    size -= 1
    k = hk[size]
    v = hv[size]
    i = 0
    c = 1
    while c + 1 < size:
        c += hk[c + 1] < hk[c]
        hk[i] = hk[c]
        hv[i] = hv[c]
        i = c
        c = 2 * i + 1
    if c < size:  # a last single child
        hk[i] = hk[c]
        hv[i] = hv[c]
        i = c
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= k:
            break
        hk[i] = hk[p]
        hv[i] = hv[p]
        i = p
    hk[i] = k
    hv[i] = v
    return k0, v0, size


# The farthest-point max-heap holds (-dist, vertex) and breaks ties of distance by the
# smaller ``tie[vertex]`` (the vertex's index in the mesh), so that the sampling depends
# on the distance field only, not on the order in which a propagation met the vertices.
@njit(cache=True, inline="always")
def _before(k1, v1, k2, v2, tie):
    return k1 < k2 or (k1 == k2 and tie[v1] < tie[v2])


@njit(cache=True, inline="always")
def _mpush(mk, mv, size, k, v, tie):
    i = size
    while i > 0:
        p = (i - 1) >> 1
        if not _before(k, v, mk[p], mv[p], tie):
            break
        mk[i] = mk[p]
        mv[i] = mv[p]
        i = p
    mk[i] = k
    mv[i] = v
    return size + 1


@njit(cache=True, inline="always")
def _mpop(mk, mv, size, tie):
    k0 = mk[0]
    v0 = mv[0]
    size -= 1
    k = mk[size]
    v = mv[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and _before(mk[c + 1], mv[c + 1], mk[c], mv[c], tie):
            c += 1
        if not _before(mk[c], mv[c], k, v, tie):
            break
        mk[i] = mk[c]
        mv[i] = mv[c]
        i = c
    mk[i] = k
    mv[i] = v
    return k0, v0, size


@njit(cache=True)
def _grow(hk, hv, size, need):
    if size + need <= hk.shape[0]:
        return hk, hv
    cap = max(2 * hk.shape[0], size + need)
    nk = np.empty(cap, hk.dtype)
    nv = np.empty(cap, hv.dtype)
    for i in range(size):  # a loop: a slice assignment compiles numba's shape checks and messages (2-3 s)
        nk[i] = hk[i]
        nv[i] = hv[i]
    return nk, nv


# ---------------------------------------------------------------- propagation
@njit(cache=True)
def _dijkstra_heap(indptr, indices, weights, dist, label, src, lab, hk, hv, settled, mark):
    """Settle, from ``src``, the vertices that get strictly closer to it (binary heap).
    Fills ``settled`` (see :func:`_propagate`) and returns how many."""
    dist[src] = 0.0
    label[src] = lab
    size = _push(hk, hv, 0, 0.0, src)
    ns = 0
    while size > 0:
        d, u, size = _pop(hk, hv, size)
        if d > dist[u]:
            continue
        mark[u] = lab
        lowered = False
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + weights[e]
            if nd < dist[v]:
                dist[v] = nd
                label[v] = lab
                size = _push(hk, hv, size, nd, v)
                lowered = True
        settled[ns] = -1 - u if lowered else u
        ns += 1
    return ns


@njit(cache=True)
def _dijkstra_dial(indptr, indices, weights, dist, label, src, lab, ek, ev, en, head, inv_width, settled, mark):
    """As :func:`_dijkstra_heap` with Dial's bucket queue: bucket b holds the entries of
    distance in [b w, (b + 1) w) for a width w a bit below the shortest edge, so a
    vertex popped from the lowest bucket cannot be lowered by another one of the same
    bucket: it is settled, in any order within the bucket. The buckets are a ring of
    ``len(head)`` > longest edge / w + 1 singly linked lists (entries ek/ev, next en),
    empty again when the propagation ends; ``len(head)`` is a power of two, so that the
    ring index is a mask. O(1) per push and pop."""
    mask = head.shape[0] - 1
    dist[src] = 0.0
    label[src] = lab
    ek[0] = 0.0
    ev[0] = src
    en[0] = -1
    head[0] = 0
    ne = 1
    pending = 1
    cur = 0  # current bucket (absolute)
    ns = 0
    while pending > 0:
        b = cur & mask
        x = head[b]
        if x < 0:
            cur += 1
            continue
        head[b] = en[x]
        pending -= 1
        d = ek[x]
        u = ev[x]
        if d > dist[u]:
            continue
        mark[u] = lab
        lowered = False
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + weights[e]
            if nd < dist[v]:
                dist[v] = nd
                label[v] = lab
                bb = np.int64(nd * inv_width) & mask
                ek[ne] = nd
                ev[ne] = v
                en[ne] = head[bb]
                head[bb] = ne
                ne += 1
                pending += 1
                lowered = True
        settled[ns] = -1 - u if lowered else u
        ns += 1
    return ns


@njit(cache=True, inline="always")
def _is_local_max(indptr, indices, dist, v):
    d = dist[v]
    for e in range(indptr[v], indptr[v + 1]):
        if dist[indices[e]] > d:
            return False
    return True


@njit(cache=True)
def _propagate(indptr, indices, weights, dist, label, src, lab, hk, hv, hn, head, inv_width, mk, mv, msize,
               tie, settled, mark):
    """Incremental Dijkstra from ``src`` (new label ``lab``): visits only vertices that
    get strictly closer (Dial's buckets when ``head`` is not empty, else a binary heap;
    same distances and labels).

    Farthest-point candidates: the farthest vertex is always a local maximum of
    ``dist``, and only the vertices settled in this run and their unsettled neighbours
    can have become local maxima, so only those local maxima are pushed onto the
    max-heap (mk, mv) with key -dist (lazy: entries whose distance later changes are
    skipped when popped). A settled vertex u that lowered a neighbour v is no local
    maximum: v is settled later in the run, from a vertex at distance >= dist[u] over an
    edge of positive length, so dist[v] > dist[u] at the end; only the others are tested
    (stored as -1 - u in ``settled``). ``hk``/``hv``/``hn`` must hold len(indices) + 1
    entries and the max-heap room for n more."""
    if head.shape[0]:
        ns = _dijkstra_dial(indptr, indices, weights, dist, label, src, lab, hk, hv, hn, head, inv_width,
                            settled, mark)
    else:
        ns = _dijkstra_heap(indptr, indices, weights, dist, label, src, lab, hk, hv, settled, mark)
    for i in range(ns):
        u = settled[i]
        if u >= 0:
            if _is_local_max(indptr, indices, dist, u):
                msize = _mpush(mk, mv, msize, -dist[u], u, tie)
        else:
            u = -1 - u
        for e in range(indptr[u], indptr[u + 1]):
            w = indices[e]
            if mark[w] != lab:
                mark[w] = lab
                if _is_local_max(indptr, indices, dist, w):
                    msize = _mpush(mk, mv, msize, -dist[w], w, tie)
    return msize


@njit(cache=True)
def _fps(indptr, indices, weights, dist, label, seeds, nseeds, k_target, hk, hv, hn, head, inv_width, mk, mv, msize,
         tie, settled, mark):
    """Farthest-point sampling until ``k_target`` seeds: pop the max-heap (lazy: skip
    entries whose key no longer equals the vertex's distance), propagate from it."""
    n = dist.shape[0]
    while nseeds < k_target:
        found = -1
        while msize > 0:
            negd, v, msize = _mpop(mk, mv, msize, tie)
            if -negd == dist[v] and dist[v] > 0.0:
                found = v
                break
        if found < 0:
            break  # every vertex is a seed
        seeds[nseeds] = found
        mk, mv = _grow(mk, mv, msize, n)
        msize = _propagate(indptr, indices, weights, dist, label, found, nseeds, hk, hv, hn, head, inv_width,
                           mk, mv, msize, tie, settled, mark)
        nseeds += 1
    return nseeds, mk, mv, msize


def _add_seeds(indptr, indices, weights, dist, label, seeds, nseeds, new, hk, hv, hn, head, inv_width, mk, mv, msize,
               tie, settled, mark):
    """Add the seeds ``new`` one after another (a loop in Python over the compiled
    propagation: one kernel fewer to compile, a few microseconds per seed)."""
    n = dist.shape[0]
    for s in new.tolist():
        if dist[s] == 0.0 and label[s] >= 0 and seeds[label[s]] == s:
            continue  # already a seed
        seeds[nseeds] = s
        mk, mv = _grow(mk, mv, msize, n)
        msize = _propagate(indptr, indices, weights, dist, label, s, nseeds, hk, hv, hn, head, inv_width,
                           mk, mv, msize, tie, settled, mark)
        nseeds += 1
    return nseeds, mk, mv, msize


#: Dial's buckets are used when the *mean* edge is at most this many times the shortest
#: (else a binary heap). The ring's extra cost is the empty buckets it steps over, about
#: (distance a propagation travels) / (shortest edge) per propagation, so it is the
#: typical edge against the shortest that matters, not the longest (on LS3
#: Loop subdivisions of TOSCA models an outlier edge would send the sampling to the slower
#: heap; ``benchmarks/remesh_hard.py`` compares the two, the same seeds and labels).
DIAL_MAX_RATIO = 1024.0
#: ... and when the ring (longest edge / bucket width buckets) is at most this long.
DIAL_MAX_BUCKETS = 1 << 20


def _dial_ring(weights: np.ndarray, max_ratio: float = DIAL_MAX_RATIO) -> tuple[np.ndarray, float]:
    """(head, 1 / width) of Dial's bucket ring for these edge lengths, or an empty head
    (binary heap) when they are not all positive and finite, when the mean edge is more
    than ``max_ratio`` times the shortest, or when the ring would hold more than
    :data:`DIAL_MAX_BUCKETS` buckets."""
    if len(weights) == 0:
        return np.empty(0, np.int32), 0.0
    wmin, wmax = float(weights.min()), float(weights.max())
    if not (wmin > 0 and np.isfinite(wmax) and float(weights.mean()) <= max_ratio * wmin):
        return np.empty(0, np.int32), 0.0
    width = 0.99 * wmin  # strictly below every edge, with room for round-off
    nb = 1 << int(np.ceil(wmax / width) + 2).bit_length()  # a power of two > wmax / width + 2
    if nb > DIAL_MAX_BUCKETS:
        return np.empty(0, np.int32), 0.0
    return np.full(nb, -1, np.int32), 1.0 / width


class VoronoiState:
    """Seeds, geodesic distance to the nearest seed and Voronoi labels, updated
    incrementally as seeds are added (paper §3.1).

    Parameters
    ----------
    V : (n, 3) float64. F : (m, 3) int64.
    graph : optional precomputed :func:`edge_graph` output (to share between samplings).
    order : optional (n,) permutation: ``graph`` is in this vertex order (graph vertex
        ``i`` = mesh vertex ``order[i]``, see :func:`locality_order` and
        ``edge_graph_from_edges(V, E, order)``). The interface stays in mesh order.
    queue : ``"auto"`` (Dial's buckets when the edge lengths allow, see
        :data:`DIAL_MAX_RATIO`, :data:`DIAL_MAX_BUCKETS`) or ``"heap"``; both give the same
        result.

    Farthest point: the vertex of largest distance, the one of smallest mesh index among
    exact ties.

    Attributes
    ----------
    seeds : (s,) int64 seed vertex indices, in insertion order (label i <-> seeds[i]).
    dist : (n,) float64 graph-geodesic distance of each vertex to its seed (mesh units).
    label : (n,) int32 Voronoi region (index into ``seeds``) of each vertex.
    (``dist`` and ``label`` are fresh arrays on each access when ``order`` is given.)

    Examples
    --------
    Example::

        st = VoronoiState(V, F)
        st.sample(100, first=0); st.add([5, 17])
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, graph=None, order: np.ndarray | None = None,
                 queue: str = "auto"):
        self.n = len(V)
        if graph is None:
            graph, order = edge_graph(V, F), None
        self.indptr, self.indices, self.weights = graph
        self._order = None if order is None else np.asarray(order, np.int64)
        self._rank = None if order is None else _inverse(self._order)
        self._tie = np.arange(self.n) if order is None else self._order  # mesh index of each graph vertex
        self._head, self._inv_width = _dial_ring(self.weights, 0.0 if queue == "heap" else DIAL_MAX_RATIO)
        self._hn = np.empty(len(self.indices) + 1 if len(self._head) else 0, np.int32)
        self._dist = np.full(self.n, np.inf)
        self._label = np.full(self.n, -1, np.int32)
        self._seeds = np.empty(16, np.int64)  # graph (work) order
        self.nseeds = 0
        self._hk = np.empty(len(self.indices) + 1, np.float64)  # one push per relaxation at most
        self._hv = np.empty(len(self.indices) + 1, np.int32)
        self._mk = np.empty(2 * self.n + 16, np.float64)
        self._mv = np.empty(2 * self.n + 16, np.int32)
        self._msize = 0
        self._settled = np.empty(self.n, np.int32)
        self._mark = np.full(self.n, -1, np.int32)

    @property
    def seeds(self) -> np.ndarray:
        s = self._seeds[: self.nseeds]
        return s if self._order is None else self._order[s]

    @property
    def dist(self) -> np.ndarray:
        return self._dist if self._rank is None else self._dist[self._rank]

    @property
    def label(self) -> np.ndarray:
        return self._label if self._rank is None else self._label[self._rank]

    def _to_work(self, v: np.ndarray) -> np.ndarray:
        return v if self._rank is None else self._rank[v]

    def _reserve(self, k: int) -> None:
        if k > len(self._seeds):
            s = np.empty(max(k, 2 * len(self._seeds)), np.int64)
            s[: self.nseeds] = self._seeds[: self.nseeds]
            self._seeds = s

    def sample(self, k: int, first: int) -> None:
        """Farthest-point sampling from vertex ``first`` until ``k`` seeds in total."""
        k = min(int(k), self.n)
        self._reserve(k)
        if self.nseeds == 0:
            self.add([first])
        (self.nseeds, self._mk, self._mv, self._msize) = _fps(
            self.indptr, self.indices, self.weights, self._dist, self._label, self._seeds, self.nseeds, k,
            self._hk, self._hv, self._hn, self._head, self._inv_width, self._mk, self._mv, self._msize, self._tie,
            self._settled, self._mark)

    def add(self, vertices) -> None:
        """Add the given vertices as seeds, in the given order (existing seeds are skipped)."""
        vertices = self._to_work(np.asarray(vertices, np.int64).ravel())
        self._reserve(self.nseeds + len(vertices))
        (self.nseeds, self._mk, self._mv, self._msize) = _add_seeds(
            self.indptr, self.indices, self.weights, self._dist, self._label, self._seeds, self.nseeds,
            vertices, self._hk, self._hv, self._hn, self._head, self._inv_width, self._mk, self._mv, self._msize,
            self._tie, self._settled, self._mark)


def farthest_point_sampling(V: np.ndarray, F: np.ndarray, k: int, *,
                            first: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodesic farthest-point sampling on the edge graph (paper §3.1).

    Parameters
    ----------
    V : (n, 3) float64. F : (m, 3) int64. k : number of seeds. first : first seed.

    Returns
    -------
    seeds : (k,) int64; label : (n,) int64 Voronoi region per vertex; dist : (n,) float64.

    Examples
    --------
    Example::

        seeds, label, dist = farthest_point_sampling(V, F, 500)
    """
    st = VoronoiState(V, F)
    st.sample(k, first)
    return st.seeds.copy(), st.label.copy(), st.dist.copy()

"""Geodesic farthest-point sampling and Voronoi regions on the edge graph
(paper §3.1; Peyré & Cohen 2006 front propagation; ReMatching, Maggioli et al. 2023).

Distances are shortest paths on the mesh edge graph with Euclidean edge lengths. Each
new seed runs an *incremental* Dijkstra that only visits vertices that get closer to it
than to their current seed, so sampling k seeds costs about O(|V| log k log |V|) rather
than k full Dijkstra runs. The hot loops are compiled with numba.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._keys import unique_int

__all__ = ["edge_graph", "edge_graph_from_edges", "VoronoiState", "farthest_point_sampling"]


def edge_graph_from_edges(V: np.ndarray, E: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR edge graph (see :func:`edge_graph`) from unique undirected edges E (e, 2)
    sorted by ``E[:, 0] * n + E[:, 1]``."""
    n = len(V)
    i = np.concatenate([E[:, 0], E[:, 1]])
    j = np.concatenate([E[:, 1], E[:, 0]])
    order = np.argsort(i * n + j)
    rows, indices = i[order], j[order]
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    w = np.sqrt(((V[rows] - V[indices]) ** 2).sum(1))
    return indptr, indices.astype(np.int32), w.astype(np.float32)


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
    a = F.ravel().astype(np.int64)
    b = np.roll(F, -1, axis=1).ravel().astype(np.int64)
    key = unique_int(np.concatenate([a * n + b, b * n + a]))  # both directions, sorted
    rows, indices = key // n, key % n
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    w = np.sqrt(((V[rows] - V[indices]) ** 2).sum(1))
    return indptr, indices.astype(np.int32), w.astype(np.float32)


# ---------------------------------------------------------------- numba heaps
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
    k0 = hk[0]
    v0 = hv[0]
    size -= 1
    k = hk[size]
    v = hv[size]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= size:
            break
        if c + 1 < size and hk[c + 1] < hk[c]:
            c += 1
        if k <= hk[c]:
            break
        hk[i] = hk[c]
        hv[i] = hv[c]
        i = c
    hk[i] = k
    hv[i] = v
    return k0, v0, size


@njit(cache=True)
def _grow(hk, hv, size, need):
    if size + need <= hk.shape[0]:
        return hk, hv
    cap = max(2 * hk.shape[0], size + need)
    nk = np.empty(cap, hk.dtype)
    nv = np.empty(cap, hv.dtype)
    nk[:size] = hk[:size]
    nv[:size] = hv[:size]
    return nk, nv


@njit(cache=True, inline="always")
def _is_local_max(indptr, indices, dist, v):
    d = dist[v]
    for e in range(indptr[v], indptr[v + 1]):
        if dist[indices[e]] > d:
            return False
    return True


@njit(cache=True)
def _propagate(indptr, indices, weights, dist, label, src, lab, hk, hv, mk, mv, msize, settled, mark):
    """Incremental Dijkstra from ``src`` (new label ``lab``): visits only vertices that
    get strictly closer.

    Farthest-point candidates: the farthest vertex is always a local maximum of
    ``dist``, and only the vertices settled in this run and their unsettled neighbours
    can have become local maxima, so only those local maxima are pushed onto the
    max-heap (mk, mv) with key -dist (lazy: entries whose distance later changes are
    skipped when popped). ``hk``/``hv`` must hold len(indices) + 1 entries and the
    max-heap room for n more."""
    dist[src] = 0.0
    label[src] = lab
    size = _push(hk, hv, 0, 0.0, src)
    ns = 0
    while size > 0:
        d, u, size = _pop(hk, hv, size)
        if d > dist[u]:
            continue
        settled[ns] = u
        ns += 1
        mark[u] = lab
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + weights[e]
            if nd < dist[v]:
                dist[v] = nd
                label[v] = lab
                size = _push(hk, hv, size, nd, v)
    for i in range(ns):
        u = settled[i]
        if _is_local_max(indptr, indices, dist, u):
            msize = _push(mk, mv, msize, -dist[u], u)
        for e in range(indptr[u], indptr[u + 1]):
            w = indices[e]
            if mark[w] != lab:
                mark[w] = lab
                if _is_local_max(indptr, indices, dist, w):
                    msize = _push(mk, mv, msize, -dist[w], w)
    return msize


@njit(cache=True)
def _fps(indptr, indices, weights, dist, label, seeds, nseeds, k_target, hk, hv, mk, mv, msize, settled, mark):
    """Farthest-point sampling until ``k_target`` seeds: pop the max-heap (lazy: skip
    entries whose key no longer equals the vertex's distance), propagate from it."""
    n = dist.shape[0]
    while nseeds < k_target:
        found = -1
        while msize > 0:
            negd, v, msize = _pop(mk, mv, msize)
            if -negd == dist[v] and dist[v] > 0.0:
                found = v
                break
        if found < 0:
            break  # every vertex is a seed
        seeds[nseeds] = found
        mk, mv = _grow(mk, mv, msize, n)
        msize = _propagate(indptr, indices, weights, dist, label, found, nseeds, hk, hv, mk, mv, msize,
                           settled, mark)
        nseeds += 1
    return nseeds, mk, mv, msize


@njit(cache=True)
def _add_seeds(indptr, indices, weights, dist, label, seeds, nseeds, new, hk, hv, mk, mv, msize, settled, mark):
    n = dist.shape[0]
    for s in new:
        if dist[s] == 0.0 and label[s] >= 0 and seeds[label[s]] == s:
            continue  # already a seed
        seeds[nseeds] = s
        mk, mv = _grow(mk, mv, msize, n)
        msize = _propagate(indptr, indices, weights, dist, label, s, nseeds, hk, hv, mk, mv, msize,
                           settled, mark)
        nseeds += 1
    return nseeds, mk, mv, msize


class VoronoiState:
    """Seeds, geodesic distance to the nearest seed and Voronoi labels, updated
    incrementally as seeds are added (paper §3.1).

    Parameters
    ----------
    V : (n, 3) float64. F : (m, 3) int64.
    graph : optional precomputed :func:`edge_graph` output (to share between samplings).

    Attributes
    ----------
    seeds : (s,) int64 seed vertex indices, in insertion order (label i <-> seeds[i]).
    dist : (n,) float64 graph-geodesic distance of each vertex to its seed (mesh units).
    label : (n,) int64 Voronoi region (index into ``seeds``) of each vertex.

    Examples
    --------
    >>> st = VoronoiState(V, F)  # doctest: +SKIP
    >>> st.sample(100, first=0); st.add([5, 17])  # doctest: +SKIP
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, graph=None):
        self.n = len(V)
        self.indptr, self.indices, self.weights = graph if graph is not None else edge_graph(V, F)
        self.dist = np.full(self.n, np.inf)
        self.label = np.full(self.n, -1, np.int32)
        self._seeds = np.empty(16, np.int64)
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
        return self._seeds[: self.nseeds]

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
            self.indptr, self.indices, self.weights, self.dist, self.label, self._seeds, self.nseeds, k,
            self._hk, self._hv, self._mk, self._mv, self._msize, self._settled, self._mark)

    def add(self, vertices) -> None:
        """Add the given vertices as seeds (existing seeds are skipped)."""
        vertices = np.asarray(vertices, np.int64).ravel()
        self._reserve(self.nseeds + len(vertices))
        (self.nseeds, self._mk, self._mv, self._msize) = _add_seeds(
            self.indptr, self.indices, self.weights, self.dist, self.label, self._seeds, self.nseeds,
            vertices, self._hk, self._hv, self._mk, self._mv, self._msize, self._settled, self._mark)


def farthest_point_sampling(V: np.ndarray, F: np.ndarray, k: int, *, first: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Geodesic farthest-point sampling on the edge graph (paper §3.1).

    Parameters
    ----------
    V : (n, 3) float64. F : (m, 3) int64. k : number of seeds. first : first seed.

    Returns
    -------
    seeds : (k,) int64; label : (n,) int64 Voronoi region per vertex; dist : (n,) float64.

    Examples
    --------
    >>> seeds, label, dist = farthest_point_sampling(V, F, 500)  # doctest: +SKIP
    """
    st = VoronoiState(V, F)
    st.sample(k, first)
    return st.seeds.copy(), st.label.copy(), st.dist.copy()

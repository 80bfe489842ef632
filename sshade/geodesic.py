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

__all__ = ["edge_graph", "VoronoiState", "farthest_point_sampling"]


def edge_graph(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR adjacency of the mesh edge graph with Euclidean edge lengths.

    Parameters
    ----------
    V : (n, 3) float64. F : (m, 3) int64.

    Returns
    -------
    indptr : (n + 1,) int64; indices : (2e,) int64 neighbour vertices;
    weights : (2e,) float64 edge lengths (mesh units).

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
    return indptr, indices, w


# ---------------------------------------------------------------- numba heaps
@njit(cache=True, inline="always")
def _push(hk, hv, size, k, v):
    if size == hk.shape[0]:
        nk = np.empty(2 * size, hk.dtype)
        nv = np.empty(2 * size, hv.dtype)
        nk[:size] = hk
        nv[:size] = hv
        hk, hv = nk, nv
    i = size
    hk[i] = k
    hv[i] = v
    while i > 0:
        p = (i - 1) >> 1
        if hk[p] <= hk[i]:
            break
        hk[p], hk[i] = hk[i], hk[p]
        hv[p], hv[i] = hv[i], hv[p]
        i = p
    return hk, hv, size + 1


@njit(cache=True, inline="always")
def _pop(hk, hv, size):
    k = hk[0]
    v = hv[0]
    size -= 1
    hk[0] = hk[size]
    hv[0] = hv[size]
    i = 0
    while True:
        l = 2 * i + 1
        if l >= size:
            break
        r = l + 1
        c = l
        if r < size and hk[r] < hk[l]:
            c = r
        if hk[i] <= hk[c]:
            break
        hk[c], hk[i] = hk[i], hk[c]
        hv[c], hv[i] = hv[i], hv[c]
        i = c
    return k, v, size


@njit(cache=True)
def _propagate(indptr, indices, weights, dist, label, src, lab, hk, hv, mk, mv, msize):
    """Incremental Dijkstra from ``src`` (new label ``lab``): visits only vertices that
    get strictly closer. Pushes every vertex it settles onto the max-heap (mk, mv) with
    key -dist (once per run). Returns the (possibly reallocated) heaps and the max-heap size."""
    dist[src] = 0.0
    label[src] = lab
    size = 0
    hk, hv, size = _push(hk, hv, size, 0.0, src)
    while size > 0:
        d, u, size = _pop(hk, hv, size)
        if d > dist[u]:
            continue
        # u is settled for this run: its final distance goes on the max-heap once
        mk, mv, msize = _push(mk, mv, msize, -d, u)
        for e in range(indptr[u], indptr[u + 1]):
            v = indices[e]
            nd = d + weights[e]
            if nd < dist[v]:
                dist[v] = nd
                label[v] = lab
                hk, hv, size = _push(hk, hv, size, nd, v)
    return hk, hv, mk, mv, msize


@njit(cache=True)
def _fps(indptr, indices, weights, dist, label, seeds, nseeds, k_target, hk, hv, mk, mv, msize):
    """Farthest-point sampling until ``k_target`` seeds: pop the max-heap (lazy: skip
    entries whose key no longer equals the vertex's distance), propagate from it."""
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
        hk, hv, mk, mv, msize = _propagate(indptr, indices, weights, dist, label, found, nseeds,
                                           hk, hv, mk, mv, msize)
        nseeds += 1
    return nseeds, hk, hv, mk, mv, msize


@njit(cache=True)
def _add_seeds(indptr, indices, weights, dist, label, seeds, nseeds, new, hk, hv, mk, mv, msize):
    for s in new:
        if dist[s] == 0.0 and label[s] >= 0 and seeds[label[s]] == s:
            continue  # already a seed
        seeds[nseeds] = s
        hk, hv, mk, mv, msize = _propagate(indptr, indices, weights, dist, label, s, nseeds,
                                           hk, hv, mk, mv, msize)
        nseeds += 1
    return nseeds, hk, hv, mk, mv, msize


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
        self.label = np.full(self.n, -1, np.int64)
        self._seeds = np.empty(16, np.int64)
        self.nseeds = 0
        self._hk = np.empty(1024, np.float64)
        self._hv = np.empty(1024, np.int64)
        self._mk = np.empty(max(1024, 2 * self.n), np.float64)
        self._mv = np.empty(max(1024, 2 * self.n), np.int64)
        self._msize = 0

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
        (self.nseeds, self._hk, self._hv, self._mk, self._mv, self._msize) = _fps(
            self.indptr, self.indices, self.weights, self.dist, self.label, self._seeds, self.nseeds, k,
            self._hk, self._hv, self._mk, self._mv, self._msize)

    def add(self, vertices) -> None:
        """Add the given vertices as seeds (existing seeds are skipped)."""
        vertices = np.asarray(vertices, np.int64).ravel()
        self._reserve(self.nseeds + len(vertices))
        (self.nseeds, self._hk, self._hv, self._mk, self._mv, self._msize) = _add_seeds(
            self.indptr, self.indices, self.weights, self.dist, self.label, self._seeds, self.nseeds,
            vertices, self._hk, self._hv, self._mk, self._mv, self._msize)


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

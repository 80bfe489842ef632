"""Topology-preserving low-resolution remesh (paper §3.1; ReMatching, Maggioli et al. 2023).

Pipeline: geodesic farthest-point sampling of ``n_low`` seeds from a random first seed
(:mod:`sshade.geodesic`), then the required vertices (handles) are added as seeds (they
do not drive the sampling, so different first seeds give different samplings), then the
*closed-ball property* (Edelsbrunner & Shah 1997) of the Voronoi decomposition is
checked and seeds are added where it fails, until it holds:

- every Voronoi region is a topological disk (connected, Euler characteristic 1);
- every two adjacent regions meet along a single arc (one path of shared edges);
- every three regions meet at a single point (exactly one high-res face carries the
  three labels).

Boundaries are handled by coning every boundary loop to a virtual vertex that is a
region of its own; the same three rules then also force each region to touch a boundary
loop along at most one arc and each low-res boundary edge to be unique. When the property
holds, the dual (nerve) of the decomposition is a triangulation homeomorphic to the input,
so the low-res mesh ``N`` (vertex i = high-res vertex ``seeds[i]``, faces = the region
triples of high-res faces, orientation kept) is manifold, with the same Euler
characteristic and the same number of boundary loops. Low-res faces whose normal opposes
the high-res surface they stand for are detected and also repaired by adding seeds.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import SShaDeError
from .geodesic import VoronoiState, edge_graph_from_edges
from .halfedge import HalfEdges, boundary_loops, halfedges
from ._keys import unique_int

__all__ = ["RemeshResult", "remesh", "MeshTopology", "mesh_topology"]


@dataclass
class MeshTopology:
    """Precomputed connectivity of the high-res mesh, shared by all samplings.

    Attributes
    ----------
    n : int, vertex count (without cone vertices).
    Fc : (m + b, 3) int64 faces with every boundary loop coned to a virtual vertex
        ``n + loop_index``.
    Ec : (e, 2) int64 unique undirected edges of ``Fc``.
    FEc : (m + b, 3) int64 edge index of each face side.
    n_loops : int, boundary loops. euler : int, Euler characteristic of the input.
    graph : CSR edge graph of the input (indptr, indices, weights).
    vnormals : (n, 3) float64 area-weighted vertex normals of the input.
    """

    n: int
    m: int
    Fc: np.ndarray
    Ec: np.ndarray
    FEc: np.ndarray
    n_loops: int
    euler: int
    graph: tuple
    vnormals: np.ndarray


def mesh_topology(V: np.ndarray, F: np.ndarray, he: HalfEdges | None = None) -> MeshTopology:
    """Connectivity needed by :func:`remesh` (computed once per mesh, shared by samplings).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64, a validated manifold mesh.
    he : its :class:`~sshade.halfedge.HalfEdges` if already built (see
        ``validate_mesh(..., return_halfedges=True)``).
    """
    import igl
    n, m = len(V), len(F)
    if he is None:
        he = halfedges(F, n)
    loops = boundary_loops(F, he)
    e = len(he.E)
    Ec, FEc, Fc = [he.E], [he.FE], [F]
    off = e
    for li, loop in enumerate(loops):
        # cone every loop to a virtual vertex c = n + li; cone faces (b, a, c) run the
        # boundary half-edge a -> b the other way, so the coned mesh stays oriented
        nl = len(loop)
        a_, b_ = loop, np.roll(loop, -1)
        c = n + li
        Fc.append(np.stack([b_, a_, np.full(nl, c)], axis=1))
        spokes = off + np.arange(nl)  # spoke of loop[i] -> c
        Ec.append(np.stack([loop, np.full(nl, c)], axis=1))
        # boundary edge index of (a, b): look it up through the sorted edge keys
        key = np.minimum(a_, b_) * n + np.maximum(a_, b_)
        ekey = he.E[:, 0] * n + he.E[:, 1]
        bidx = np.searchsorted(ekey, key)
        FEc.append(np.stack([bidx, spokes, np.roll(spokes, -1)], axis=1))
        off += nl
    Fc = np.concatenate(Fc).astype(np.int64)
    Ec = np.concatenate(Ec).astype(np.int64)
    FEc = np.concatenate(FEc).astype(np.int64)
    euler = n - e + m
    vn = igl.per_vertex_normals(V, F)
    return MeshTopology(n=n, m=m, Fc=Fc, Ec=Ec, FEc=FEc, n_loops=len(loops), euler=int(euler),
                        graph=edge_graph_from_edges(V, he.E), vnormals=vn)


@dataclass
class RemeshResult:
    """A low-resolution remesh ``N`` of a high-resolution mesh ``M`` (paper §3.1).

    Attributes
    ----------
    seeds : (k,) int64, high-res index of each low-res vertex (``V_N = V_M[seeds]``).
    F : (t, 3) int64, low-res faces, indices into ``seeds``.
    label : (n,) int64, Voronoi region of every high-res vertex (index into ``seeds``).
    dist : (n,) float64, graph-geodesic distance of every high-res vertex to its seed.
    n_sampled : int, seeds placed by farthest-point sampling.
    n_required : int, required vertices (handles) that were not already seeds.
    n_repair : int, seeds added to obtain the closed-ball property / fix flipped faces.
    n_flipped : int, low-res faces whose normal still opposes the high-res surface.
    iterations : int, check-and-repair rounds.
    timings : dict, seconds per step.
    """

    seeds: np.ndarray
    F: np.ndarray
    label: np.ndarray
    dist: np.ndarray
    n_sampled: int
    n_required: int
    n_repair: int
    n_flipped: int
    iterations: int
    first: int
    timings: dict = field(default_factory=dict)

    def vertices(self, V: np.ndarray) -> np.ndarray:
        """(k, 3) low-res vertex positions taken from high-res positions ``V``."""
        return V[self.seeds]


def _group_argmax(groups: np.ndarray, verts: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """For each distinct group id, the vertex in ``verts`` with the largest ``dist``.
    Groups whose best vertex has dist 0 (already seeds) are dropped."""
    if len(groups) == 0:
        return np.empty(0, np.int64)
    order = np.lexsort((-dist[verts], groups))
    g = groups[order]
    first = np.ones(len(g), bool)
    first[1:] = g[1:] != g[:-1]
    best = verts[order][first]
    return best[dist[best] > 0]


def _check(topo: MeshTopology, label: np.ndarray, dist: np.ndarray, nseeds: int, V: np.ndarray,
           seeds: np.ndarray, fix_flips: bool):
    """One round of closed-ball checks. Returns (new seed candidates, low-res faces or
    None, n_flipped)."""
    n = topo.n
    lab = np.concatenate([label, nseeds + np.arange(topo.n_loops)])  # cone vertices: own regions
    Fc, Ec, FEc = topo.Fc, topo.Ec, topo.FEc
    L = lab[Fc]
    EL = lab[Ec]
    nlab = nseeds + topo.n_loops
    cand = []

    # 1. regions are disks: chi = V - E + F == 1 (connectivity holds by construction:
    # every vertex's shortest-path predecessor is in its region)
    same_e = EL[:, 0] == EL[:, 1]
    same_f = (L[:, 0] == L[:, 1]) & (L[:, 1] == L[:, 2])
    chi = (np.bincount(lab, minlength=nlab) - np.bincount(EL[same_e, 0], minlength=nlab)
           + np.bincount(L[same_f, 0], minlength=nlab))
    bad_r = np.flatnonzero(chi != 1)
    if len(bad_r):
        sel = np.flatnonzero(np.isin(label, bad_r))
        cand.append(_group_argmax(label[sel], sel, dist))

    # 2. two regions meet along one arc. Nodes: cross edges; links: faces with exactly
    # two labels (they hold two cross edges of the same pair).
    cross = ~same_e
    ce = np.flatnonzero(cross)
    a, b = np.minimum(EL[ce, 0], EL[ce, 1]), np.maximum(EL[ce, 0], EL[ce, 1])
    pkey = a * nlab + b
    two = (~same_f) & ((L[:, 0] == L[:, 1]) | (L[:, 1] == L[:, 2]) | (L[:, 0] == L[:, 2]))
    f2 = np.flatnonzero(two)
    fe = FEc[f2]
    cr = cross[fe]  # exactly two True per row
    pair_edges = fe[cr].reshape(-1, 2)
    node_of = np.full(len(Ec), -1, np.int64)
    node_of[ce] = np.arange(len(ce))
    A = sp.coo_matrix((np.ones(len(pair_edges)), (node_of[pair_edges[:, 0]], node_of[pair_edges[:, 1]])),
                      shape=(len(ce), len(ce)))
    ncomp, comp = connected_components(A, directed=False)
    upair, pinv, n_e = unique_int(pkey, return_inverse=True, return_counts=True)
    n_f2 = np.bincount(pinv[node_of[pair_edges[:, 0]]], minlength=len(upair))
    # number of distinct components per pair
    pc = unique_int(pinv * (ncomp + 1) + comp)
    comps = np.bincount(pc // (ncomp + 1), minlength=len(upair))
    bad_p = np.flatnonzero((n_e - n_f2 != 1) | (comps != 1))
    if len(bad_p):
        badmask = np.isin(pinv, bad_p)
        e_bad = Ec[ce[badmask]]
        g = np.repeat(pinv[badmask], 2)
        vv = e_bad.ravel()
        keep = vv < n
        cand.append(_group_argmax(g[keep], vv[keep], dist))

    # 3. three regions meet at one point: each label triple on exactly one face
    three = (L[:, 0] != L[:, 1]) & (L[:, 1] != L[:, 2]) & (L[:, 0] != L[:, 2])
    f3 = np.flatnonzero(three)
    S = np.sort(L[f3], axis=1)
    tkey = (S[:, 0] * nlab + S[:, 1]) * nlab + S[:, 2]
    utri, tinv, tcnt = unique_int(tkey, return_inverse=True, return_counts=True)
    bad_t = np.flatnonzero(tcnt != 1)
    if len(bad_t):
        badmask = np.isin(tinv, bad_t)
        vv = Fc[f3[badmask]].ravel()
        g = np.repeat(tinv[badmask], 3)
        keep = vv < n
        cand.append(_group_argmax(g[keep], vv[keep], dist))

    if cand:
        c = unique_int(np.concatenate(cand))
        return c, None, -1

    # Closed-ball property holds: the nerve. Drop faces touching cone vertices.
    keepf = f3[(L[f3] < nseeds).all(axis=1)]
    FN = label[Fc[keepf]]
    # flipped faces: low-res normal vs. high-res vertex normals at the three seeds
    P = V[seeds]
    nN = np.cross(P[FN[:, 1]] - P[FN[:, 0]], P[FN[:, 2]] - P[FN[:, 0]])
    nM = topo.vnormals[seeds[FN]].sum(axis=1)
    flipped = np.einsum("ij,ij->i", nN, nM) <= 0
    nflip = int(flipped.sum())
    if nflip and fix_flips:
        ff = keepf[flipped]
        vv = np.concatenate([np.flatnonzero(np.isin(label, FN[flipped].ravel()))])
        # farthest vertex in the union of the three regions of each flipped face
        g = np.repeat(np.arange(len(ff)), 3)
        regs = FN[flipped].ravel()
        # map each vertex to flipped faces through its region: take best per region
        best_in_region = _group_argmax(label[vv], vv, dist)
        reg_of = label[best_in_region]
        lookup = np.full(nseeds, -1, np.int64)
        lookup[reg_of] = best_in_region
        per_face = lookup[regs].reshape(-1, 3)
        dd = np.where(per_face >= 0, dist[np.maximum(per_face, 0)], -1)
        pick = per_face[np.arange(len(ff)), dd.argmax(axis=1)]
        pick = pick[pick >= 0]
        if len(pick):
            return np.unique(pick), FN, nflip
    return np.empty(0, np.int64), FN, nflip


def remesh(V: np.ndarray, F: np.ndarray, n_low: int, *, seed: int = 0, required=None,
           topology: MeshTopology | None = None, max_rounds: int = 200,
           fix_flips: bool = True, max_flip_rounds: int = 8) -> RemeshResult:
    """Topology-preserving low-resolution remesh (paper §3.1, after ReMatching).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64, a validated single-component manifold mesh
        (see :func:`sshade.validate.validate_mesh`).
    n_low : int, number of farthest-point samples (the low-res mesh gets this many
        vertices plus the required ones plus the few repair seeds).
    seed : int, seeds the RNG that picks the first sample; different seeds give
        different samplings (paper §3.3).
    required : (h,) int64 or None, vertices that must be low-res vertices (handles);
        they are added after the sampling and do not drive it.
    topology : precomputed :func:`mesh_topology` of ``(V, F)`` (shared between samplings).
    max_rounds : int, cap on check-and-repair rounds.
    fix_flips : bool, also add seeds where a low-res face's normal opposes the surface.
    max_flip_rounds : int, at most this many rounds spent on flipped faces; the rest
        are counted in ``n_flipped``.

    Returns
    -------
    RemeshResult

    Raises
    ------
    SShaDeError if ``n_low`` < 4 or the closed-ball property cannot be reached within
    ``max_rounds`` rounds (never seen on valid manifold input).

    Examples
    --------
    >>> rm = remesh(V, F, 1000, seed=0)  # doctest: +SKIP
    >>> VN, FN = V[rm.seeds], rm.F  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    n = len(V)
    if n_low < 4:
        raise SShaDeError(f"n_low must be at least 4, got {n_low}")
    topo = topology if topology is not None else mesh_topology(V, F)
    t1 = time.perf_counter()
    rng = np.random.default_rng(seed)
    first = int(rng.integers(n))
    st = VoronoiState(V, F, graph=topo.graph)
    st.sample(min(n_low, n), first)
    n_sampled = st.nseeds
    if required is not None and len(required):
        st.add(np.asarray(required, np.int64))
    n_req = st.nseeds - n_sampled
    t2 = time.perf_counter()
    FN, nflip, rounds = None, 0, 0
    flip_rounds = 0
    while rounds < max_rounds:
        rounds += 1
        new, FN, nflip = _check(topo, st.label, st.dist, st.nseeds, V, st.seeds, fix_flips and flip_rounds < max_flip_rounds)
        if len(new) == 0:
            break
        if FN is not None:
            flip_rounds += 1
        st.add(new)
    else:
        raise SShaDeError(f"remesh: closed-ball property not reached after {max_rounds} rounds "
                          f"({st.nseeds} seeds); the input may not be a manifold surface")
    if FN is None:
        raise SShaDeError("remesh: closed-ball property not reached")
    t3 = time.perf_counter()
    return RemeshResult(seeds=st.seeds.copy(), F=np.ascontiguousarray(FN, np.int64), label=st.label.copy(),
                        dist=st.dist.copy(), n_sampled=n_sampled, n_required=n_req,
                        n_repair=st.nseeds - n_sampled - n_req, n_flipped=nflip, iterations=rounds, first=first,
                        timings={"topology_s": t1 - t0, "sampling_s": t2 - t1, "repair_s": t3 - t2})

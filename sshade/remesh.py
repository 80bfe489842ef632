"""Topology-preserving low-resolution remesh (paper §3.1; ReMatching, Maggioli et al. 2023).

Pipeline: geodesic farthest-point sampling of ``n_low`` seeds from a random first seed
(:mod:`sshade.mesh.geodesic`), then the required vertices (handles) are added as seeds (they
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
the high-res surface they stand for are detected and also repaired by adding seeds, at
their Voronoi vertices (:mod:`sshade.remesh_repair`; a departure from the paper).
Each round repairs every violation it finds, of the property and flips alike (issue 24).

Speed (issue 13): the connectivity (:func:`mesh_topology`) is built once per mesh and
shared by the samplings; the sampling runs on the edge graph in a cache-friendly vertex
order (:mod:`sshade.mesh.geodesic`); each check round is one compiled pass over the faces
when the property holds (the common case at 6000 seeds) and a compiled pass over edges
and faces that also picks the repair seeds when it does not.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ._keys import unique_int
from .errors import SShaDeError
from .mesh.geodesic import VoronoiState, edge_graph_from_edges, locality_order
from .mesh.halfedge import HalfEdges, boundary_loops, halfedges, vertex_normals
from .remesh_repair import flipped_faces, nerve_faces, voronoi_vertex_seeds

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
    graph : CSR edge graph of the input (indptr, indices, weights), in ``order``.
    vnormals : (n, 3) float64 area-weighted vertex normals of the input.
    order : (n,) int64 locality order of the vertices (graph vertex i = mesh vertex
        ``order[i]``; :func:`sshade.mesh.geodesic.locality_order`).
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
    order: np.ndarray


def mesh_topology(V: np.ndarray, F: np.ndarray, he: HalfEdges | None = None) -> MeshTopology:
    """Connectivity needed by :func:`remesh` (computed once per mesh, shared by samplings).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64, a validated manifold mesh.
    he : its :class:`~sshade.mesh.halfedge.HalfEdges` if already built (see
        ``validate_mesh(..., return_halfedges=True)``).
    """
    n, m = len(V), len(F)
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    if he is None:
        he = halfedges(F, n)
    loops = boundary_loops(F, he)
    e = len(he.E)
    Ec, FEc, Fc = [he.E], [he.FE], [F]
    off = e
    if loops:
        # edge index of the boundary half-edge leaving each boundary vertex
        bh = np.flatnonzero(he.twin < 0)
        out_edge = np.full(n, -1, np.int64)
        out_edge[F.ravel()[bh]] = he.FE.ravel()[bh]
    for li, loop in enumerate(loops):
        # cone every loop to a virtual vertex c = n + li; cone faces (b, a, c) run the
        # boundary half-edge a -> b the other way, so the coned mesh stays oriented
        nl = len(loop)
        a_, b_ = loop, np.roll(loop, -1)
        c = n + li
        Fc.append(np.stack([b_, a_, np.full(nl, c)], axis=1))
        spokes = off + np.arange(nl)  # spoke of loop[i] -> c
        Ec.append(np.stack([loop, np.full(nl, c)], axis=1))
        FEc.append(np.stack([out_edge[a_], spokes, np.roll(spokes, -1)], axis=1))
        off += nl
    # (no copy for a closed mesh)
    Fc, Ec, FEc = (x[0] if len(x) == 1 else np.concatenate(x).astype(np.int64, copy=False) for x in (Fc, Ec, FEc))
    euler = n - e + m
    order = locality_order(V)
    _warm_check()
    return MeshTopology(n=n, m=m, Fc=Fc, Ec=Ec, FEc=FEc, n_loops=len(loops), euler=int(euler),
                        graph=edge_graph_from_edges(V, he.E, order), vnormals=vertex_normals(V, F), order=order)


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
    timings : dict, seconds per step: topology_s (mesh_topology, when not given),
        sampling_s = fps_s (farthest-point sampling) + required_s (adding the handles),
        repair_s = check_s (closed-ball checks, nerve, flips) + add_s (repair seeds).
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


# ------------------------------------------------------------ closed-ball check
# Pairs and triples of region labels are numbered through open-addressing hash tables
# (int64 keys, -1 = empty slot, linear probing, Fibonacci hashing).
_HASH_MULT = -7046029254386353131  # 0x9E3779B97F4A7C15 as int64


@njit(cache=True, inline="always")
def _slot(keys, key, mask):
    i = ((key * _HASH_MULT) >> 24) & mask
    while keys[i] != -1 and keys[i] != key:
        i = (i + 1) & mask
    return i


@njit(cache=True, inline="always")
def _table_id(keys, ids, key, mask, nxt):
    """Id of ``key`` in the table (keys, ids), inserting it with id ``nxt`` if new.
    Returns (id, next free id)."""
    i = _slot(keys, key, mask)
    if keys[i] == -1:
        keys[i] = key
        ids[i] = nxt
        nxt += 1
    return ids[i], nxt


@njit(cache=True)
def _table(n_keys):
    cap = 16
    while cap < 2 * n_keys:
        cap *= 2
    return np.full(cap, -1, np.int64), np.empty(cap, np.int64), cap - 1


@njit(cache=True, inline="always")
def _find(parent, x):
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@njit(cache=True, inline="always")
def _better(best, g, v, dist):
    """Keep the first vertex of largest distance per group (ties: the earlier one)."""
    if best[g] < 0 or dist[v] > dist[best[g]]:
        best[g] = v


@njit(cache=True)
def _closed_ball_full(Fc, Ec, FEc, lab, dist, n, nlab):
    """One round of closed-ball checks with the repair candidates (see :func:`_check`).

    lab : (n + loops,) labels with the cone vertices as their own regions.
    Returns (bad, cand, f3): whether the property fails, the sorted unique seed
    candidates and the faces carrying three labels, in face order."""
    chi, kind, ncross, n3 = _region_euler(Fc, Ec, lab, nlab)
    pair, parent, arc, np_ = _cross_pairs(Ec, lab, nlab, ncross)
    cyc = np.zeros(np_, np.bool_)
    f3, tri, nt = _link_faces(Fc, FEc, lab, nlab, kind, n3, pair, parent, arc, cyc)
    tcnt = np.zeros(nt, np.int64)
    for j in range(n3):
        tcnt[tri[j]] += 1
    bad = False
    for r in range(nlab):
        bad |= chi[r] != 1
    for p in range(np_):
        bad |= arc[p] != 1 or cyc[p]
    for t in range(nt):
        bad |= tcnt[t] != 1
    if not bad:
        return False, np.empty(0, np.int64), f3
    pick = _repair_candidates(Fc, Ec, lab, dist, n, nlab, chi, pair, arc, cyc, np_, f3, tri, tcnt, nt)
    return True, np.flatnonzero(pick), f3


@njit(cache=True)
def _region_euler(Fc, Ec, lab, nlab):
    """1. regions are disks: chi = V - E + F == 1 per label. Returns chi (nlab,), the
    number of distinct labels of each face (nf,) int8, the cross-edge count and the
    count of faces with three labels."""
    ne, nf = Ec.shape[0], Fc.shape[0]
    chi = np.zeros(nlab, np.int64)
    for v in range(lab.shape[0]):
        chi[lab[v]] += 1
    ncross = 0
    for e in range(ne):
        if lab[Ec[e, 0]] == lab[Ec[e, 1]]:
            chi[lab[Ec[e, 0]]] -= 1
        else:
            ncross += 1
    kind = np.empty(nf, np.int8)  # number of distinct labels of each face
    n3 = 0
    for f in range(nf):
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        if l0 == l1 and l1 == l2:
            kind[f] = 1
            chi[l0] += 1
        elif l0 != l1 and l1 != l2 and l0 != l2:
            kind[f] = 3
            n3 += 1
        else:
            kind[f] = 2
    return chi, kind, ncross, n3


@njit(cache=True)
def _cross_pairs(Ec, lab, nlab, ncross):
    """2. two regions meet along one arc: the cross edges of a pair, linked through the
    faces with two labels, form paths and cycles; one arc <=> (edges - links) == 1 and
    no link closes a cycle (union-find over the cross edges). Returns each edge's pair
    id (-1 inside a region), the union-find parents, the per-pair cross-edge counts
    (links are subtracted by :func:`_link_faces`) and the number of pairs."""
    ne = Ec.shape[0]
    pkeys, pids, pmask = _table(ncross)
    pair = np.full(ne, -1, np.int64)
    parent = np.empty(ne, np.int64)
    np_ = 0
    for e in range(ne):
        a, b = lab[Ec[e, 0]], lab[Ec[e, 1]]
        if a != b:
            pair[e], np_ = _table_id(pkeys, pids, min(a, b) * nlab + max(a, b), pmask, np_)
            parent[e] = e
    arc = np.zeros(np_, np.int64)  # cross edges - links: 1 for a single path
    for e in range(ne):
        if pair[e] >= 0:
            arc[pair[e]] += 1
    return pair, parent, arc, np_


@njit(cache=True)
def _link_faces(Fc, FEc, lab, nlab, kind, n3, pair, parent, arc, cyc):
    """Links of the cross edges through the two-label faces (updates ``arc``, ``cyc``,
    ``parent`` in place) and 3. three regions meet at one point: each label triple on
    exactly one face. Returns the three-label faces (n3,), their triple ids and the
    number of triples."""
    tkeys, tids, tmask = _table(n3)
    f3 = np.empty(n3, np.int64)
    tri = np.empty(n3, np.int64)
    nt = 0
    j = 0
    for f in range(Fc.shape[0]):
        if kind[f] == 2:
            e1 = -1
            for k in range(3):
                e = FEc[f, k]
                if pair[e] >= 0:
                    if e1 < 0:
                        e1 = e
                    else:
                        arc[pair[e]] -= 1
                        r1, r2 = _find(parent, e1), _find(parent, e)
                        if r1 == r2:
                            cyc[pair[e]] = True
                        else:
                            parent[r1] = r2
        elif kind[f] == 3:
            l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
            a = min(l0, l1, l2)
            c = max(l0, l1, l2)
            b = l0 + l1 + l2 - a - c
            f3[j] = f
            tri[j], nt = _table_id(tkeys, tids, (a * nlab + b) * nlab + c, tmask, nt)
            j += 1
    return f3, tri, nt


@njit(cache=True)
def _repair_candidates(Fc, Ec, lab, dist, n, nlab, chi, pair, arc, cyc, np_, f3, tri, tcnt, nt):
    """Candidates: per bad region / pair / triple, its farthest vertex from its seed
    (first one met on ties, in vertex / edge / face order), if not a seed already.
    Returns a (n,) bool mask."""
    pick = np.zeros(n, np.bool_)
    best = np.full(max(nlab, np_, nt), -1, np.int64)
    for v in range(n):
        if chi[lab[v]] != 1:
            _better(best, lab[v], v, dist)
    for r in range(nlab):
        if best[r] >= 0 and dist[best[r]] > 0:
            pick[best[r]] = True
    best[:] = -1
    for e in range(Ec.shape[0]):
        p = pair[e]
        if p >= 0 and (arc[p] != 1 or cyc[p]):
            for k in range(2):
                if Ec[e, k] < n:
                    _better(best, p, Ec[e, k], dist)
    for p in range(np_):
        if best[p] >= 0 and dist[best[p]] > 0:
            pick[best[p]] = True
    best[:] = -1
    for j in range(f3.shape[0]):
        t = tri[j]
        if tcnt[t] != 1:
            for k in range(3):
                if Fc[f3[j], k] < n:
                    _better(best, t, Fc[f3[j], k], dist)
    for t in range(nt):
        if best[t] >= 0 and dist[best[t]] > 0:
            pick[best[t]] = True
    return pick


@njit(cache=True)
def _closed_ball_holds(Fc, FEc, lab, nlab, ne):
    """Whether the closed-ball property holds, from one pass over the faces (the common
    case once the sampling is dense enough; :func:`_closed_ball_full` otherwise).

    On the coned mesh every edge lies on exactly two faces, so the edge counts follow
    from the faces: a region's same-label edges number (3 F1 + F2) / 2 (F1: faces of
    that label only, F2: faces with it twice), so 2 chi = 2 V - F1 - F2; and a pair's
    cross edges minus its two-label faces (the number of its arcs that are paths) is
    half its three-label faces F3. The property holds iff 2 chi == 2 for every
    region, F3 == 2 and no closed loop for every pair (union-find over the cross edges
    linked by the two-label faces: a pair whose edges only form loops has F3 == 0 but
    is caught by its loop), and every label triple is on one face.
    Returns (holds, f3 = the three-label faces in face order)."""
    nf = Fc.shape[0]
    chi2 = np.zeros(nlab, np.int64)
    for v in range(lab.shape[0]):
        chi2[lab[v]] += 2
    parent = np.arange(ne)
    f3 = np.empty(nf, np.int64)
    n3 = 0
    for f in range(nf):
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        if l0 == l1 and l1 == l2:
            chi2[l0] -= 1
        elif l0 != l1 and l1 != l2 and l0 != l2:
            f3[n3] = f
            n3 += 1
        else:
            chi2[l1 if (l0 == l1 or l1 == l2) else l0] -= 1
            # the two cross edges: the sides whose end points have different labels
            e1 = FEc[f, 0] if l0 != l1 else FEc[f, 1]
            e2 = FEc[f, 2] if l2 != l0 else FEc[f, 1]
            r1, r2 = _find(parent, e1), _find(parent, e2)
            if r1 == r2:
                return False, f3[:n3]  # a loop
            parent[r1] = r2
    for r in range(nlab):
        if chi2[r] != 2:
            return False, f3[:n3]
    keys, ids, mask = _table(3 * n3)
    cnt = np.zeros(3 * n3, np.int64)
    np_ = 0
    for j in range(n3):
        f = f3[j]
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        a = min(l0, l1, l2)
        c = max(l0, l1, l2)
        b = l0 + l1 + l2 - a - c
        for key in (a * nlab + b, b * nlab + c, a * nlab + c):
            p, np_ = _table_id(keys, ids, key, mask, np_)
            cnt[p] += 1
    for p in range(np_):
        if cnt[p] != 2:
            return False, f3[:n3]
    tkeys, _, tmask = _table(n3)
    for j in range(n3):
        f = f3[j]
        l0, l1, l2 = lab[Fc[f, 0]], lab[Fc[f, 1]], lab[Fc[f, 2]]
        a = min(l0, l1, l2)
        c = max(l0, l1, l2)
        b = l0 + l1 + l2 - a - c
        i = _slot(tkeys, (a * nlab + b) * nlab + c, tmask)
        if tkeys[i] != -1:
            return False, f3[:n3]  # a triple on two faces
        tkeys[i] = (a * nlab + b) * nlab + c
    return True, f3[:n3].copy()


@njit(cache=True)
def _closed_ball(Fc, Ec, FEc, lab, dist, n, nlab):
    """One round of closed-ball checks (see :func:`_check`): the one-pass test, and the
    full check with repair candidates when it fails. Returns (bad, cand, f3)."""
    ok, f3 = _closed_ball_holds(Fc, FEc, lab, nlab, Ec.shape[0])
    if ok:
        return False, np.empty(0, np.int64), f3
    return _closed_ball_full(Fc, Ec, FEc, lab, dist, n, nlab)


def _check(topo: MeshTopology, label: np.ndarray, dist: np.ndarray, nseeds: int, V: np.ndarray,
           seeds: np.ndarray, fix_flips: bool):
    """One round of closed-ball checks and flipped-face repair (paper §3.1; flips:
    :mod:`sshade.remesh_repair`). Returns (new seed candidates (c,) int64, low-res faces
    (t, 3) int64 or None while the property fails, number of flipped faces: of the
    nerve when it holds, else of its already valid faces, -1 when not looked at).

    - every Voronoi region is a topological disk (connectivity holds by construction:
      every vertex's shortest-path predecessor is in its region, so chi == 1 suffices);
    - two regions meet along one arc; three regions meet at one point;
    candidates are the farthest vertex of every failing region, pair and triple
    (compiled: :func:`_closed_ball`), and with ``fix_flips`` the Voronoi vertex of every
    flipped low-res face, in the same round (issue 24: the property's and the flips'
    repairs do not wait for each other)."""
    lab = np.concatenate([label, nseeds + np.arange(topo.n_loops, dtype=label.dtype)])  # cone vertices: own regions
    bad, cand, f3 = _closed_ball(topo.Fc, topo.Ec, topo.FEc, lab, dist, topo.n, nseeds + topo.n_loops)
    if bad and not fix_flips:
        return cand, None, -1
    keepf, FN = nerve_faces(topo.Fc, lab, f3, nseeds, unique_only=bad)
    flipped = flipped_faces(V, topo.vnormals, seeds, FN)
    nflip = int(flipped.sum())
    new = voronoi_vertex_seeds(topo.Fc, keepf[flipped], FN[flipped], label, dist) if nflip and fix_flips else cand[:0]
    if bad:
        return unique_int(np.concatenate([cand, new])), None, nflip
    return new, FN, nflip


_WARM = False


def _warm_check() -> None:
    """Compile (or load from numba's cache) the check kernel in this process with the
    argument types :func:`remesh` uses, so that worker processes forked after
    :func:`mesh_topology` inherit it."""
    global _WARM
    if _WARM:
        return
    Fc = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    he = halfedges(Fc, 4)
    _closed_ball(Fc, he.E, he.FE, np.arange(4, dtype=np.int32), np.zeros(4), 4, 4)
    _WARM = True


def remesh(V: np.ndarray, F: np.ndarray, n_low: int, *, seed: int = 0, required=None,
           topology: MeshTopology | None = None, max_rounds: int = 200,
           fix_flips: bool = True, max_flip_rounds: int = 8) -> RemeshResult:
    """Topology-preserving low-resolution remesh (paper §3.1, after ReMatching).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64, a validated single-component manifold mesh
        (see :func:`sshade.mesh.validate.validate_mesh`).
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
    Example::

        rm = remesh(V, F, 1000, seed=0)
        VN, FN = V[rm.seeds], rm.F
    """
    t0 = time.perf_counter()
    n = len(V)
    if n_low < 4:
        raise SShaDeError(f"n_low must be at least 4, got {n_low}")
    topo = topology if topology is not None else mesh_topology(V, F)
    t1 = time.perf_counter()
    rng = np.random.default_rng(seed)
    first = int(rng.integers(n))
    st = VoronoiState(V, F, graph=topo.graph, order=topo.order)
    st.sample(min(n_low, n), first)
    n_sampled = st.nseeds
    t_fps = time.perf_counter()
    if required is not None and len(required):
        st.add(np.asarray(required, np.int64))
    n_req = st.nseeds - n_sampled
    t2 = time.perf_counter()
    FN, nflip, rounds = None, 0, 0
    flip_rounds = 0
    t_check = 0.0
    while rounds < max_rounds:
        rounds += 1
        tc = time.perf_counter()
        label, dist, seeds = st.label, st.dist, st.seeds
        fix = fix_flips and flip_rounds < max_flip_rounds
        new, FN, nflip = _check(topo, label, dist, st.nseeds, V, seeds, fix)
        t_check += time.perf_counter() - tc
        if len(new) == 0:
            break
        if fix and nflip > 0:
            flip_rounds += 1
        st.add(new)
    else:
        raise SShaDeError(f"remesh: closed-ball property not reached after {max_rounds} rounds "
                          f"({st.nseeds} seeds); the input may not be a manifold surface")
    if FN is None:
        raise SShaDeError("remesh: closed-ball property not reached")
    t3 = time.perf_counter()
    return RemeshResult(seeds=seeds, F=np.ascontiguousarray(FN, np.int64), label=label,
                        dist=dist, n_sampled=n_sampled, n_required=n_req,
                        n_repair=st.nseeds - n_sampled - n_req, n_flipped=nflip, iterations=rounds, first=first,
                        timings={"topology_s": t1 - t0, "sampling_s": t2 - t1, "repair_s": t3 - t2,
                                 "fps_s": t_fps - t1, "required_s": t2 - t_fps, "check_s": t_check,
                                 "add_s": t3 - t2 - t_check})

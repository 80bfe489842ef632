"""Topology-preserving low-resolution remesh (paper §3.1; ReMatching, Maggioli et al. 2023).

:func:`remesh`: geodesic farthest-point sampling of ``n_low`` seeds from a random first
seed (:mod:`sshade.mesh.geodesic`), the required vertices (handles) added, then seeds
added until the Voronoi decomposition has the closed-ball property (Edelsbrunner & Shah
1997; :mod:`sshade.closed_ball`) and no low-res face is flipped or degenerate
(:mod:`sshade.remesh_repair`, a departure); its nerve is then a manifold low-res mesh
homeomorphic to the input. :func:`mesh_topology` is built once per mesh; :func:`remesh_drawn`
draws again when a degenerate face is left. Details: docs/implementation.md ("Implementation
notes: sshade/remesh.py").
"""
from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .closed_ball import closed_ball, closed_ball_local, vertex_faces
from .closed_ball import warm_kernels as warm_closed_ball
from .cores import available_cores
from .errors import SShaDeError
from .mesh.geodesic import VoronoiState, edge_graph_from_edges, locality_order
from .mesh.halfedge import HalfEdges, boundary_loops, halfedges, vertex_normals
from .remesh_repair import degenerate_faces, faces_to_repair, fixed_faces, nerve_faces, voronoi_vertex_seeds
from .unique import unique_int

__all__ = ["RemeshResult", "remesh", "remesh_drawn", "redraw_seed", "MAX_REDRAWS", "MeshTopology", "mesh_topology"]


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
    vf_ptr : (n + 1,) int64, vf_idx : (3 m + 2 c,) int32 (c cone faces), the faces of
        ``Fc`` around each vertex (:func:`sshade.closed_ball.vertex_faces`), for the local
        checks.
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
    vf_ptr: np.ndarray
    vf_idx: np.ndarray


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
    # the sampling's graph (locality order, then the CSR: compiled without the GIL) is
    # built in a second thread, where a second core is there, while this one builds the
    # rest (this setup is the serial part of a SShaDe call)
    with ThreadPoolExecutor(1) if available_cores() > 1 else _InPlace() as ex:
        graph = ex.submit(_sampling_graph, V, he.E)
        Fc, Ec, FEc, n_loops = _coned(F, he, n)
        _warm_check()
        vnormals = vertex_normals(V, F)
        vf_ptr, vf_idx = vertex_faces(Fc, n)
        order, csr = graph.result()
    return MeshTopology(n=n, m=m, Fc=Fc, Ec=Ec, FEc=FEc, n_loops=n_loops, euler=int(n - len(he.E) + m),
                        graph=csr, vnormals=vnormals, order=order, vf_ptr=vf_ptr, vf_idx=vf_idx)


class _InPlace:
    """An executor that runs a task at once, in this thread (one core)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> bool:
        return False

    def submit(self, fn, *args) -> Future:
        f: Future = Future()
        f.set_result(fn(*args))
        return f


def _sampling_graph(V: np.ndarray, E: np.ndarray) -> tuple[np.ndarray, tuple]:
    """(locality order (n,) int64, CSR edge graph in that order) of the sampling."""
    order = locality_order(V)
    return order, edge_graph_from_edges(V, E, order)


def _coned(F: np.ndarray, he: HalfEdges, n: int):
    """(Fc, Ec, FEc, loops): faces, edges and face edges with every boundary loop coned
    to a virtual vertex ``n + loop index`` (see :class:`MeshTopology`)."""
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
    return Fc, Ec, FEc, len(loops)


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
    n_flipped : int, low-res faces still flipped or degenerate (:func:`sshade.remesh_repair.faces_to_repair`).
    n_degenerate : int, of those, the degenerate ones (:func:`sshade.remesh_repair.degenerate_faces`)
        but those whose corners are all required (:func:`sshade.remesh_repair.fixed_faces`).
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
    n_degenerate: int = 0
    timings: dict = field(default_factory=dict)

    def vertices(self, V: np.ndarray) -> np.ndarray:
        """(k, 3) low-res vertex positions taken from high-res positions ``V``."""
        return V[self.seeds]


def _check(topo: MeshTopology, label: np.ndarray, dist: np.ndarray, nseeds: int, V: np.ndarray,
           seeds: np.ndarray, fix_flips: bool, fixed: np.ndarray | None = None):
    """One round of closed-ball checks and flipped-face repair (paper §3.1; flips:
    :mod:`sshade.remesh_repair`). Returns (new seed candidates (c,) int64, low-res faces
    (t, 3) int64 or None while the property fails, number of flipped faces: of the
    nerve when it holds, else of its already valid faces, -1 when not looked at).

    - every Voronoi region is a topological disk (connectivity holds by construction:
      every vertex's shortest-path predecessor is in its region, so chi == 1 suffices);
    - two regions meet along one arc; three regions meet at one point;
    candidates are the farthest vertex of every failing region, pair and triple
    (compiled: :func:`sshade.closed_ball.closed_ball`), and with ``fix_flips`` the Voronoi vertex of every
    flipped low-res face, in the same round (the property's and the flips'
    repairs do not wait for each other); ``fixed`` (n,) bool or None: the required
    vertices (:func:`sshade.remesh_repair.fixed_faces`)."""
    lab = np.concatenate([label, nseeds + np.arange(topo.n_loops, dtype=label.dtype)])  # cone vertices: own regions
    bad, cand, f3 = closed_ball(topo.Fc, topo.Ec, topo.FEc, lab, dist, topo.n, nseeds + topo.n_loops)
    if bad and not fix_flips:
        return cand, None, -1
    keepf, FN = nerve_faces(topo.Fc, lab, f3, nseeds, unique_only=bad)
    flipped = faces_to_repair(V, topo.vnormals, seeds, FN, fixed)
    nflip = int(flipped.sum())
    new = voronoi_vertex_seeds(topo.Fc, keepf[flipped], FN[flipped], label, dist) if nflip and fix_flips else cand[:0]
    if bad:
        return unique_int(np.concatenate([cand, new])), None, nflip
    return new, FN, nflip


def _check_local(topo: MeshTopology, label: np.ndarray, dist: np.ndarray, nseeds: int, V: np.ndarray,
                 seeds: np.ndarray, fix_flips: bool, before: np.ndarray, fixed: np.ndarray | None = None):
    """A round after seeds were added: :func:`_check` restricted to the
    regions whose vertices changed label since ``before`` (the labels (n,) of the
    previous round; :func:`sshade.closed_ball.closed_ball_local`), the flips among the
    triples involving them. Returns (new seed candidates (c,) int64, flipped faces found).
    No candidate does not mean the property holds: :func:`remesh` then runs :func:`_check`."""
    nlab = nseeds + topo.n_loops
    lab = np.concatenate([label, nseeds + np.arange(topo.n_loops, dtype=label.dtype)])
    changed = label != before
    in_a = np.zeros(nlab, np.bool_)
    in_a[before[changed]] = True
    in_a[label[changed]] = True
    _, cand, f3u = closed_ball_local(topo.Fc, topo.Ec, topo.FEc, topo.vf_ptr, topo.vf_idx, lab, dist, topo.n,
                                     nlab, in_a)
    if not fix_flips:
        return cand, 0
    keepf, FN = nerve_faces(topo.Fc, lab, f3u, nseeds)
    flipped = faces_to_repair(V, topo.vnormals, seeds, FN, fixed)
    nflip = int(flipped.sum())
    if not nflip:
        return cand, 0
    new = voronoi_vertex_seeds(topo.Fc, keepf[flipped], FN[flipped], label, dist)
    return unique_int(np.concatenate([cand, new])), nflip


_WARM = False


def _warm_check() -> None:
    """Compile (or load from numba's cache) the check kernel in this process with the
    argument types :func:`remesh` uses, so that worker processes forked after
    :func:`mesh_topology` inherit it."""
    global _WARM
    if _WARM:
        return
    warm_closed_ball()
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
    fix_flips : bool, also add seeds where a low-res face's normal opposes the surface
        or the face is degenerate (:func:`sshade.remesh_repair.faces_to_repair`).
    max_flip_rounds : int, at most this many rounds spent on those faces; the rest
        are counted in ``n_flipped`` (the degenerate ones also in ``n_degenerate``).

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
    fixed = None
    if required is not None and len(required):
        st.add(np.asarray(required, np.int64))
        fixed = np.zeros(n, bool)
        fixed[np.asarray(required, np.int64)] = True
    n_req = st.nseeds - n_sampled
    t2 = time.perf_counter()
    FN, nflip, rounds = None, 0, 0
    flip_rounds = 0
    t_check = 0.0
    before = None  # the labels before the last round's seeds: later rounds check near them first
    while rounds < max_rounds:
        rounds += 1
        tc = time.perf_counter()
        label, dist, seeds = st.label, st.dist, st.seeds
        fix = fix_flips and flip_rounds < max_flip_rounds
        new = None
        if before is not None:
            new, nflip = _check_local(topo, label, dist, st.nseeds, V, seeds, fix, before, fixed)
        if new is None or len(new) == 0:  # the first round, or nothing left near the changes
            new, FN, nflip = _check(topo, label, dist, st.nseeds, V, seeds, fix, fixed)
        t_check += time.perf_counter() - tc
        if len(new) == 0:
            break
        if fix and nflip > 0:
            flip_rounds += 1
        before = label
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
                        n_degenerate=_n_degenerate(V, seeds, FN, fixed),
                        timings={"topology_s": t1 - t0, "sampling_s": t2 - t1, "repair_s": t3 - t2,
                                 "fps_s": t_fps - t1, "required_s": t2 - t_fps, "check_s": t_check,
                                 "add_s": t3 - t2 - t_check})


#: Draws of a sampling after the first when its low-res mesh keeps a degenerate face
#: (:func:`remesh_drawn`).
MAX_REDRAWS = 4


def _n_degenerate(V: np.ndarray, seeds: np.ndarray, FN: np.ndarray, fixed: np.ndarray | None) -> int:
    """Degenerate low-res faces a redraw could remove: not those whose corners are all
    required (:func:`sshade.remesh_repair.fixed_faces`)."""
    deg = degenerate_faces(V[seeds], FN)
    if fixed is not None and deg.any():
        deg &= ~fixed_faces(fixed, seeds, FN)
    return int(deg.sum())


def redraw_seed(seed: int, attempt: int) -> int:
    """The RNG seed of draw ``attempt`` (>= 1) of the sampling seeded ``seed``
    (:func:`remesh_drawn`), derived from both; recorded in the info."""
    return int(np.random.SeedSequence([int(seed), int(attempt)]).generate_state(1, dtype=np.uint32)[0])


def remesh_drawn(V: np.ndarray, F: np.ndarray, n_low: int, *, seed: int, required=None,
                 topology: MeshTopology | None = None) -> tuple[RemeshResult, list[int]]:
    """:func:`remesh`, drawn again with a derived seed (:func:`redraw_seed`, at most
    :data:`MAX_REDRAWS` times) while the low-res mesh keeps a degenerate face (one the
    repair rounds left: :attr:`RemeshResult.n_degenerate`), whose cotangent weights the
    low-res ARAP could not use.

    Parameters
    ----------
    As :func:`remesh` (``V`` (n, 3) float64, ``F`` (m, 3) int64, ``required`` (h,) int64).

    Returns
    -------
    (RemeshResult without a degenerate face, the seeds of the draws given up (list, in order)).

    Raises
    ------
    SShaDeError when every draw keeps a degenerate face, or as :func:`remesh`.
    """
    given_up = []
    s = int(seed)
    for attempt in range(1, MAX_REDRAWS + 2):
        rm = remesh(V, F, n_low, seed=s, required=required, topology=topology)
        if rm.n_degenerate == 0:
            return rm, given_up
        given_up.append(s)
        s = redraw_seed(seed, attempt)
    raise SShaDeError(f"remesh: every one of {MAX_REDRAWS + 1} samplings drawn from seed {seed} kept a "
                      f"degenerate low-res face (seeds {given_up}); the handles may be too close together")

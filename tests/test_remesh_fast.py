"""The compiled fast paths of the remesher against plain numpy/scipy
references: half-edges, pinch vertices, components, boundary loops, the fast
validation, the edge graph, the closed-ball check, and the farthest-point sampling's
independence from the vertex order and the priority queue (with exact distance ties)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from sshade.closed_ball import closed_ball_full as _closed_ball_full
from sshade.closed_ball import closed_ball_holds as _closed_ball_holds
from sshade.closed_ball import closed_ball_local
from sshade.mesh.geodesic import VoronoiState, edge_graph, edge_graph_from_edges, locality_order
from sshade.mesh.halfedge import (
    boundary_loops,
    count_components,
    count_pinched_vertices,
    halfedges,
    vertex_fan_count,
    vertex_normals,
)
from sshade.mesh.io import read_mesh
from sshade.mesh.validate import _fast_checks, validate_mesh
from sshade.remesh import _check, mesh_topology, remesh
from sshade.unique import unique_int

from .conftest import data_file
from .test_bad_input import BAD_MESHES, KNOWN_BAD_MESH_BUGS, _bowtie, _double_cone

REAL = ["faust_reg/tr_reg_000.ply", "tosca/cat0.off", "classic/bunny.off"]


# ----------------------------------------------------------------- references
def _halfedges_ref(F, n):
    """The sort-based construction (stable argsort of lo * n + hi)."""
    a = F.ravel()
    b = np.roll(F, -1, axis=1).ravel()
    key = np.minimum(a, b) * n + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    sk = key[order]
    start = np.r_[True, sk[1:] != sk[:-1]]
    FE = np.empty(len(key), np.int64)
    FE[order] = np.cumsum(start) - 1
    first = np.flatnonzero(start)
    count = np.diff(np.append(first, len(sk)))
    E = np.stack([sk[first] // n, sk[first] % n], axis=1)
    twin = np.full(len(key), -1, np.int64)
    two = np.flatnonzero(count == 2)
    h1, h2 = order[first[two]], order[first[two] + 1]
    twin[h1], twin[h2] = h2, h1
    return E, FE.reshape(-1, 3), count, twin, int((a[h1] == a[h2]).sum())


def _boundary_loops_ref(F, twin):
    bh = np.flatnonzero(twin < 0)
    a, b = F.ravel()[bh], np.roll(F, -1, axis=1).ravel()[bh]
    nxt = dict(zip(a.tolist(), b.tolist()))
    loops, seen = [], set()
    for s in a.tolist():
        if s in seen:
            continue
        loop, v = [s], nxt[s]
        seen.add(s)
        while v != s:
            loop.append(v)
            seen.add(v)
            v = nxt[v]
        loops.append(loop)
    return loops


def _group_argmax(groups, verts, dist):
    if len(groups) == 0:
        return np.empty(0, np.int64)
    order = np.lexsort((-dist[verts], groups))
    g = groups[order]
    first = np.r_[True, g[1:] != g[:-1]]
    best = verts[order][first]
    return best[dist[best] > 0]


def _candidates_ref(topo, label, dist, nseeds):
    """The numpy closed-ball check (candidates only), as before the compiled kernel."""
    n = topo.n
    lab = np.concatenate([label, nseeds + np.arange(topo.n_loops)])
    Fc, Ec, FEc = topo.Fc, topo.Ec, topo.FEc
    L, EL = lab[Fc], lab[Ec]
    nlab = nseeds + topo.n_loops
    cand = []
    same_e = EL[:, 0] == EL[:, 1]
    same_f = (L[:, 0] == L[:, 1]) & (L[:, 1] == L[:, 2])
    chi = (np.bincount(lab, minlength=nlab) - np.bincount(EL[same_e, 0], minlength=nlab)
           + np.bincount(L[same_f, 0], minlength=nlab))
    bad_r = np.flatnonzero(chi != 1)
    if len(bad_r):
        sel = np.flatnonzero(np.isin(label, bad_r))
        cand.append(_group_argmax(label[sel], sel, dist))
    cross = ~same_e
    ce = np.flatnonzero(cross)
    pkey = np.minimum(EL[ce, 0], EL[ce, 1]) * nlab + np.maximum(EL[ce, 0], EL[ce, 1])
    two = (~same_f) & ((L[:, 0] == L[:, 1]) | (L[:, 1] == L[:, 2]) | (L[:, 0] == L[:, 2]))
    fe = FEc[np.flatnonzero(two)]
    pair_edges = fe[cross[fe]].reshape(-1, 2)
    node_of = np.full(len(Ec), -1, np.int64)
    node_of[ce] = np.arange(len(ce))
    A = sp.coo_matrix((np.ones(len(pair_edges)), (node_of[pair_edges[:, 0]], node_of[pair_edges[:, 1]])),
                      shape=(len(ce), len(ce)))
    ncomp, comp = connected_components(A, directed=False)
    upair, pinv, n_e = unique_int(pkey, return_inverse=True, return_counts=True)
    n_f2 = np.bincount(pinv[node_of[pair_edges[:, 0]]], minlength=len(upair))
    comps = np.bincount(unique_int(pinv * (ncomp + 1) + comp) // (ncomp + 1), minlength=len(upair))
    bad_p = np.flatnonzero((n_e - n_f2 != 1) | (comps != 1))
    if len(bad_p):
        badmask = np.isin(pinv, bad_p)
        vv = Ec[ce[badmask]].ravel()
        g = np.repeat(pinv[badmask], 2)
        keep = vv < n
        cand.append(_group_argmax(g[keep], vv[keep], dist))
    f3 = np.flatnonzero((L[:, 0] != L[:, 1]) & (L[:, 1] != L[:, 2]) & (L[:, 0] != L[:, 2]))
    S = np.sort(L[f3], axis=1)
    _, tinv, tcnt = unique_int((S[:, 0] * nlab + S[:, 1]) * nlab + S[:, 2], return_inverse=True,
                               return_counts=True)
    bad_t = np.flatnonzero(tcnt != 1)
    if len(bad_t):
        badmask = np.isin(tinv, bad_t)
        vv = Fc[f3[badmask]].ravel()
        g = np.repeat(tinv[badmask], 3)
        keep = vv < n
        cand.append(_group_argmax(g[keep], vv[keep], dist))
    return bool(cand), unique_int(np.concatenate(cand)) if cand else np.empty(0, np.int64)


def _grid(k: int = 40):
    """A regular k x k grid of unit squares, two triangles each: many exact distance ties."""
    x, y = np.meshgrid(np.arange(k, dtype=float), np.arange(k, dtype=float))
    V = np.c_[x.ravel(), y.ravel(), np.zeros(k * k)]
    i = (np.arange(k - 1)[:, None] * k + np.arange(k - 1)[None, :]).ravel()
    F = np.vstack([np.c_[i, i + 1, i + k + 1], np.c_[i, i + k + 1, i + k]])
    return V, F


@pytest.fixture(scope="module", params=REAL + ["grid"], ids=[p.split("/")[-1] for p in REAL] + ["grid"])
def mesh(request):
    if request.param == "grid":
        return _grid()
    return read_mesh(data_file(request.param))


def _junk_meshes(count: int = 40):
    """Random face sets over few vertices: non-manifold edges, duplicates, pinches."""
    rng = np.random.default_rng(0)
    out = []
    for _ in range(count):
        nv = int(rng.integers(4, 20))
        F = rng.integers(0, nv, (int(rng.integers(1, 40)), 3))
        F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
        if len(F):
            out.append((np.zeros((nv, 3)), F))
    return out


# ----------------------------------------------------------------- connectivity
def test_halfedges_equal_the_sort_reference(mesh):
    V, F = mesh
    he = halfedges(F, len(V))
    E, FE, count, twin, mis = _halfedges_ref(F, len(V))
    assert np.array_equal(he.E, E) and np.array_equal(he.FE, FE) and np.array_equal(he.count, count)
    assert np.array_equal(he.twin, twin) and he.misoriented == mis


def test_halfedges_on_non_manifold_junk_and_a_high_degree_vertex():
    k = 100  # a fan of 100 triangles: vertex 0 has a bucket above the insertion-sort size
    cone = (np.zeros((k + 1, 3)), np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)]))
    for V, F in _junk_meshes() + [cone]:
        he = halfedges(F, len(V))
        ref = _halfedges_ref(F, len(V))
        assert all(np.array_equal(a, b) for a, b in zip((he.E, he.FE, he.count, he.twin), ref[:4]))
        assert he.misoriented == ref[4]


def test_pinched_vertices_components_and_loops(mesh):
    V, F = mesh
    n = len(V)
    he = halfedges(F, n)
    assert count_pinched_vertices(F, he, n) == int((vertex_fan_count(F, he, n) > 1).sum()) == 0
    A = sp.coo_matrix((np.ones(len(he.E)), (he.E[:, 0], he.E[:, 1])), shape=(n, n))
    assert count_components(he.E, n) == connected_components(A, directed=False)[0]
    assert [lp.tolist() for lp in boundary_loops(F, he)] == _boundary_loops_ref(F, he.twin)


@pytest.mark.parametrize("make", [_bowtie, _double_cone], ids=["bowtie", "double-cone"])
def test_pinched_vertex_found(make):
    V, F = make()
    he = halfedges(F, len(V))
    assert count_pinched_vertices(F, he, len(V)) == int((vertex_fan_count(F, he, len(V)) > 1).sum()) == 1


def test_vertex_normals_match_libigl(mesh):
    import igl
    V, F = mesh
    assert np.abs(vertex_normals(V, F) - igl.per_vertex_normals(V, F)).max() < 1e-12


# ----------------------------------------------------------------- validation
@pytest.mark.parametrize("name", sorted(set(BAD_MESHES) | set(KNOWN_BAD_MESH_BUGS)))
def test_fast_validation_flags_every_bad_mesh(name):
    V, F, _ = {**BAD_MESHES, **KNOWN_BAD_MESH_BUGS}[name]
    try:
        V = np.ascontiguousarray(V, np.float64)
        F = np.asarray(F)
    except ValueError:
        pytest.skip("rejected before the fast checks (ragged)")
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(V) < 3 or F.dtype.kind == "f":
        pytest.skip("rejected before the fast checks (shape/dtype)")
    assert _fast_checks(V, np.ascontiguousarray(F, np.int64), True, 1e-14) is None


def test_fast_validation_passes_good_meshes_with_their_halfedges(mesh):
    V, F = mesh
    V2, F2, he = validate_mesh(V, F, return_halfedges=True)
    ref = _halfedges_ref(F2, len(V2))
    assert all(np.array_equal(a, b) for a, b in zip((he.E, he.FE, he.count, he.twin), ref[:4]))
    assert _fast_checks(V2, F2, True, 1e-14) is not None


def test_a_small_mesh_takes_the_reference_checks_alone_while_deferred_with_the_same_halfedges(mesh, monkeypatch):
    import sshade.mesh.halfedge as hmod
    import sshade.mesh.validate as val
    V, F = mesh
    calls = []
    real = val._fast_checks
    monkeypatch.setattr(val, "_fast_checks", lambda *a: calls.append(1) or real(*a))
    monkeypatch.setattr(hmod, "_DEFERRED", [True])
    monkeypatch.setattr(hmod, "KERNEL_MIN_FACES", len(F) + 1)
    small = validate_mesh(V, F, return_halfedges=True)
    monkeypatch.setattr(hmod, "KERNEL_MIN_FACES", len(F))
    large = validate_mesh(V, F, return_halfedges=True)
    assert calls == [1]  # the compiled checks ran for the large one only
    assert all(np.array_equal(a, b) for a, b in zip(small[:2], large[:2]))
    a, b = small[2], large[2]
    assert all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("E", "FE", "count", "twin"))
    assert a.misoriented == b.misoriented == 0


def test_fast_validation_on_junk_agrees_with_reference():
    from sshade.errors import SShaDeError
    for V, F in _junk_meshes():
        V = np.random.default_rng(len(F)).normal(size=V.shape)
        try:
            validate_mesh(V, F)
            ok = True
        except SShaDeError:
            ok = False
        assert ok == (_fast_checks(V, np.ascontiguousarray(F, np.int64), True, 1e-14) is not None)


# ----------------------------------------------------------------- sampling
def _edge_graph_ref(V, F):
    n = len(V)
    a, b = F.ravel(), np.roll(F, -1, axis=1).ravel()
    key = np.unique(np.concatenate([a * n + b, b * n + a]))
    rows, cols = key // n, key % n
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    return indptr, cols.astype(np.int32), np.sqrt(((V[rows] - V[cols]) ** 2).sum(1)).astype(np.float32)


def test_edge_graph_equals_reference(mesh):
    V, F = mesh
    assert all(np.array_equal(a, b) for a, b in zip(edge_graph(V, F), _edge_graph_ref(V, F)))


def test_sampling_independent_of_vertex_order_and_queue(mesh):
    """Same seeds, distances and labels in mesh order or locality order, with Dial's
    buckets or the binary heap; on the grid, exact ties go to the smallest index."""
    V, F = mesh
    k = min(300, len(V) // 5)
    order = locality_order(V)
    graph = edge_graph_from_edges(V, halfedges(F, len(V)).E, order)
    runs = []
    for g, o in ((None, None), (graph, order)):
        for q in ("heap", "auto"):
            st = VoronoiState(V, F, graph=g, order=o, queue=q)
            st.sample(k, first=len(V) // 3)
            st.add([0, 1, 2])
            runs.append((st.seeds.copy(), st.dist.copy(), st.label.copy()))
    for r in runs[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(runs[0], r))
    st = VoronoiState(V, F)
    assert len(st._head) > 0  # these meshes use Dial's buckets by default


def test_dial_ring_rule_follows_the_mean_edge():
    """Dial's ring is chosen from the mean edge against the shortest (not the
    longest one: an outlier on LS3 meshes would send 1M-vertex TOSCA meshes to the slower
    heap), and never longer than DIAL_MAX_BUCKETS; a heap for bad lengths."""
    from sshade.mesh.geodesic import DIAL_MAX_BUCKETS, DIAL_MAX_RATIO, _dial_ring
    w = np.ones(10_000)
    w[0] = 3000.0  # longest / shortest 3000 > DIAL_MAX_RATIO, mean / shortest ~1.3
    head, inv = _dial_ring(w)
    assert len(head) >= 3000 / 0.99 + 2 and inv == pytest.approx(1 / 0.99)
    w[0] = DIAL_MAX_BUCKETS * 2.0  # ring too long
    assert len(_dial_ring(w)[0]) == 0
    w = np.full(100, 2 * DIAL_MAX_RATIO)
    w[0] = 1.0  # mean / shortest above the ratio
    assert len(_dial_ring(w)[0]) == 0
    for bad in ([0.0, 1.0], [1.0, np.inf], [1.0, np.nan], []):
        assert len(_dial_ring(np.asarray(bad, float))[0]) == 0
    assert len(_dial_ring(np.ones(5), 0.0)[0]) == 0  # queue="heap"


def test_stretched_mesh_same_sampling_with_ring_and_heap():
    """A grid with one row of very thin triangles (longest / shortest edge > 1024, the
    old threshold): the ring is used, and gives the heap's seeds, distances and labels."""
    V, F = _grid(40)
    V = V.copy()
    V[V[:, 1] > V[:, 1].min() + 1e-9, 1] += 2000.0 * np.ptp(V[:, 0]) / 39  # stretch the first row
    g = edge_graph(V, F)
    assert g[2].max() / g[2].min() > 1024
    runs = []
    for q in ("heap", "auto"):
        st = VoronoiState(V, F, queue=q)
        st.sample(150, first=7)
        runs.append((st.seeds.copy(), st.dist.copy(), st.label.copy(), len(st._head)))
    assert runs[0][3] == 0 and runs[1][3] > 0
    assert all(np.array_equal(a, b) for a, b in zip(runs[0][:3], runs[1][:3]))


def test_farthest_point_ties_go_to_smallest_index():
    V, F = _grid(9)  # diagonals run from corner 0 to corner 80
    st = VoronoiState(V, F)
    st.sample(1, first=40)  # the centre: corners 8 and 72 are the farthest, exactly tied
    d = st.dist
    assert d[8] == d[72] == d.max() and d[0] < d[8]
    st.sample(2, first=40)
    assert st.seeds.tolist() == [40, 8]


@pytest.mark.parametrize("rel,k", [("classic/armadillo.obj", 40), ("tosca/cat0.off", 60),
                                   ("faust_reg/tr_reg_000.ply", 300)])
def test_closed_ball_candidates_equal_numpy_reference(rel, k):
    """Every check-and-repair round of a coarse remesh (many failing regions, pairs and
    triples): the compiled check picks the same candidates as the numpy one."""
    V, F = read_mesh(data_file(rel))
    topo = mesh_topology(V, F)
    st = VoronoiState(V, F, graph=topo.graph, order=topo.order)
    st.sample(k, first=7)
    rounds = 0
    for rounds in range(1, 60):  # noqa: B007 -- read after the loop
        label, dist, seeds = st.label, st.dist, st.seeds
        new, FN, _ = _check(topo, label, dist, st.nseeds, V, seeds, False)
        bad, ref = _candidates_ref(topo, label, dist, st.nseeds)
        assert np.array_equal(new, ref) and (FN is None) == bad
        lab = np.concatenate([label, st.nseeds + np.arange(topo.n_loops, dtype=label.dtype)])
        nlab = st.nseeds + topo.n_loops
        holds, f3 = _closed_ball_holds(topo.Fc, topo.FEc, lab, nlab, len(topo.Ec))
        full = _closed_ball_full(topo.Fc, topo.Ec, topo.FEc, lab, dist, topo.n, nlab)
        assert holds == (not bad) == (not full[0])
        if holds:
            assert np.array_equal(f3, full[2])
        if not len(new):
            break
        st.add(new)
    assert rounds > 1 and FN is not None


@pytest.mark.parametrize("rel,k", [("classic/armadillo.obj", 40), ("tosca/cat0.off", 60),
                                   ("faust_reg/tr_reg_000.ply", 300)])
def test_local_check_equals_the_full_check(rel, k):
    """In every round of a coarse remesh, the check restricted to the regions
    whose vertices changed label (and the pairs and triples involving them) finds the
    same repair candidates as the full check, and over all regions the same verdict,
    candidates and single-face triples."""
    V, F = read_mesh(data_file(rel))
    topo = mesh_topology(V, F)
    st = VoronoiState(V, F, graph=topo.graph, order=topo.order)
    st.sample(k, first=7)
    before, rounds, local_rounds = None, 0, 0
    for rounds in range(1, 60):  # noqa: B007 -- read after the loop
        label, dist = st.label, st.dist
        nlab = st.nseeds + topo.n_loops
        lab = np.concatenate([label, st.nseeds + np.arange(topo.n_loops, dtype=label.dtype)])
        bad, cand, f3 = _closed_ball_full(topo.Fc, topo.Ec, topo.FEc, lab, dist, topo.n, nlab)
        args = (topo.Fc, topo.Ec, topo.FEc, topo.vf_ptr, topo.vf_idx, lab, dist, topo.n, nlab)
        bad_all, cand_all, f3u = closed_ball_local(*args, np.ones(nlab, np.bool_))  # cone regions: left out
        assert bad_all == bad and np.array_equal(cand_all, cand)
        S = np.sort(lab[topo.Fc[f3]], axis=1)
        _, inv, cnt = unique_int((S[:, 0] * nlab + S[:, 1]) * nlab + S[:, 2], return_inverse=True,
                                 return_counts=True)
        assert np.array_equal(f3u, f3[cnt[inv] == 1])
        if before is not None:
            changed = label != before
            in_a = np.zeros(nlab, np.bool_)
            in_a[before[changed]] = in_a[label[changed]] = True
            assert in_a.sum() < nlab
            _, cand_local, _ = closed_ball_local(*args, in_a)
            assert np.array_equal(cand_local, cand)
            local_rounds += 1
        if not len(cand):
            break
        before = label
        st.add(cand)
    assert local_rounds >= 1 and not bad


def test_remesh_deterministic_with_shared_topology():
    V, F = read_mesh(data_file("faust_reg/tr_reg_000.ply"))
    topo = mesh_topology(V, F)
    a = remesh(V, F, 500, seed=4, topology=topo)
    b = remesh(V, F, 500, seed=4)
    assert np.array_equal(a.seeds, b.seeds) and np.array_equal(a.F, b.F) and np.array_equal(a.label, b.label)


def _morton_order_ref(V):
    """The Z-order by definition: 10 bits per axis of the bounding box's largest side,
    bit b of axis k to bit 3b + k, one bit at a time; a stable sort (ties in index order)."""
    lo = V.min(0)
    ext = (V.max(0) - lo).max()
    s = 1023.0 / ext if ext > 0 else 0.0
    code = np.zeros(len(V), np.int64)
    for k in range(3):
        q = np.array([min(1023, max(0, int((x - lo[k]) * s))) for x in V[:, k]], np.int64)
        for b in range(10):
            code |= ((q >> b) & 1) << (3 * b + k)
    return np.argsort(code, kind="stable")


@pytest.mark.parametrize("case", ["random", "ties", "flat", "one"])
def test_locality_order_is_the_stable_morton_order(case):
    rng = np.random.default_rng(3)
    V = {"random": rng.standard_normal((5000, 3)) * [1.0, 3.0, 0.2],
         "ties": np.repeat(rng.integers(0, 4, (300, 3)).astype(float), 3, axis=0),
         "flat": np.zeros((7, 3)), "one": np.ones((1, 3))}[case]
    order = locality_order(V)
    assert order.dtype == np.int64
    assert np.array_equal(order, _morton_order_ref(V))

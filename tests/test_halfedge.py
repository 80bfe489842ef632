"""sshade.mesh.halfedge: the edge table against a NumPy construction, low- and high-degree
vertices alike (the kernel sorts buckets of more than 32 half-edges another way), on both
paths (the kernels, and the NumPy/SciPy twins a mesh under KERNEL_MIN_FACES faces takes while
the kernels are deferred); the twins give the kernels' integers and floats bit for bit."""
import numpy as np
import pytest

from sshade.mesh import halfedge as hmod
from sshade.mesh.halfedge import (
    count_components,
    count_pinched_vertices,
    defer_kernels,
    halfedges,
    large_mesh,
    takes_kernels,
    tetrahedron,
    vertex_fan_count,
    vertex_normals,
)
from sshade.mesh.io import read_mesh

from .conftest import SHARED_DATA


@pytest.fixture(autouse=True, params=["kernels", "numpy"])
def path(request, monkeypatch):
    """Every test here on both paths: every mesh takes the kernels, or none does."""
    monkeypatch.setattr(hmod, "_DEFERRED", [request.param == "numpy"])
    monkeypatch.setattr(hmod, "KERNEL_MIN_FACES", 0 if request.param == "kernels" else 10**12)
    return request.param


def _reference(F):
    """Edges as (lo, hi) in lexicographic order, each half-edge's edge, the counts, and the
    twins of two-face edges, from a stable NumPy sort (half-edge 3 f + k runs F[f, k] -> F[f, k+1])."""
    a, b = F.reshape(-1), np.roll(F, -1, axis=1).reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.lexsort((hi, lo))  # stable: equal edges keep half-edge order
    E, inv, count = np.unique(np.stack([lo, hi], 1), axis=0, return_inverse=True, return_counts=True)
    twin = np.full(len(a), -1)
    for e in np.flatnonzero(count == 2):
        h1, h2 = order[np.searchsorted(inv[order], e):][:2]
        twin[h1], twin[h2] = h2, h1
    return E, inv.reshape(-1, 3), count, twin


def _fan(k, close=True):
    """A fan of k triangles around vertex 0 (rim 1..k), closed into a disk when ``close``."""
    rim = np.arange(1, k + 1)
    nxt = np.roll(rim, -1) if close else rim + 1
    F = np.stack([np.zeros(k, np.int64), rim, nxt], 1)
    return (F if close else F[:-1]), k + 1


@pytest.mark.parametrize("k", [5, 33, 200, 1000])
def test_edge_table_matches_a_numpy_sort_around_a_vertex_of_degree_k(k):
    rng = np.random.default_rng(k)
    F, n = _fan(k)
    perm = rng.permutation(n)  # the high-degree vertex anywhere in the numbering
    F = perm[F][rng.permutation(len(F))]
    he = halfedges(F, n)
    E, FE, count, twin = _reference(F)
    assert np.array_equal(he.E, E) and np.array_equal(he.FE, FE)
    assert np.array_equal(he.count, count) and np.array_equal(he.twin, twin)
    assert he.misoriented == 0


def test_an_edge_run_the_same_way_by_both_faces_counts_as_misoriented():
    F = np.array([[0, 1, 2], [0, 1, 3]], np.int64)  # edge 0 -> 1 in both
    he = halfedges(F, 4)
    assert he.misoriented == 1
    assert he.twin[0] == 3 and he.twin[3] == 0


def test_an_edge_on_three_faces_has_no_twin_and_count_three():
    F = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]], np.int64)
    he = halfedges(F, 5)
    e01 = int(np.flatnonzero((he.E == [0, 1]).all(1))[0])
    assert he.count[e01] == 3
    assert (he.twin[[0, 3, 6]] == -1).all()


def _odd_meshes():
    """Meshes whose connectivity is not a closed manifold's: random faces over few vertices
    (edges of three or more faces, duplicates, both orientations, pinches, several
    components), a misoriented pair, a bow tie, an open fan of high degree and an empty set."""
    rng = np.random.default_rng(7)
    out = []
    for _ in range(60):
        nv = int(rng.integers(4, 25))
        F = rng.integers(0, nv, (int(rng.integers(1, 60)), 3))
        F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
        out.append((rng.normal(size=(nv, 3)), F))
    out.append((rng.normal(size=(4, 3)), np.array([[0, 1, 2], [0, 1, 3]])))
    out.append((rng.normal(size=(5, 3)), np.array([[0, 1, 2], [0, 3, 4]])))
    F, n = _fan(300, close=False)
    out.append((rng.normal(size=(n, 3)), F))
    out.append((rng.normal(size=(3, 3)), np.zeros((0, 3), np.int64)))
    return out


def _real_meshes():
    out = []
    for rel in ("classic/bunny.off", "faust_reg/tr_reg_000.ply"):
        if (SHARED_DATA / rel).exists():
            out.append(read_mesh(SHARED_DATA / rel))
    return out


def _all_outputs(V, F):
    n = len(V)
    he = halfedges(F, n)
    out = [he.E, he.FE, he.count, he.twin, np.array(he.misoriented), vertex_fan_count(F, he, n),
           np.array(count_components(he.E, n)), vertex_normals(V, F)]
    if he.misoriented == 0 and (he.count <= 2).all():  # count_pinched_vertices' domain
        out.append(np.array(count_pinched_vertices(F, he, n)))
    return out


def test_the_numpy_paths_give_the_kernels_integers_and_floats_bit_for_bit(monkeypatch):
    monkeypatch.setattr(hmod, "KERNEL_MIN_FACES", 10**12)
    for V, F in _odd_meshes() + _real_meshes():
        F = np.ascontiguousarray(F, np.int64)
        defer_kernels(False)
        kern = _all_outputs(V, F)
        defer_kernels(True)
        twin = _all_outputs(V, F)
        for a, b in zip(kern, twin):
            assert a.dtype == b.dtype and a.shape == b.shape
            assert a.tobytes() == b.tobytes()  # the same bits (normals: the same sums in the same order)


def test_only_a_small_mesh_takes_the_numpy_paths_and_only_while_the_kernels_are_deferred(monkeypatch):
    V, F = _real_meshes()[0] if _real_meshes() else (np.zeros((4, 3)), np.array([[0, 2, 1], [0, 1, 3]]))
    calls = []
    real = hmod._halfedges_numpy
    monkeypatch.setattr(hmod, "_halfedges_numpy", lambda *a: calls.append(1) or real(*a))
    for deferred, limit, numpy_path in ((True, len(F) + 1, True), (True, len(F), False), (False, len(F) + 1, False)):
        defer_kernels(deferred)
        monkeypatch.setattr(hmod, "KERNEL_MIN_FACES", limit)
        assert large_mesh(F) == (limit <= len(F)) and takes_kernels(F) != numpy_path
        calls.clear()
        halfedges(F, len(V))
        assert calls == ([1] if numpy_path else [])
    assert not large_mesh(object())  # no length: small (checked, and refused, later)


def test_the_warm_up_tetrahedron_is_closed_consistently_oriented_and_outward():
    V, F = tetrahedron()
    he = halfedges(F, 4)
    assert (he.twin >= 0).all() and (he.count == 2).all() and he.misoriented == 0
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    assert np.einsum("ij,ij->", a, np.cross(b, c)) / 6 == pytest.approx(1 / 6)

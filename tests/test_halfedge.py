"""sshade.mesh.halfedge: the edge table against a NumPy construction, low- and high-degree
vertices alike (the kernel sorts buckets of more than 32 half-edges another way)."""
import numpy as np
import pytest

from sshade.mesh.halfedge import halfedges


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

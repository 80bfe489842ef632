"""defaust.self_intersections: the faces that cross another, by exact-sign tests."""
from __future__ import annotations

import numpy as np
import pytest

from defaust.self_intersections import self_intersections
from sshade.errors import SShaDeError


def _sphere(center=(0.0, 0.0, 0.0), r=1.0, subdivisions=3):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=r)
    return np.asarray(m.vertices) + np.asarray(center), np.asarray(m.faces, np.int64)


def _two(a, b):
    (Va, Fa), (Vb, Fb) = a, b
    return np.vstack([Va, Vb]), np.vstack([Fa, Fb + len(Va)])


def test_a_closed_sphere_and_two_apart_have_no_crossing():
    assert self_intersections(*_sphere()).size == 0
    assert self_intersections(*_two(_sphere(), _sphere((2.5, 0, 0)))).size == 0


def test_two_interpenetrating_spheres_cross_exactly_along_their_common_circle():
    """Every flagged face reaches the other sphere's surface (a vertex on each side of it,
    or within its extent), each sphere has flagged faces, and the set is the same whichever
    sphere comes first."""
    a, b = _sphere(), _sphere((1.0, 0.2, 0.1))
    V, F = _two(a, b)
    got = self_intersections(V, F)
    na = len(a[1])
    assert (got < na).any() and (got >= na).any()
    dist = np.linalg.norm(V[F[got]] - np.where((got < na)[:, None, None], [1.0, 0.2, 0.1], 0.0), axis=2)
    assert ((dist.min(1) <= 1.0 + 1e-12) & (dist.max(1) >= 1.0 - 0.1)).all()  # near the other sphere
    nb = len(b[1])
    swapped = self_intersections(*_two(b, a))  # b's faces first: index k of b is k + na in (a, b)
    assert np.array_equal(np.sort(np.where(swapped < nb, swapped + na, swapped - nb)), got)


def test_faces_sharing_an_edge_never_cross_and_a_fold_at_a_shared_vertex_does():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, -1], [0.2, 0.2, 1.0]])
    assert self_intersections(V, np.array([[0, 1, 2], [0, 1, 3]])).size == 0  # an edge: neighbours
    # shares vertex 0; its edge 3-4 pierces triangle 0-1-2 at (0.2, 0.2, 0)
    assert self_intersections(V, np.array([[0, 1, 2], [0, 3, 4]])).tolist() == [0, 1]
    assert self_intersections(V, np.array([[0, 1, 2], [1, 3, 4]])).tolist() == [0, 1]
    V[3:, :2] = -0.2  # turned away: the faces meet at vertex 0 only
    assert self_intersections(V, np.array([[0, 1, 2], [0, 3, 4]])).size == 0


def test_a_touch_is_no_crossing():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 0], [2, 2, 1], [2, 3, 1]])
    assert self_intersections(V, np.array([[0, 1, 2], [3, 4, 5]])).size == 0  # a vertex on the face


def test_the_answer_does_not_depend_on_what_pymeshlab_did_before():
    """pymeshlab's own test answered 30 then 31 for one mesh in one process, after other
    pymeshlab calls: this one gives the same faces before and after."""
    pymeshlab = pytest.importorskip("pymeshlab")
    V, F = _two(_sphere(), _sphere((1.0, 0.2, 0.1)))
    before = self_intersections(V, F)
    for _ in range(3):
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(V, F.astype(np.int32)))
        ms.meshing_surface_subdivision_ls3_loop(loopweight="Loop", iterations=1,
                                                threshold=pymeshlab.PercentageValue(0))
        ms.compute_selection_by_self_intersections_per_face()
    assert np.array_equal(self_intersections(V, F), before)


def test_open3d_agrees_on_crossings_between_faces_sharing_no_vertex():
    """Open3D's ``get_self_intersecting_triangles`` (pairs sharing no vertex) finds the
    same faces on two interpenetrating spheres (no shared vertex between them)."""
    try:
        import open3d as o3d
    except Exception as e:  # noqa: BLE001 - its wheel may fail on a missing system library
        pytest.skip(f"open3d not importable: {type(e).__name__}")
    V, F = _two(_sphere(), _sphere((1.0, 0.2, 0.1)))
    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(F.astype(np.int32)))
    theirs = np.unique(np.asarray(m.get_self_intersecting_triangles()))
    assert np.array_equal(self_intersections(V, F), theirs)


@pytest.mark.parametrize("V, F, word", [
    (np.zeros((3, 2)), np.array([[0, 1, 2]]), "need V"),
    (np.zeros((3, 3)), np.array([[0, 1, 3]]), "outside"),
    (np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), np.array([[0, 1, 2]]), "not finite"),
])
def test_bad_input_is_refused_naming_it(V, F, word):
    with pytest.raises(SShaDeError, match=word):
        self_intersections(V, F)


def test_the_grid_finds_every_crossing_pair_with_faces_of_very_different_sizes():
    """Small and large triangles mixed (large boxes span many cells of the grid, whose
    cells are twice the median box), and a far cluster: the same faces as testing every
    pair of faces on its own (a two-face mesh holds one pair)."""
    rng = np.random.default_rng(7)
    V = np.vstack([rng.random((90, 3)), rng.random((6, 3)) * 0.01 + 50.0])
    small = rng.integers(0, 88, (50, 1)) + np.array([[0, 1, 2]])  # three consecutive vertices of the 90, made near
    V[small[:, 1]] = V[small[:, 0]] + rng.normal(0, 0.02, (50, 3))
    V[small[:, 2]] = V[small[:, 0]] + rng.normal(0, 0.02, (50, 3))
    large = rng.integers(0, 90, (12, 3))
    F = np.vstack([small, large, [[90, 91, 92], [93, 94, 95], [90, 93, 94]]])
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    pairs = set()
    for i in range(len(F)):
        for j in range(i + 1, len(F)):
            if self_intersections(V, F[[i, j]]).size:
                pairs.update((i, j))
    assert len(pairs) > 10
    np.testing.assert_array_equal(self_intersections(V, F), sorted(pairs))

"""Deformation metrics (eval/metrics/measures.py) against answers known by hand."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from eval.metrics import measures as M
from sshade.errors import SShaDeError
from sshade.guard import handle_error
from tests.conftest import data_file

# closed unit cube, 12 outward-oriented triangles
CUBE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                   [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
CUBE_F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                   [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])

TRI_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
TRI_F = np.array([[0, 1, 2]])


def _square(z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    V = np.array([[0, 0, z], [1, 0, z], [1, 1, z], [0, 1, z]], float)
    return V, np.array([[0, 1, 2], [0, 2, 3]])


def _rotation(seed: int = 0) -> np.ndarray:
    Q, R = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def _sphere():
    m = trimesh.creation.icosphere(subdivisions=3)
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


# ----------------------------------------------------------------------------- volume / area
def test_cube_volume_and_area():
    assert M.volume(CUBE_V, CUBE_F) == pytest.approx(1.0, abs=1e-14)
    assert M.surface_area(CUBE_V, CUBE_F) == pytest.approx(6.0, abs=1e-14)


def test_volume_is_signed_and_translation_invariant():
    assert M.volume(CUBE_V, CUBE_F[:, ::-1]) == pytest.approx(-1.0, abs=1e-14)
    assert M.volume(CUBE_V + [100.0, -50.0, 7.0], CUBE_F) == pytest.approx(1.0, rel=1e-12)


def test_tetrahedron_volume():
    V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    assert M.volume(V, F) == pytest.approx(1 / 6, abs=1e-15)
    assert M.surface_area(V, F) == pytest.approx(1.5 + np.sqrt(3) / 2, abs=1e-14)


def test_scaled_cube_errors():
    Vd = 2.0 * CUBE_V
    assert M.area_error(CUBE_V, Vd, CUBE_F) == pytest.approx(300.0, abs=1e-10)
    assert M.volume_error(CUBE_V, Vd, CUBE_F) == pytest.approx(700.0, abs=1e-10)
    # 12 cube edges of length 1 and 6 face diagonals of length sqrt 2; each doubles,
    # so |l - 2l| = l and the error is 100 * mean(l) / max(l)
    mean_l = (12 * 1.0 + 6 * np.sqrt(2)) / 18
    expected = 100.0 * mean_l / np.sqrt(2)
    assert M.edge_length_error(CUBE_V, Vd, CUBE_F) == pytest.approx(expected, abs=1e-10)


def test_shrunk_volume_error():
    # scale 0.5 -> volume 1/8, error 87.5 %
    assert M.volume_error(CUBE_V, 0.5 * CUBE_V, CUBE_F) == pytest.approx(87.5, abs=1e-10)


def test_edge_error_counts_each_undirected_edge_once():
    # stretch only vertex 2 of the two-triangle square along x: edges (1,2), (2,3), (0,2)
    V, F = _square()
    Vd = V.copy()
    Vd[2, 0] += 0.5  # vertex 2: (1,1) -> (1.5,1)
    l0 = np.array([1, 1, 1, 1, np.sqrt(2)])                       # 01 12 23 30 02
    l1 = np.array([1, np.hypot(.5, 1), 1.5, 1, np.hypot(1.5, 1)])
    expected = 100 * np.mean(np.abs(l0 - l1)) / np.sqrt(2)
    assert M.edge_length_error(V, Vd, F) == pytest.approx(expected, abs=1e-12)


# ----------------------------------------------------------------------------- rigid motion
@pytest.mark.parametrize("mesh", ["cube", "sphere"])
def test_rigid_motion_gives_zero_errors(mesh):
    V, F = (CUBE_V, CUBE_F) if mesh == "cube" else _sphere()
    Vd = V @ _rotation(1).T + np.array([3.0, -2.0, 0.5])
    d = M.deformation_metrics(V, Vd, F)
    assert set(d) == {"volume_err_pct", "area_err_pct", "edge_err_pct", "angle_err_deg", "angle_err_rel_pct"}
    for k, v in d.items():
        assert abs(v) < 1e-10, (k, v)


# ----------------------------------------------------------------------------- angles
def test_uniform_scale_keeps_angles():
    V, F = _sphere()
    deg, rel = M.face_angle_error(V, 3.7 * V + 1.0, F)
    assert deg < 1e-10 and rel < 1e-10


def test_shear_angle_error_by_hand():
    # x += y on the right triangle: corners 90/45/45 deg -> 45/90/45 deg
    Vd = TRI_V.copy()
    Vd[:, 0] += Vd[:, 1]
    deg, rel = M.face_angle_error(TRI_V, Vd, TRI_F)
    assert deg == pytest.approx((45 + 45 + 0) / 3, abs=1e-12)
    assert rel == pytest.approx(100 * (45 / 90 + 45 / 45 + 0) / 3, abs=1e-12)


def test_angle_error_degenerate_rest_face_raises():
    V = np.array([[0., 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(SShaDeError, match="degenerate"):
        M.face_angle_error(V, V, TRI_F)


# ----------------------------------------------------------------------------- handles
def test_handle_error_known_value():
    Vd = CUBE_V.copy()
    targets = Vd[[1, 3]] + np.array([[0, 0, 0.3], [0.4, 0, 0]])
    assert handle_error(Vd, [1, 3], targets, 2.0) == pytest.approx(100 * 0.4 / 2.0, abs=1e-12)
    d = M.deformation_metrics(CUBE_V, Vd, CUBE_F, [1, 3], targets)
    assert d["handle_err_pct"] == pytest.approx(100 * 0.4 / np.sqrt(3), abs=1e-12)


@pytest.mark.parametrize("handles,targets,diag,word", [
    ([8], np.zeros((1, 3)), 1.0, "out of range"),
    ([1, 1], np.zeros((2, 3)), 1.0, "duplicate"),
    ([1, 2], np.zeros((1, 3)), 1.0, "length"),
    ([1], [[np.nan, 0, 0]], 1.0, "NaN"),
    ([1], np.zeros((1, 3)), 0.0, "diag"),
    ([1], np.zeros((1, 3)), np.nan, "diag"),
])
def test_handle_error_bad_input(handles, targets, diag, word):
    with pytest.raises(SShaDeError, match=word):
        handle_error(CUBE_V, handles, targets, diag)


def test_deformation_metrics_needs_both_handles_and_targets():
    with pytest.raises(SShaDeError, match="both"):
        M.deformation_metrics(CUBE_V, CUBE_V, CUBE_F, handles=[0])


# ----------------------------------------------------------------------------- Hausdorff / Chamfer
def test_normalize_unit_sphere():
    V, _ = _sphere()
    X = 5.0 * V + [1.0, 2.0, 3.0]
    Xn, c, s = M.normalize_unit_sphere(X)
    np.testing.assert_allclose(c, [1, 2, 3], atol=1e-12)
    assert s == pytest.approx(5.0, rel=1e-12)
    assert np.linalg.norm(Xn, axis=1).max() == pytest.approx(1.0, abs=1e-12)
    # with a reference the reference's transform is applied
    Yn, c2, s2 = M.normalize_unit_sphere(2 * X, ref=X)
    np.testing.assert_allclose(c2, c)
    assert s2 == s
    np.testing.assert_allclose(Yn, (2 * X - c) / s)


def test_point_surface_distance():
    V, F = _square()
    P = np.array([[0.5, 0.5, 2.0], [2.0, 0.5, 0.0], [0.25, 0.75, -0.5]])
    np.testing.assert_allclose(M.point_surface_distance(P, V, F), [2.0, 1.0, 0.5], atol=1e-12)


@pytest.mark.parametrize("normalize", [True, False])
def test_distances_of_a_mesh_to_itself_are_zero(normalize):
    V, F = _sphere()
    assert M.hausdorff(V, F, V, F, normalize=normalize) < 1e-12
    assert M.chamfer(V, F, V, F, normalize=normalize) < 1e-20


@pytest.mark.parametrize("d", [0.1, 0.37, 2.0])
def test_parallel_squares_offset(d):
    VX, F = _square(d)
    VY, _ = _square(0.0)
    assert M.hausdorff(VX, F, VY, F, normalize=False) == pytest.approx(d, abs=1e-12)
    assert M.chamfer(VX, F, VY, F, normalize=False) == pytest.approx(2 * d * d, abs=1e-12)


def test_normalization_uses_the_reference_and_does_not_hide_scaling():
    V, F = _sphere()
    r = np.linalg.norm(V, axis=1).max()
    # X = 2 Y: in Y's normalisation the sphere of radius 2 is 1 away from the unit one
    h = M.hausdorff(2 * V, F, V, F, normalize=True)
    assert h == pytest.approx(1.0, abs=0.02)
    # the metric is scale invariant when both shapes are scaled together
    h1 = M.hausdorff(V + [0, 0, 0.1], F, V, F, normalize=True)
    h10 = M.hausdorff(10 * (V + [0, 0, 0.1]), F, 10 * V, F, normalize=True)
    assert h1 == pytest.approx(h10, rel=1e-9)
    assert h1 == pytest.approx(M.hausdorff(V + [0, 0, 0.1], F, V, F, normalize=False) / r, rel=1e-9)


def test_ground_truth_metrics():
    V, F = _sphere()
    t = np.array([0.0, 0.0, 0.05])
    g = M.ground_truth_metrics(V + t, F, V)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert g["gt_vertex_mean_pct"] == pytest.approx(100 * 0.05 / diag, rel=1e-12)
    assert g["gt_vertex_max_pct"] == pytest.approx(100 * 0.05 / diag, rel=1e-12)
    assert 0 < g["hausdorff"] <= 0.05 + 1e-12
    assert 0 < g["chamfer"] <= 2 * 0.05 ** 2
    z = M.ground_truth_metrics(V, F, V)
    assert all(abs(v) < 1e-12 for v in z.values())


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("fn", [M.volume_error, M.area_error, M.edge_length_error,
                                M.face_angle_error, M.deformation_metrics])
def test_mismatched_vertex_arrays(fn):
    with pytest.raises(SShaDeError, match="differ in shape"):
        fn(CUBE_V, CUBE_V[:-1], CUBE_F)


@pytest.mark.parametrize("fn", [M.volume_error, M.area_error, M.edge_length_error,
                                M.face_angle_error, M.deformation_metrics])
def test_nan_deformed_vertices(fn):
    Vd = CUBE_V.copy()
    Vd[3, 1] = np.nan
    with pytest.raises(SShaDeError, match="NaN"):
        fn(CUBE_V, Vd, CUBE_F)


@pytest.mark.parametrize("V,F,word", [
    (CUBE_V[:, :2], CUBE_F, "shape"),
    (CUBE_V, CUBE_F[:, :2], "triangles"),
    (CUBE_V, CUBE_F + 1, "out of range"),
    (CUBE_V, CUBE_F - 1, "out of range"),
    (np.full((8, 3), np.inf), CUBE_F, "NaN/inf"),
    (CUBE_V, CUBE_F + 0.5, "not integers"),
])
def test_bad_mesh_arrays(V, F, word):
    for fn in (M.volume, M.surface_area):
        with pytest.raises(SShaDeError, match=word):
            fn(V, F)
    with pytest.raises(SShaDeError, match=word):
        M.hausdorff(V, F, CUBE_V, CUBE_F)


def test_zero_rest_volume_raises():
    V, F = _square()
    with pytest.raises(SShaDeError, match="volume"):
        M.volume_error(V, V, F)


def test_ground_truth_shape_mismatch():
    with pytest.raises(SShaDeError, match="ground truth"):
        M.ground_truth_metrics(CUBE_V, CUBE_F, CUBE_V[:-1])


# ----------------------------------------------------------------------------- real mesh
def test_bunny_volume_matches_trimesh():
    from sshade.mesh.io import read_mesh
    V, F = read_mesh(data_file("classic/bunny.off"))
    vol = M.volume(V, F)
    ref = trimesh.Trimesh(V, F, process=False).volume
    assert vol > 0
    assert vol == pytest.approx(ref, rel=1e-9)
    assert M.surface_area(V, F) == pytest.approx(trimesh.Trimesh(V, F, process=False).area, rel=1e-12)

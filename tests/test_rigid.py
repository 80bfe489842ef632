"""The best rigid motion of corresponding points (sshade/arap/rigid.py): the Kabsch fit
for sets spanning a plane or more, the rotation nearest the identity for collinear and
coincident sets, and what that means for two-handle deformations of a real body."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from baselines import Elastic
from sshade import deform
from sshade.arap import rigid_fit
from sshade.mesh import read_mesh

from .conftest import data_file


def _angle(R: np.ndarray) -> float:
    """Rotation angle of R (3, 3) in radians."""
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _assert_rotation(R: np.ndarray) -> None:
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


def _plain_kabsch(P, Q):
    """The textbook Kabsch fit, as rigid_fit computed it for every set before degenerate
    sets got their own rule."""
    cp, cq = P.mean(0), Q.mean(0)
    U, _, Vt = np.linalg.svd((P - cp).T @ (Q - cq))
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, cq - R @ cp


def test_two_points_give_the_minimal_rotation_about_an_axis_perpendicular_to_both_directions():
    rng = np.random.default_rng(1)
    for _ in range(20):
        P = rng.normal(size=(2, 3))
        Q = rng.normal(size=(2, 3)) * rng.uniform(0.5, 2.0)  # not rigid: the distance changes
        R, t = rigid_fit(P, Q)
        _assert_rotation(R)
        a, b = _unit(P[1] - P[0]), _unit(Q[1] - Q[0])
        np.testing.assert_allclose(R @ a, b, atol=1e-12)  # the best fit turns the segment onto the target's
        axis = _unit(np.cross(a, b))
        np.testing.assert_allclose(R @ axis, axis, atol=1e-12)  # rotation axis perpendicular to both
        assert _angle(R) == pytest.approx(np.arccos(np.clip(a @ b, -1, 1)), abs=1e-12)
        np.testing.assert_allclose(t, Q.mean(0) - R @ P.mean(0), atol=1e-12)  # midpoints coincide
        # no rotation fits better (the objective depends on R only through R a . b)
        for Rr in Rotation.random(50, random_state=2).as_matrix():
            tr = Q.mean(0) - Rr @ P.mean(0)
            assert ((P @ R.T + t - Q) ** 2).sum() <= ((P @ Rr.T + tr - Q) ** 2).sum() + 1e-12


def test_two_points_moved_without_turning_give_the_identity_and_fit_the_translation():
    P = np.array([[0.2, -1.1, 0.2], [0.1, 0.6, 0.2]])
    for Q in (P + [0.3, -0.1, 0.05], P + 2.0 * (P[1] - P[0]), 1.5 * P):
        R, t = rigid_fit(P, Q)
        np.testing.assert_array_equal(R, np.eye(3))
        np.testing.assert_allclose(t, Q.mean(0) - P.mean(0), atol=1e-15)


def test_two_points_swapped_give_a_half_turn_about_a_perpendicular_axis():
    P = np.array([[0.0, 0.0, 0.0], [0.3, 1.0, 0.1]])
    R, t = rigid_fit(P, P[::-1])
    _assert_rotation(R)
    np.testing.assert_allclose(P @ R.T + t, P[::-1], atol=1e-12)
    assert _angle(R) == pytest.approx(np.pi, abs=1e-9)


def test_collinear_points_spun_about_their_line_give_the_rotation_nearest_identity():
    rng = np.random.default_rng(3)
    d = _unit(np.array([0.3, 1.0, -0.2]))
    P = np.array([0.5, -0.2, 0.1]) + np.outer(rng.uniform(-1, 1, 7), d)
    spin = Rotation.from_rotvec(2.0 * d).as_matrix()  # 115 degrees about the line itself
    turn = Rotation.from_rotvec([0.0, 0.0, 0.4]).as_matrix()
    Q = (P - P[0]) @ (turn @ spin).T + P[0] + [0.1, 0.2, -0.3]
    R, t = rigid_fit(P, Q)
    _assert_rotation(R)
    np.testing.assert_allclose(P @ R.T + t, Q, atol=1e-12)  # fits exactly
    axis = _unit(np.cross(d, turn @ d))
    minimal = Rotation.from_rotvec(axis * np.arccos(d @ (turn @ d))).as_matrix()
    np.testing.assert_allclose(R, minimal, atol=1e-12)
    np.testing.assert_allclose(R @ axis, axis, atol=1e-12)  # no spin about the line
    assert _angle(R) == pytest.approx(np.arccos(d @ (turn @ d)), abs=1e-12)
    assert _angle(R) <= _angle(turn) + 1e-12


def test_coincident_points_give_the_identity_whatever_the_rounding_of_their_mean():
    rng = np.random.default_rng(4)
    for n in range(2, 12):
        for p in ([0.1, 0.2, 0.3], [1 / 3, 2 / 7, 0.7]):  # means that round off the point for some n
            P, Q = np.tile(p, (n, 1)), rng.normal(size=(n, 3))
            for A, B in ((P, Q), (Q, P), (P, P + [0.3, 0.1, 0.7])):
                R, t = rigid_fit(A, B)
                np.testing.assert_array_equal(R, np.eye(3))
                np.testing.assert_allclose(t, B.mean(0) - A.mean(0), atol=1e-15)


def test_coplanar_non_collinear_set_reproduces_a_rigid_motion_to_1e_12():
    rng = np.random.default_rng(5)
    for k in range(10):
        P = np.c_[rng.normal(size=(3 + k, 2)), np.zeros(3 + k)] @ Rotation.random(random_state=k).as_matrix().T
        Rt = Rotation.random(random_state=100 + k).as_matrix()
        tt = rng.normal(size=3)
        R, t = rigid_fit(P, P @ Rt.T + tt)
        np.testing.assert_allclose(R, Rt, atol=1e-12)
        np.testing.assert_allclose(t, tt, atol=1e-12)


def test_generic_set_reproduces_a_rigid_motion_exactly_with_the_plain_kabsch_fit():
    rng = np.random.default_rng(6)
    for k in range(10):
        P = rng.normal(size=(4 + 3 * k, 3))
        Rt = Rotation.random(random_state=200 + k).as_matrix()
        tt = rng.normal(size=3)
        Q = P @ Rt.T + tt
        R, t = rigid_fit(P, Q)
        np.testing.assert_allclose(R, Rt, atol=1e-12)
        np.testing.assert_allclose(t, tt, atol=1e-12)
        R2, t2 = _plain_kabsch(P, Q)  # sets spanning 3-D (and noisy ones) keep the Kabsch fit bit for bit
        assert np.array_equal(R, R2) and np.array_equal(t, t2)
        Qn = Q + 0.05 * rng.normal(size=Q.shape)
        assert all(np.array_equal(x, y) for x, y in zip(rigid_fit(P, Qn), _plain_kabsch(P, Qn), strict=True))


@pytest.fixture(scope="module")
def faust_two_handles():
    """FAUST subject 0's rest pose with its lowest vertex pinned and its highest one moved
    5 cm sideways, along x and along z. Returns V, F, handles, [targets_x, targets_z]."""
    V, F = read_mesh(data_file("faust_reg/tr_reg_000.ply"))
    h = np.array([np.argmin(V[:, 1]), np.argmax(V[:, 1])])
    targets = []
    for axis in (0, 2):
        T = V[h].copy()
        T[1, axis] += 0.05
        targets.append(T)
    return V, F, h, targets


@pytest.mark.parametrize("method", ["sshade", "elastic"])
def test_faust_two_handles_moved_5cm_sideways_do_not_spin_the_body(faust_two_handles, method):
    V, F, h, targets = faust_two_handles
    for T in targets:
        if method == "sshade":
            Vd = deform(V, F, h, T, n_low=1000, n_samplings=2, workers=1)
        else:
            Vd = Elastic().deform(V, F, h, T)
        np.testing.assert_allclose(Vd[h], T, atol=1e-9)
        mean_disp = float(np.linalg.norm(Vd - V, axis=1).mean())
        assert mean_disp < 2 * 0.05, f"{method}: the body moved {mean_disp:.3f} m on average for a 5 cm handle move"

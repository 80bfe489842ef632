"""sshade/averaging.py: the samplings' averages: the weights' properties (positive,
summing to one, a low-res vertex taking its own sampling's value, a rigid motion
weighted as the rest) and the weighted sum against numpy."""
from __future__ import annotations

import numpy as np

from sshade.averaging import distortion_weights, normalize_weights, proximity_weights, weighted_sum
from sshade.sampling import average
from tests.test_lrf import _grid, _on_coarse, _rotation


def test_proximity_weights_are_the_inverse_second_moment_about_the_corners():
    rng = np.random.default_rng(0)
    VN, FN = _grid(4)
    V = rng.uniform(0, 1, size=(50, 3)) * [1, 1, 0.1]
    tri, bary = _on_coarse(V, VN, FN)
    q = np.array([sum(bary[i, k] * np.sum((V[i] - VN[FN[tri[i], k]]) ** 2) for k in range(3))
                  for i in range(len(V))])
    np.testing.assert_allclose(1.0 / proximity_weights(V, tri, bary, VN, FN), q, rtol=1e-9, atol=1e-11)


def test_at_a_low_res_vertex_its_sampling_decides_the_weighted_average():
    rng = np.random.default_rng(1)
    VN, FN = _grid(4)
    V = np.r_[VN[5:6], rng.uniform(0, 1, size=(10, 3)) * [1, 1, 0]]   # vertex 0 is low-res vertex 5
    tri, bary = _on_coarse(V, VN, FN)
    w_own = proximity_weights(V, tri, bary, VN, FN)
    VN2 = VN + [0.05, 0.07, 0.0]                                         # another sampling, shifted
    tri2, bary2 = _on_coarse(V, VN2, FN)
    w_other = proximity_weights(V, tri2, bary2, VN2, FN)
    X = [np.ones((len(V), 3)), np.zeros((len(V), 3))]
    out = weighted_sum(X, normalize_weights([w_own, w_other]))
    assert out[0, 0] > 1 - 1e-6 and np.isfinite(out).all()


def test_normalized_weights_sum_to_one_and_equal_weights_give_the_mean():
    rng = np.random.default_rng(2)
    W = [rng.uniform(0.1, 5, size=20) for _ in range(4)]
    np.testing.assert_allclose(sum(normalize_weights(W)), 1.0, rtol=1e-14)
    X = [rng.normal(size=(20, 3)) for _ in range(4)]
    np.testing.assert_allclose(weighted_sum(X, normalize_weights([np.ones(20)] * 4)), average(X), rtol=1e-13,
                               atol=1e-15)
    want = sum(w[:, None] * x for w, x in zip(W, X)) / sum(W)[:, None]
    np.testing.assert_allclose(weighted_sum(X, normalize_weights(W)), want, rtol=1e-12)


def test_a_rigid_motion_has_no_distortion_and_a_stretch_has_less_weight():
    rng = np.random.default_rng(3)
    VN, FN = _grid(4)
    VN[:, 2] = 0.05 * rng.normal(size=len(VN))
    tri = np.arange(len(FN))
    R = _rotation(rng)
    w_rigid = distortion_weights(tri, VN, VN @ R.T + 1.0, FN)
    np.testing.assert_allclose(w_rigid, 1e6, rtol=1e-6)                # 1 / (1e-3 + 0)^2
    w_stretch = distortion_weights(tri, VN, VN * [1.3, 1, 1], FN)
    assert (w_stretch < w_rigid).all() and (w_stretch > 0).all()

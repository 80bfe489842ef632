"""DeFAUST handles: Delta_l static/dynamic classification, geodesic neighbourhoods,
position storage and snapping (paper appendix "DeFAUST dataset")."""
from __future__ import annotations

import numpy as np
import pytest

from defaust.handles import (
    BASE_LANDMARKS,
    classify_groups,
    geodesic_neighbourhood,
    handles_from_arrays,
    handles_to_arrays,
    landmark_handles,
    landmarks_for_target,
    snap_handles,
)
from sshade.errors import SShaDeError


def grid(n: int = 21, size: float = 1.0):
    """A flat n x n vertex grid in the xy-plane (metres), two triangles per cell."""
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    V = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return V, F


def test_delta_classification_constructed_case():
    V, F = grid()
    n = 21
    W = V.copy()
    left = V[:, 0] < 0.5
    W[left, 2] += 0.05          # left half moves 5 cm
    W[~left, 2] += 0.005        # right half moves 5 mm
    lm = {"left": 10 * n + 0, "right": 10 * n + 20}  # middles of the left and right edges
    H = landmark_handles(V, F, W, lm, n_per_landmark=30, neighbourhood=90, static_threshold=0.02, seed=3)
    # every draw of a group lies on its own half, so Delta_l = 30 * displacement
    assert np.allclose(H.delta, [30 * 0.05, 30 * 0.005])
    assert H.group_static.tolist() == [False, True]
    assert len(H) == 60 and H.landmark_names == ("left", "right")
    dyn, sta = H.group == 0, H.group == 1
    assert not H.static[dyn].any() and H.static[sta].all()
    np.testing.assert_array_equal(H.target[dyn], W[H.index[dyn]])   # dynamic: target pose positions
    np.testing.assert_array_equal(H.target[sta], V[H.index[sta]])   # static: kept in place
    np.testing.assert_array_equal(H.rest, V[H.index])               # stored as exact rest positions
    # the threshold is on the mean displacement, strictly below = static
    assert classify_groups([0.6, 0.59], 30, 0.02).tolist() == [False, True]
    # a higher threshold makes both static; same seed, same draw
    H2 = landmark_handles(V, F, W, lm, static_threshold=0.06, seed=3)
    assert H2.group_static.all()
    np.testing.assert_array_equal(H2.index, H.index)


def test_draws_are_seeded_and_local():
    V, F = grid()
    lm = {"a": 0, "b": 440}
    H1 = landmark_handles(V, F, V, lm, seed=1)
    H2 = landmark_handles(V, F, V, lm, seed=1)
    H3 = landmark_handles(V, F, V, lm, seed=2)
    np.testing.assert_array_equal(H1.index, H2.index)
    assert not np.array_equal(H1.index, H3.index)
    nb = geodesic_neighbourhood(V, F, [0, 440], 90)
    assert nb[0, 0] == 0 and nb[1, 0] == 440
    assert set(H1.index[H1.group == 0]) <= set(nb[0]) and set(H1.index[H1.group == 1]) <= set(nb[1])
    assert H1.group_static.all()  # nothing moves


def test_roundtrip_arrays():
    V, F = grid()
    H = landmark_handles(V, F, V + 0.1, {"a": 0, "b": 440}, seed=0)
    H2 = handles_from_arrays(handles_to_arrays(H))
    for k in ("rest", "target", "static", "group", "delta", "group_static", "index"):
        np.testing.assert_array_equal(getattr(H2, k), getattr(H, k))
    assert H2.landmark_names == H.landmark_names and H2.seed == H.seed


def test_snap_exact_near_duplicates_and_off_surface():
    V, F = grid()
    s = snap_handles(V, V[[5, 7, 9]])
    assert s.index.tolist() == [5, 7, 9] and s.keep.all() and s.n_dropped == 0 and s.distance.max() == 0
    # perturbed positions snap back to their vertices
    rng = np.random.default_rng(0)
    P = V[[100, 200, 300]] + rng.uniform(-0.005, 0.005, (3, 3))  # grid step 0.05
    assert snap_handles(V, P).index.tolist() == [100, 200, 300]
    # two handles on one vertex: the nearer one is kept, deterministically
    P = np.array([V[50] + [0.004, 0, 0], V[50] + [0.001, 0, 0], V[60]])
    s = snap_handles(V, P)
    assert s.keep.tolist() == [False, True, True] and s.index.tolist() == [50, 60] and s.n_dropped == 1
    # a handle far from the mesh is an error naming it
    with pytest.raises(SShaDeError, match="off the surface"):
        snap_handles(V, [[0.5, 0.5, 0.3]])
    with pytest.raises(SShaDeError):
        snap_handles(V, np.zeros((0, 3)))


def test_landmarks_for_last_target():
    lm = {n: i for i, n in enumerate(BASE_LANDMARKS + ("left_elbow", "chest"))}
    assert list(landmarks_for_target(lm, 0, 4)) == list(BASE_LANDMARKS)
    assert list(landmarks_for_target(lm, 3, 4)) == list(lm)
    with pytest.raises(SShaDeError):
        landmarks_for_target({"chest": 1}, 0, 4)


def test_bad_handle_parameters():
    V, F = grid()
    with pytest.raises(SShaDeError):
        landmark_handles(V, F, V[:-1], {"a": 0})
    with pytest.raises(SShaDeError):
        landmark_handles(V, F, V, {"a": 0, "b": 0})
    with pytest.raises(SShaDeError):
        landmark_handles(V, F, V, {"a": 0}, n_per_landmark=100, neighbourhood=90)
    with pytest.raises(SShaDeError):
        landmark_handles(V, F, V, {"a": 10_000})

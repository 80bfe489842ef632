"""defaust/anny_path.py: the frames from the rest pose to a target pose of an ANNY subject.
Frame 0 is the rest pose and frame 1 the target the builder makes (the last target with its
turn and shift); the joint rotations move along the geodesic; the planted feet stay; the
frames of a smooth path change smoothly. Skips without body-models or the ANNY assets."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from defaust.anny_path import interpolate_pose_arrays, path_transforms
from defaust.anny_source import anny_subject
from sshade.errors import SShaDeError


@pytest.fixture(scope="module")
def model(anny_fixed_assets):
    return anny_fixed_assets


@pytest.fixture(scope="module")
def sub(model):
    """Subject 0 in its default targets (the last one turned and moved)."""
    return anny_subject(0, model=model, check_intersections=False)


def test_the_ends_of_the_path_are_the_rest_pose_and_the_target(model, sub):
    for pose in (1, len(sub.T) - 1):  # a planted target, and the last one (turned and shifted)
        T = path_transforms(sub, model, pose, [0.0, 1.0])
        np.testing.assert_allclose(sub.posed_by(T[0]), sub.V, atol=1e-9)
        np.testing.assert_allclose(sub.posed_by(T[1]), sub.posed(pose), atol=1e-9)


def test_the_joint_rotations_follow_the_geodesic():
    rng = np.random.default_rng(0)
    rest, target = {"body_pose": rng.normal(size=(5, 3))}, {"body_pose": rng.normal(size=(5, 3))}
    half = interpolate_pose_arrays(rest, target, 0.5)["body_pose"]
    r0, r1, rh = (Rotation.from_rotvec(x) for x in (rest["body_pose"], target["body_pose"], half))
    # halfway: equally far (angle) from both ends, and the two halves add up to the whole
    d0, d1, d = ((a.inv() * b).magnitude() for a, b in ((r0, rh), (rh, r1), (r0, r1)))
    np.testing.assert_allclose(d0, d1, atol=1e-12)
    np.testing.assert_allclose(d0 + d1, d, atol=1e-12)
    with pytest.raises(SShaDeError, match="in \\[0, 1\\]"):
        interpolate_pose_arrays(rest, target, 1.5)


def test_the_feet_stay_planted_and_the_path_is_smooth(model, sub):
    """Frames of the first target (feet planted): the lowest point stays on the floor, and
    the second difference of the vertex positions over the frames (the acceleration)
    stays far below the motion's own scale."""
    alphas = np.linspace(0.0, 1.0, 11)
    X = np.stack([sub.posed_by(T) for T in path_transforms(sub, model, 1, alphas)])
    assert np.abs(X[:, :, 1].min(axis=1)).max() < 0.02  # metres above or below y = 0
    motion = np.linalg.norm(X[-1] - X[0], axis=1).max()
    acc = np.linalg.norm(X[2:] - 2 * X[1:-1] + X[:-2], axis=2).max()
    assert motion > 0.1 and acc < 0.1 * motion


def test_a_pose_out_of_range_is_refused(model, sub):
    with pytest.raises(SShaDeError, match="out of range"):
        path_transforms(sub, model, 0, [0.5])
    with pytest.raises(SShaDeError, match="out of range"):
        path_transforms(sub, model, len(sub.T), [0.5])

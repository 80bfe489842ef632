"""DeFAUST synthetic source: human-like bodies posed by LBS share one face array and are
closed single-component manifolds (small settings so the test runs in seconds)."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from defaust.skinning import lbs, transfer_weights
from defaust.synthetic import synthetic_subject
from defaust.synthetic_body import JOINTS, LANDMARK_NAMES, BodyParams, body_model
from defaust.synthetic_mesh import body_sdf
from defaust.synthetic_poses import pose_names, pose_transforms
from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh

SMALL = dict(n_vertices=2500, voxel_size=0.02)


@pytest.fixture(scope="module")
def subject():
    return synthetic_subject(0, 1, n_poses=5, **SMALL)


def test_poses_share_faces_and_are_watertight_manifolds(subject):
    sub = subject
    assert sub.pose_names == ["rest", "arms_raised", "knees_bent", "twisted_torso", "step_turn"]
    F = sub.F
    for p in range(len(sub.pose_names)):
        Vp = sub.posed(p)
        assert Vp.shape == sub.V.shape
        # single component, closed 2-manifold, no degenerate faces
        validate_mesh(Vp, F, name=f"pose {p}", allow_boundary=False)
        tm = trimesh.Trimesh(Vp, F, process=False)
        assert tm.is_watertight and tm.is_winding_consistent
        assert tm.volume > 0  # outward orientation
        assert len(tm.split(only_watertight=False)) == 1
    np.testing.assert_array_equal(sub.posed(0), sub.V)  # pose 0 is the rest pose


def test_human_like_proportions_and_landmarks(subject):
    sub = subject
    V, H = sub.V, sub.body.params.height
    ext = V.max(0) - V.min(0)
    assert abs(ext[1] - H) < 0.08 * H              # as tall as the stature
    assert 0.35 * H < ext[0] < 0.8 * H             # arms spread in an A-pose
    assert ext[2] < 0.25 * H                       # a body, not a blob
    lm = {k: V[i] for k, i in sub.landmarks.items()}
    assert list(sub.landmarks) == list(LANDMARK_NAMES)
    assert lm["head_top"][1] > V[:, 1].max() - 0.01
    assert lm["left_hand"][0] > 0.25 * H and lm["right_hand"][0] < -0.25 * H   # +x is the subject's left
    assert lm["left_foot"][1] < 0.05 * H and lm["left_foot"][2] > 0.05 * H       # toe tips, forward
    assert lm["left_knee"][1] < lm["crotch"][1] < lm["chest"][1] < lm["head_top"][1]
    assert lm["left_elbow"][2] < 0 and lm["chest"][2] > 0                        # back of the elbow, front of the chest
    assert len(set(sub.landmarks.values())) == len(LANDMARK_NAMES)


def test_deterministic_and_independent_of_other_subjects(subject):
    again = synthetic_subject(0, 1, n_poses=5, **SMALL)
    np.testing.assert_array_equal(again.V, subject.V)
    np.testing.assert_array_equal(again.F, subject.F)
    np.testing.assert_array_equal(again.posed(3), subject.posed(3))
    other = synthetic_subject(0, 2, n_poses=5, **SMALL)
    assert other.body.params != subject.body.params


def test_skinning_is_rigid_per_part_and_transfers():
    body = body_model(BodyParams())
    R, t = pose_transforms(body, np.zeros((len(JOINTS), 3)), [0.1, 0, 0])
    V = np.random.default_rng(0).normal(size=(5, 3))
    W = np.full((5, len(JOINTS)), 1.0 / len(JOINTS))
    np.testing.assert_allclose(lbs(V, W, R, t), V + [0.1, 0, 0])
    assert body_sdf(body, body.joints).max() < 0       # joints are inside the body
    # weights interpolated at a mesh's own vertices are its weights
    Vt = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    Ft = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    Wt = np.eye(4)
    np.testing.assert_allclose(transfer_weights(Vt, Ft, Wt, Vt), Wt, atol=1e-12)


def test_pose_count_bounds():
    assert pose_names(2) == ["rest", "step_turn"]
    assert len(pose_names(7)) == 7
    with pytest.raises(SShaDeError):
        pose_names(8)

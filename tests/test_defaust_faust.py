"""DeFAUST faust source: discovery of tr_reg_XYZ.ply files, landmarks, a small build with
its high-res ground truth, and its resume (skips cleanly when ../shared/data/faust_reg is
absent)."""
from __future__ import annotations

import os

import numpy as np
import pytest

import defaust.sources
from defaust.build import build_defaust
from defaust.cli import compose_config, config_from_omegaconf
from defaust.dataset import load_handles
from defaust.faust_source import FAUST_LANDMARKS, discover_faust, faust_subjects
from eval.datasets.defaust_dataset import DefaustOptions, load_defaust
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh

from .conftest import SHARED_DATA


@pytest.fixture(scope="module")
def faust_root():
    root = SHARED_DATA / "faust_reg"
    if not (root / "tr_reg_000.ply").is_file():
        pytest.skip(f"FAUST registrations not found in {root}")
    return root


def test_discovery_on_shared_data(faust_root):
    files = discover_faust(faust_root)
    present = {divmod(int(p.name[7:10]), 10) for p in faust_root.glob("tr_reg_???.ply")}
    assert set(files) == present and (0, 0) in files
    plan = faust_subjects(files, n_targets=4)
    assert plan[0] == sorted(p for s, p in present if s == 0 and p != 0)[:4]
    assert faust_subjects(files, target_poses=[2, 9], subjects=[0]) == {0: [2]}


def test_discovery_archive_layout_and_errors(faust_root, tmp_path):
    reg = tmp_path / "MPI-FAUST" / "training" / "registrations"
    reg.mkdir(parents=True)
    for name in ("tr_reg_000.ply", "tr_reg_001.ply"):
        os.symlink(faust_root / name, reg / name)  # links in a temp dir: nothing is copied
    (reg / "tr_reg_1.ply").write_text("not a registration name")
    files = discover_faust(tmp_path / "MPI-FAUST")
    assert sorted(files) == [(0, 0), (0, 1)]
    with pytest.raises(SShaDeError, match="not found"):
        discover_faust(tmp_path / "missing")
    with pytest.raises(SShaDeError, match="no FAUST registrations"):
        discover_faust(tmp_path / "MPI-FAUST" / "training")
    with pytest.raises(SShaDeError, match="rest pose"):
        faust_subjects({(0, 1): reg / "tr_reg_001.ply"})


def test_landmarks_on_template(faust_root):
    V, F = read_mesh(faust_root / "tr_reg_000.ply")
    lm = {k: V[i] for k, i in FAUST_LANDMARKS.items()}
    assert FAUST_LANDMARKS["head_top"] == int(np.argmax(V[:, 1]))
    assert lm["left_hand"][0] > lm["crotch"][0] > lm["right_hand"][0]     # +x = subject's left
    assert lm["left_foot"][1] < lm["left_knee"][1] < lm["crotch"][1] < lm["chest"][1] < lm["head_top"][1]
    assert lm["chest"][2] > lm["crotch"][2] and lm["left_elbow"][2] < lm["chest"][2]


def test_small_faust_build(faust_root, tmp_path):
    cfg = compose_config(["preset=ci", "source=faust", f"faust.root={faust_root}", f"out={tmp_path}",
                          "subjects=[0]", "faust.target_poses=[1,4]", "progress=false"])
    rep = build_defaust(config_from_omegaconf(cfg))
    assert rep.built == ["subject_00/rest", "subject_00/pose_01", "subject_00/pose_04"]
    V0, F0 = read_mesh(faust_root / "tr_reg_000.ply")
    Vl, Fl = read_mesh(tmp_path / "subject_00/rest_low.ply")
    np.testing.assert_array_equal(Vl, V0)
    np.testing.assert_array_equal(Fl, F0)
    V4, _ = read_mesh(faust_root / "tr_reg_004.ply")
    H = load_handles(tmp_path / "subject_00/pose_04_handles.npz")
    assert len(H.landmark_names) == len(FAUST_LANDMARKS)   # last target: all landmarks
    assert len(load_handles(tmp_path / "subject_00/pose_01_handles.npz").landmark_names) == 6
    dyn = ~H.static
    np.testing.assert_array_equal(H.target[dyn], V4[H.index[dyn]])
    cases = load_defaust(tmp_path, DefaustOptions(resolution="low", subjects=[0]))  # a build of subject 0 only
    np.testing.assert_array_equal(cases[1].V_gt, V4)
    # the high-res ground truth (defaust.registration_gt): on rest_high's faces, written per pose
    Vh, Fh = read_mesh(tmp_path / "subject_00/rest_high.ply")
    hi = load_defaust(tmp_path, DefaustOptions(subjects=[0]))
    assert 8000 <= len(hi[0].V) <= 12000
    for c in hi:
        Vg, Fg = read_mesh(tmp_path / f"subject_00/pose_{c.pose:02d}_high.ply", validate=False)
        np.testing.assert_array_equal(Fg, Fh)
        np.testing.assert_array_equal(c.V_gt, Vg)
        assert c.V_gt.shape == Vh.shape and np.abs(c.V_gt - Vh).max() > 0.01
    info = rep.manifest["items"]["subject_00/pose_04"]["info"]
    assert info["gt_volume_change_pct_high"] == pytest.approx(info["gt_volume_change_pct_low"], abs=0.5)


def test_faust_pose_items_rebuild_when_the_ground_truth_changes(faust_root, tmp_path, monkeypatch):
    """The faust pose keys hold the ground truth's definition (defaust.sources.FAUST_HIGH_GT): a
    build made with another (e.g. before the high-res ground truth) rebuilds its pose items on
    resume and keeps its rest item."""
    args = ["preset=ci", "source=faust", f"faust.root={faust_root}", f"out={tmp_path}", "subjects=[0]",
            "faust.target_poses=[1]", "progress=false"]
    monkeypatch.setattr(defaust.sources, "FAUST_HIGH_GT", "an earlier definition")
    build_defaust(config_from_omegaconf(compose_config(args)))
    monkeypatch.undo()
    rep = build_defaust(config_from_omegaconf(compose_config(args)))
    assert rep.built == ["subject_00/pose_01"] and rep.skipped == ["subject_00/rest"]

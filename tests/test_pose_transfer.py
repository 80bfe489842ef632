"""Pose transfer (paper §4.3): sshade.isometric.pose_transfer and the FAUST experiment
(eval/experiments/pose_transfer.py)."""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from eval.config_check import check_config
from sshade.errors import SShaDeError
from sshade.isometric import isometric_transfer, pose_transfer, rigid_align

from .conftest import SHARED_DATA, data_file


@pytest.fixture(scope="module")
def faust():
    """Subjects 0 and 1 in poses 0 and 1 (one shared face array)."""
    from sshade.mesh.io import read_mesh
    V = {}
    for s in (0, 1):
        for p in (0, 1):
            V[(s, p)], F = read_mesh(data_file(f"faust_reg/tr_reg_0{s}{p}.ply"), validate=False)
    return V, F


def _vertex_err_pct(X, gt):
    """Mean vertex error in % of gt's bbox diagonal after the best rigid motion of X onto gt."""
    d = np.linalg.norm(rigid_align(X, gt) - gt, axis=1)
    return 100 * d.mean() / np.linalg.norm(gt.max(0) - gt.min(0))


def test_s_equal_m_is_isometric_transfer(faust):
    V, F = faust
    M, Mp = V[(0, 0)], V[(0, 1)]
    a = pose_transfer(M, F, M, Mp, n_low=300, n_samplings=2, seed=4, workers=1)
    b, _ = isometric_transfer(M, F, Mp, n_low=300, n_samplings=2, seed=4, workers=1)
    assert np.abs(a - b).max() < 1e-12


def test_align_removes_a_rigid_misplacement_of_s(faust):
    from scipy.spatial.transform import Rotation
    V, F = faust
    M, S, Mp = V[(0, 0)], V[(1, 0)], V[(0, 1)]
    R = Rotation.from_rotvec([0.2, -0.4, 0.1]).as_matrix()
    a = pose_transfer(M, F, S, Mp, n_low=300, n_samplings=2, workers=1, align=True)
    b = pose_transfer(M, F, S @ R.T + [1.0, 2.0, 3.0], Mp, n_low=300, n_samplings=2, workers=1, align=True)
    assert np.abs(a - b).max() < 1e-9


def test_faust_s0_to_s1_beats_identity(faust):
    """Subject 1 put in subject 0's pose 1, against subject 1's own pose 1."""
    V, F = faust
    M, S, Mp, gt = V[(0, 0)], V[(1, 0)], V[(0, 1)], V[(1, 1)]
    Sp, info = pose_transfer(M, F, S, Mp, n_low=300, n_samplings=2, seed=0, workers=1, align=True,
                             return_info=True)
    e_transfer, e_identity = _vertex_err_pct(Sp, gt), _vertex_err_pct(S, gt)
    assert e_transfer < 0.5 * e_identity, (e_transfer, e_identity)
    assert e_transfer < 4.0
    assert set(info) >= {"total_s", "remesh_s", "sampling_seeds", "n_low"}


def test_bad_input(faust):
    V, F = faust
    M = V[(0, 0)]
    with pytest.raises(SShaDeError, match="V_S"):
        pose_transfer(M, F, M[:-3], M, n_low=100, n_samplings=1)
    with pytest.raises(SShaDeError, match="V_Mprime"):
        pose_transfer(M, F, M, M[:, :2], n_low=100, n_samplings=1)
    with pytest.raises(SShaDeError):
        pose_transfer(M, F[:, :2], M, M, n_low=100, n_samplings=1)


def _cfg(root, out_dir, **over):
    from omegaconf import OmegaConf
    pt = {"root": str(root), "subjects": [0, 1], "poses": [1], "align": True}
    pt.update(over)
    sshade = {"n_low": 300, "n_samplings": 2, "seed": 0, "gradient": "normalized", "workers": 1}
    return OmegaConf.create({"experiment": {"name": "pose_transfer", "kind": "pose_transfer"},
                             "out_dir": str(out_dir), "pose_transfer": pt, "sshade": sshade})


def test_run_pose_transfer_writes_tables(tmp_path, faust):
    from eval.experiments.pose_transfer import run_pose_transfer
    from eval.present.render import png_size
    out = tmp_path / "out"
    cfg = _cfg(SHARED_DATA / "faust_reg", out)
    cfg.figures = {"enabled": True, "max_cases": 1}
    res = run_pose_transfer(check_config(cfg))
    for f in ("cases.csv", "table.csv", "table.md", "run.json"):
        assert (out / f).is_file(), f
    # the first figures.max_cases cases: M, M', S, SShaDe, truth + colour bar (pose_transfer_figure)
    figs = sorted((out / "figures").glob("*.png"))
    assert [f.name for f in figs] == ["s0-s1_p1.png"]
    assert figs[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png_size(figs[0]) == (5 * 240 + 90, 400 + 56)
    assert not list(out.glob(".*.tmp"))
    cases = pd.read_csv(out / "cases.csv", keep_default_na=False)
    assert cases["case"].tolist() == ["s0->s1_p1", "s1->s0_p1"] and (cases["error"] == "").all()
    for pre in ("", "naive_", "identity_", "mprime_"):
        for m in ("gt_vertex_mean_pct", "gt_vertex_max_pct", "hausdorff", "chamfer", "stretch_vs_S_pct"):
            assert math.isfinite(float(cases[pre + m][0])), pre + m
    assert (cases["gt_vertex_mean_pct"] < 0.5 * cases["identity_gt_vertex_mean_pct"]).all()
    table = pd.read_csv(out / "table.csv")
    assert table["method"].iloc[0] == "SShaDe pose transfer" and (table["n_cases"] == 2).all()
    assert any(table["method"].str.startswith("identity"))
    assert "identity" in (out / "table.md").read_text()
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "done" and info["n_cases"] == 2
    assert res["n_errors"] == 0


def test_run_pose_transfer_bad_config(tmp_path):
    from eval.experiments.pose_transfer import run_pose_transfer
    with pytest.raises(SShaDeError, match="pose_transfer.root"):
        run_pose_transfer(check_config(_cfg(tmp_path / "nowhere", tmp_path / "out")))
    data_file("faust_reg/tr_reg_000.ply")
    with pytest.raises(SShaDeError, match="subject"):
        run_pose_transfer(check_config(_cfg(SHARED_DATA / "faust_reg", tmp_path / "out", subjects=[0, 7])))
    with pytest.raises(SShaDeError, match="no pose-transfer case"):
        run_pose_transfer(check_config(_cfg(SHARED_DATA / "faust_reg", tmp_path / "out", poses=[9])))

"""Non-rigid isometric deformation transfer (paper §4.2): sshade.isometric and the TOSCA
experiment (eval/experiments/tosca.py)."""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval.config_check import check_config
from sshade.errors import SShaDeError
from sshade.isometric import isometric_transfer, rigid_align
from sshade.sampling import sampling_seeds

from .conftest import SHARED_DATA, data_file, subprocess_env

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def sphere():
    """A 642-vertex icosphere, slightly squashed so no two coordinate axes are alike."""
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=3)
    return np.asarray(m.vertices) * [1.0, 0.8, 0.6], np.asarray(m.faces, np.int64)


@pytest.fixture(scope="module")
def cat():
    from sshade.mesh.io import read_mesh
    V0, F0 = read_mesh(data_file("tosca/cat0.off"))
    V1, _ = read_mesh(data_file("tosca/cat1.off"), validate=False)  # cat0's faces for every pose
    return V0, F0, V1


def _rotation(seed=3):
    from scipy.spatial.transform import Rotation
    return Rotation.random(random_state=seed).as_matrix()


def _diag(V):
    return float(np.linalg.norm(V.max(0) - V.min(0)))


@pytest.mark.parametrize("gradient", ["normalized", "raw"])
def test_rigid_motion_is_reproduced_exactly(sphere, gradient):
    V, F = sphere
    T = V @ _rotation().T + [0.3, -2.0, 5.0]
    Vp, info = isometric_transfer(V, F, T, n_low=100, n_samplings=2, seed=1, gradient=gradient, workers=1)
    assert Vp.shape == V.shape and Vp.dtype == np.float64
    assert np.abs(Vp - T).max() < 1e-9 * _diag(V)
    assert info["sampling_seeds"] == sampling_seeds(1, 2) and len(info["samplings"]) == 2


def test_identity_target_gives_rest(sphere):
    V, F = sphere
    Vp, _ = isometric_transfer(V, F, V.copy(), n_low=100, n_samplings=2, workers=1)
    assert np.abs(Vp - V).max() < 1e-12 * _diag(V)


def test_workers_do_not_change_the_result(sphere):
    V, F = sphere
    T = V.copy()
    T[:, 2] += 0.3 * np.sin(2 * V[:, 0])  # a smooth non-rigid bend
    a, ia = isometric_transfer(V, F, T, n_low=80, n_samplings=3, seed=5, workers=1)
    b, ib = isometric_transfer(V, F, T, n_low=80, n_samplings=3, seed=5, workers=2)
    assert np.array_equal(a, b)
    assert ia["sampling_seeds"] == ib["sampling_seeds"]
    assert np.abs(a - T).mean() < 0.05 * _diag(V)


def test_bad_input(sphere):
    V, F = sphere
    with pytest.raises(SShaDeError, match="1:1"):
        isometric_transfer(V, F, V[:-1], n_low=50, n_samplings=1)
    bad = V.copy()
    bad[7, 1] = np.nan
    with pytest.raises(SShaDeError, match="NaN"):
        isometric_transfer(V, F, bad, n_low=50, n_samplings=1)
    with pytest.raises(SShaDeError, match="n_samplings"):
        isometric_transfer(V, F, V, n_low=50, n_samplings=0)
    with pytest.raises(SShaDeError, match="n_low"):
        isometric_transfer(V, F, V, n_low=2, n_samplings=1)
    with pytest.raises(SShaDeError, match="gradient"):
        isometric_transfer(V, F, V, n_low=50, n_samplings=1, gradient="affine")
    with pytest.raises(SShaDeError):  # two components: not a valid single-component mesh
        V2 = np.concatenate([V, V + 5])
        isometric_transfer(V2, np.concatenate([F, F + len(V)]), V2, n_low=50, n_samplings=1)


def test_rigid_align(sphere):
    V, _ = sphere
    X = V @ _rotation(7).T - 4.0
    assert np.abs(rigid_align(X, V) - V).max() < 1e-12
    with pytest.raises(SShaDeError):
        rigid_align(V[:-1], V)


def test_tosca_cat_pair(cat):
    """cat0 -> cat1 (paper §4.2 protocol, smaller settings): close to the true pose."""
    from eval.metrics.measures import chamfer, ground_truth_metrics, hausdorff
    V0, F0, V1 = cat
    Vp, info = isometric_transfer(V0, F0, V1, n_low=3000, n_samplings=2, seed=0, workers=1)
    m = ground_truth_metrics(Vp, F0, V1)
    direct_h, direct_c = hausdorff(V0, F0, V1, F0), chamfer(V0, F0, V1, F0)
    assert m["hausdorff"] < 0.02, m
    assert m["hausdorff"] < 0.05 * direct_h and m["chamfer"] < 1e-4 * direct_c
    assert m["gt_vertex_mean_pct"] < 0.1
    assert info["n_low"] >= 3000


# ------------------------------------------------------------------ experiment runner

def _cfg(root, out_dir, **over):
    from omegaconf import OmegaConf
    tosca = {"root": str(root), "min_vertices": 5000, "classes": ["centaur", "wolf"], "poses": [1]}
    tosca.update(over)
    sshade = {"n_low": 300, "n_samplings": 2, "seed": 0, "gradient": "normalized", "workers": 1}
    return OmegaConf.create({"experiment": {"name": "tosca", "kind": "tosca"}, "out_dir": str(out_dir),
                             "tosca": tosca, "sshade": sshade})


def test_run_tosca_writes_tables(tmp_path):
    from eval.experiments.tosca import PAPER_TOSCA, run_tosca
    data_file("tosca/centaur0.off"), data_file("tosca/centaur1.off"), data_file("tosca/wolf0.off")
    from eval.present.render import png_size
    out = tmp_path / "out"
    cfg = _cfg(SHARED_DATA / "tosca", out)
    cfg.figures = {"enabled": True, "max_cases": 4}
    res = run_tosca(check_config(cfg))
    for f in ("cases.csv", "table.csv", "table.md", "run.json"):
        assert (out / f).is_file(), f
    # one figure per class that ran: rest, true pose, SShaDe + colour bar (eval.present.figures.tosca_figure)
    figs = sorted((out / "figures").glob("*.png"))
    assert [f.name for f in figs] == ["centaur1.png"]
    assert figs[0].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png_size(figs[0]) == (3 * 320 + 90, 400 + 56)
    assert not list(out.glob(".*.tmp"))
    # one 3D view per class: rest, true pose, SShaDe coloured by its distance to the true pose
    from eval.present.meshview import read_view
    view = read_view(out / "report" / "centaur1.js")
    assert [m["label"] for m in view["meshes"]] == ["rest", "target (ground truth)", "SShaDe"]
    assert view["meshes"][2]["gt"] is not None and view["meshes"][2]["kind"] == "result"
    cases = pd.read_csv(out / "cases.csv", keep_default_na=False)
    assert cases["case"].tolist() == ["centaur1"] and (cases["error"] == "").all()
    assert cases["n_vertices"].tolist() == [15768]
    for c in ("hausdorff", "chamfer", "gt_vertex_mean_pct", "gt_vertex_max_pct", "time_s", "rest_hausdorff"):
        assert math.isfinite(float(cases[c][0])), c
    assert float(cases["hausdorff"][0]) < 0.1 * float(cases["rest_hausdorff"][0])
    table = pd.read_csv(out / "table.csv")
    assert table["class"].tolist()[:2] == ["centaur", "all (mean over cases)"]
    paper = table.iloc[-1]
    assert paper["hausdorff"] == pytest.approx(PAPER_TOSCA["hausdorff"])
    assert paper["chamfer"] == pytest.approx(PAPER_TOSCA["chamfer"])
    md = (out / "table.md").read_text()
    assert "5.66" in md and "3.76" in md and "wolf" in md  # reference row, exclusion note
    import json
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "done" and "wolf" in info["excluded"]
    assert info["seeds"]["sampling_seeds"] == sampling_seeds(0, 2)
    assert res["n_errors"] == 0


def test_run_tosca_bad_config(tmp_path):
    from eval.experiments.tosca import run_tosca
    with pytest.raises(SShaDeError, match="tosca.root"):
        run_tosca(check_config(_cfg(tmp_path / "nowhere", tmp_path / "out")))
    (tmp_path / "empty").mkdir()
    with pytest.raises(SShaDeError, match="no TOSCA"):
        run_tosca(check_config(_cfg(tmp_path / "empty", tmp_path / "out")))
    data_file("tosca/centaur0.off")
    with pytest.raises(SShaDeError, match="horse"):
        run_tosca(check_config(_cfg(SHARED_DATA / "tosca", tmp_path / "out", classes=["horse"])))
    with pytest.raises(SShaDeError, match="no TOSCA case"):  # wolf alone is excluded
        run_tosca(check_config(_cfg(SHARED_DATA / "tosca", tmp_path / "out", classes=["wolf"])))


@pytest.mark.slow
def test_cli_experiment_tosca(tmp_path):
    """`python -m eval experiment=tosca` with the default (relative) root from the repo root;
    conf/config.yaml's dataset.root=??? is never touched."""
    data_file("tosca/centaur0.off")
    if Path(os.path.relpath(SHARED_DATA / "tosca", ROOT)) != Path("../shared/data/tosca"):
        pytest.skip("shared data is not at ../shared/data relative to the repository")
    env = subprocess_env()
    r = subprocess.run([sys.executable, "-m", "eval", "experiment=tosca", "tosca.classes=[centaur]",
                        "tosca.poses=[2]", "sshade.n_low=300", "sshade.n_samplings=1", "sshade.workers=1",
                        f"out_dir={tmp_path / 'cli'}"], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert (tmp_path / "cli" / "table.md").is_file()
    cases = pd.read_csv(tmp_path / "cli" / "cases.csv", keep_default_na=False)
    assert cases["case"].tolist() == ["centaur2"]
    r = subprocess.run([sys.executable, "-m", "eval", "experiment=tosca", f"tosca.root={tmp_path / 'nope'}",
                        f"out_dir={tmp_path / 'cli2'}"], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 2 and "error: tosca.root" in r.stderr

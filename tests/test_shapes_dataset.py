"""Stanford shapes with the fixed user-defined edit (eval/datasets/shapes.py)."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from eval.config_check import check_config
from eval.datasets import load_cases
from eval.datasets.shapes import ShapesOptions, axis_handles, axis_landmarks, principal_axes, shape_cases
from sshade.errors import SShaDeError

from .conftest import data_file


def _options(**kw) -> ShapesOptions:
    """The shapes' options with ``kw``, at the files' native resolution unless ``kw`` says."""
    return ShapesOptions(**{"vertex_range": None, **kw})


@pytest.fixture(scope="module")
def classic():
    return data_file("classic/bunny.off").parent


def test_the_edit_is_what_the_docstring_says(classic):
    (c,) = shape_cases(classic, _options(files=["bunny.off"], seed=3))
    assert c.V_gt is None and c.n_source == len(c.V) == 3485
    g = c.group
    assert len(c.handles) == len(np.unique(c.handles)) == len(g)
    counts = np.bincount(g, minlength=4)
    assert len(counts) == 4 and (counts >= 25).all() and (counts <= 30).all()  # a small region may hold < 30
    lm, center, axes = axis_landmarks(c.V)
    diag = np.linalg.norm(c.V.max(0) - c.V.min(0))
    # regions: within 6% of the diagonal of their landmark
    assert (np.linalg.norm(c.V[c.handles] - lm[g], axis=1) <= 0.06 * diag + 1e-12).all()
    # regions 0 and 2 static (targets = rest), 1 rotated 20 deg about a3, 3 moved 5% of the diagonal along a3
    np.testing.assert_array_equal(c.static, np.isin(g, [0, 2]))
    P = c.V[c.handles]
    np.testing.assert_array_equal(c.targets[c.static], P[c.static])
    R = Rotation.from_rotvec(np.deg2rad(20.0) * axes[2]).as_matrix()
    np.testing.assert_allclose(c.targets[g == 1], (P[g == 1] - center) @ R.T + center, atol=1e-12)
    np.testing.assert_allclose(c.targets[g == 3] - P[g == 3], np.tile(0.05 * diag * axes[2], (counts[3], 1)),
                               atol=1e-12)
    # principal axes are orthonormal
    A = np.stack(axes)
    np.testing.assert_allclose(A @ A.T, np.eye(3), atol=1e-12)


#: sha256 of the bunny's edit at its own resolution (handles, targets, static, group bytes),
#: as made on a 2-core AMD EPYC with numpy's OpenBLAS; any machine must make these bytes.
BUNNY_EDIT_SHA256 = "b7446468006875c87dbad36dcd68050970daaed8b7ccc98b9334e8202ee8fc5f"


def test_the_edit_is_the_same_bytes_on_every_machine(classic):
    """No BLAS or LAPACK in the edit: the bytes recorded on one machine are made here,
    whatever this machine's library, kernels or threads (rows keyed by them compare)."""
    (c,) = shape_cases(classic, _options(files=["bunny.off"]))
    h = hashlib.sha256()
    for a in (c.handles, c.targets, c.static, c.group):
        h.update(np.ascontiguousarray(a).tobytes())
    assert h.hexdigest() == BUNNY_EDIT_SHA256


def test_principal_axes_are_lapacks_with_a_fixed_sign(classic):
    (c,) = shape_cases(classic, _options(files=["bunny.off"]))
    center, axes = principal_axes(c.V)
    np.testing.assert_allclose(center, c.V.mean(0), rtol=0, atol=1e-15)
    _, _, Wt = np.linalg.svd(c.V - c.V.mean(0), full_matrices=False)
    A = np.stack(axes)
    np.testing.assert_allclose(np.abs(np.sum(A * Wt, axis=1)), 1.0, atol=1e-12)  # the same axes, up to sign
    assert np.linalg.det(A) > 0  # right-handed: a3 = a1 x a2
    for a in axes[:2]:  # the sign: the largest-magnitude component positive
        assert a[np.abs(a).argmax()] > 0


def test_seeded_and_dispatched(classic):
    a = load_cases("shapes", classic, files=["bunny.off"], seed=0, vertex_range=None)[0]
    b = shape_cases(classic, _options(files=["bunny.off"], seed=0))[0]
    c = shape_cases(classic, _options(files=["bunny.off"], seed=1))[0]
    np.testing.assert_array_equal(a.handles, b.handles)
    assert not np.array_equal(a.handles, c.handles)


def test_high_resolution_version_is_cached(classic, tmp_path):
    (c,) = shape_cases(classic, _options(files=["bunny.off"], vertex_range=(8000, 12000), cache=tmp_path))
    assert 8000 <= len(c.V) <= 12000 and c.n_source == 3485
    cached = tmp_path / "bunny.off_8000-12000.ply"  # the whole file name: bunny.obj would have its own
    assert cached.is_file()
    (again,) = shape_cases(classic, _options(files=["bunny.off"], vertex_range=(8000, 12000), cache=tmp_path))
    np.testing.assert_array_equal(again.F, c.F)
    np.testing.assert_allclose(again.V, c.V)
    # the edit is defined on the source shape: the same regions at every resolution
    lm, _, _ = axis_landmarks(shape_cases(classic, _options(files=["bunny.off"]))[0].V)
    diag = np.linalg.norm(c.V.max(0) - c.V.min(0))
    assert np.bincount(c.group).tolist() == [30] * 4
    assert (np.linalg.norm(c.V[c.handles] - lm[c.group], axis=1) <= 0.06 * diag + 1e-12).all()


def test_bad_input(classic, tmp_path):
    with pytest.raises(SShaDeError, match="not a folder"):
        shape_cases(tmp_path / "nowhere")
    with pytest.raises(SShaDeError, match="not found"):
        shape_cases(classic, _options(files=["teapot.obj"]))
    with pytest.raises(SShaDeError, match="limit"):
        shape_cases(classic, _options(files=["bunny.off"], limit=0))
    with pytest.raises(SShaDeError, match="no file"):
        shape_cases(classic, _options(files=[]))
    (c,) = shape_cases(classic, _options(files=["bunny.off"]))
    lm, center, axes = axis_landmarks(c.V)
    with pytest.raises(SShaDeError, match="no free vertex"):
        axis_handles(c.V, lm + 1e3, center, axes)


def test_app_runs_experiment_shapes(classic, tmp_path):
    """`python -m eval experiment=shapes` on the bunny at its own resolution: every method
    scored, no ground truth, a figure."""
    import pandas as pd
    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR, run
    from eval.present.render import png_size
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=[
            "experiment=shapes", f"dataset.root={classic}", "dataset.files=[bunny.off]", "dataset.vertex_range=null",
            "methods=[Elastic,SShaDe]", "sshade.n_low=500", "sshade.n_samplings=2", f"out_dir={tmp_path / 'run'}"])
    res = run(check_config(cfg))
    cases = pd.read_csv(res["out_dir"] / "cases.csv", keep_default_na=False)
    assert cases["method"].tolist() == ["Elastic", "SShaDe"] and (cases["error"] == "").all()
    assert (cases["n_vertices"] == 3485).all() and "gt_vertex_mean_pct" not in cases.columns
    assert (cases["handle_err_pct"].astype(float) < 1e-3).all()
    assert (cases["edge_err_pct"].astype(float) < 2.0).all()
    fig = res["out_dir"] / "figures" / "bunny.png"
    assert png_size(fig) == (3 * 320 + 90, 480 + 56)


# ------------------------------------------------------------ case names and files of their own
def _write_shapes(d, names):
    """Each of ``names`` in ``d`` as a small closed mesh (an icosphere stretched along x,
    a different length per file, so the files differ); returns ``d``."""
    from sshade.mesh.io import write_mesh

    from .conftest import icosphere
    V, F = icosphere()
    for k, n in enumerate(names):
        write_mesh(d / n, V * np.array([2.0 + 0.25 * k, 1.0, 0.6]), F)
    return d


COLLIDING = ["a b.off", "a_b.off", "bunny.off", "bunny.obj", "solo.off"]


def test_colliding_case_names_become_distinct_file_names(tmp_path):
    from eval.run.names import safe_name
    cases = load_cases("shapes", _write_shapes(tmp_path, COLLIDING), files=COLLIDING, vertex_range=None,
                       n_per_group=3, region_radius=0.3)
    names = [c.name for c in cases]
    assert len({safe_name(n).casefold() for n in names}) == len(COLLIDING), names
    assert names[-1] == "solo" and cases[-1].subject == "solo"  # a name without a twin is kept
    assert [n.rsplit("-", 1)[0] for n in names[:4]] == ["a b", "a_b", "bunny", "bunny"]
    assert all(len(n.rsplit("-", 1)[1]) == 8 for n in names[:4])
    assert [c.subject for c in cases[:4]] == names[:4]  # the stem was the subject: it follows the name
    again = load_cases("shapes", tmp_path, files=COLLIDING, vertex_range=None, n_per_group=3, region_radius=0.3)
    assert [c.name for c in again] == names  # from the source paths: the same names every time


def test_a_file_listed_twice_is_refused(tmp_path):
    _write_shapes(tmp_path, ["x.off", "y.off"])
    for files in (["x.off", "y.off", "x.off"], ["x.off", "./x.off"]):
        with pytest.raises(SShaDeError, match="listed once"):
            shape_cases(tmp_path, _options(files=files, limit=1))  # the whole list is checked, not the first file


def test_the_app_refuses_a_file_listed_twice_before_any_work(tmp_path):
    import subprocess
    import sys

    from .conftest import ROOT, subprocess_env
    _write_shapes(tmp_path, ["x.off"])
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "eval", "dataset=shapes", f"dataset.root={tmp_path}",
                        "dataset.files=[x.off,x.off]", "dataset.vertex_range=null", "methods=[ARAP]",
                        "reference.cases=none", f"out_dir={out}"], cwd=ROOT, env=subprocess_env(),
                       capture_output=True, text=True, timeout=300)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), r.stderr[-2000:]
    assert "x.off" in lines[0] and "twice" in lines[0]
    assert not out.exists()


def test_colliding_cases_keep_their_own_results_and_views(tmp_path):
    """``a b`` / ``a_b`` and ``bunny.off`` / ``bunny.obj``: a stored record and a 3D view
    each, every view on the page, and a resume restores every pair (none recomputed)."""
    import json
    import re

    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR, run_experiment
    from eval.present.meshview import read_view
    root = tmp_path / "shapes"
    root.mkdir()
    _write_shapes(root, COLLIDING)
    out = tmp_path / "run"
    files = "[" + ",".join(f"'{f}'" for f in COLLIDING) + "]"
    overrides = ["dataset=shapes", f"dataset.root={root}", f"dataset.files={files}", "dataset.vertex_range=null",
                 "dataset.n_per_group=3", "dataset.region_radius=0.3", "reference.cases=none",
                 "methods=[{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:3}]",
                 "report.view_cases=5", "jobs=1", f"out_dir={out}"]
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=overrides)
        again = compose(config_name="config", overrides=[*overrides, "resume=true"])
    run_experiment(cfg)
    records = sorted((out / "runs").glob("*/Mine.json"))
    cases = [json.loads(p.read_text())["case"] for p in records]
    assert len(records) == len(set(cases)) == len(COLLIDING)
    views = sorted((out / "report").glob("*.js"))
    assert sorted(read_view(p)["case"] for p in views) == sorted(cases)
    page = (out / "index.html").read_text()
    assert sorted(re.findall(r'<div class="view" data-case="([^"]+)"', page)) == sorted(cases)
    stamps = {p: p.stat().st_mtime_ns for p in records}
    run_experiment(again)
    assert {p: p.stat().st_mtime_ns for p in records} == stamps  # every pair restored, none run again

"""eval/experiments/animation.py (``python -m eval experiment=animation``): on a small
ANNY-built DeFAUST, every method's frames start at the rest pose and end near the target
pose, SShaDe's frames converge, the table and the per-frame rows agree; the jitter of a
sequence equal to its ground truth is 0 and a known wobble gives its known value; a
FAUST-built DeFAUST is refused with one error line."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from defaust.manifest import FORMAT, MANIFEST
from eval.experiments.animation import jitter_pct

from .conftest import subprocess_env


def _eval(args, cwd):
    return subprocess.run([sys.executable, "-m", "eval", "experiment=animation", *args], cwd=cwd,
                          env=subprocess_env(), capture_output=True, text=True, timeout=900)


def test_jitter_is_what_the_result_accelerates_beyond_the_truth():
    rng = np.random.default_rng(0)
    G = np.cumsum(rng.normal(size=(6, 50, 3)), axis=0)  # any motion
    assert jitter_pct(G, G, 2.0) == 0.0
    assert abs(jitter_pct(G + [1.0, 2.0, 3.0], G, 2.0)) < 1e-12  # a constant offset does not accelerate
    wobble = np.zeros_like(G)
    wobble[3, :, 0] = 0.01  # one frame 1 cm off: second differences +0.01, -0.02, +0.01 around it
    assert np.isclose(jitter_pct(G + wobble, G, 1.0), 100 * 0.04 / 4)  # 4 inner frames
    assert np.isnan(jitter_pct(G[:2], G[:2], 1.0))


def test_a_faust_built_defaust_is_refused_with_one_line(tmp_path):
    root = tmp_path / "defaust"
    root.mkdir()
    (root / MANIFEST).write_text(json.dumps({"format": FORMAT, "source": "faust", "files": {}, "subjects": {}}))
    r = _eval([f"dataset.root={root}", f"out_dir={tmp_path / 'out'}"], tmp_path)
    assert r.returncode == 2
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "ANNY-built" in err[0] and "'faust'" in err[0]
    assert not (tmp_path / "out").exists()


@pytest.fixture(scope="module")
def small_defaust(tmp_path_factory, anny_assets, anny_cache):
    """Subject 0 of the ci preset (ANNY source), two target poses."""
    root = tmp_path_factory.mktemp("anim") / "defaust"
    r = subprocess.run([sys.executable, "-m", "defaust", "preset=ci", f"out={root}", "subjects=[0]",
                        "anny.poses=[squat,step]", f"anny.cache={anny_cache}", "progress=false"],
                       env=subprocess_env(), capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return root


@pytest.mark.slow
def test_frames_go_from_the_rest_pose_to_the_target_for_every_method(small_defaust, tmp_path, anny_cache):
    out = tmp_path / "out"
    r = _eval([f"dataset.root={small_defaust}", "animation.frames=4", "animation.subjects=[0]",
               "animation.baseline_cases=1", f"animation.anny_cache={anny_cache}", "methods=[SShaDe,Elastic]",
               "sshade.n_samplings=2", f"out_dir={out}"], tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = pd.read_csv(out / "cases.csv")
    assert set(rows.groupby("method")["case"].nunique().items()) == {("SShaDe", 2), ("Elastic", 1)}
    assert all(list(f) == [1, 2, 3, 4] for _, f in rows.groupby(["case", "method"])["frame"])
    s = rows[rows["method"] == "SShaDe"]
    assert s["converged"].astype(bool).all() and (s["time_s"] > 0).all()
    # the first frame is a quarter of the way: nearer the truth than the last, for every method
    first, last = (rows[rows["frame"] == f].set_index(["case", "method"])["gt_mean_pct"] for f in (1, 4))
    assert (first < last).all() and (last < 5.0).all()
    table = pd.read_csv(out / "table.csv").set_index("method")  # over the case both methods ran on
    assert table.loc["SShaDe", "n_frames"] == 4 and table.loc["Elastic", "n_frames"] == 4
    both = s[s["case"] == rows.loc[rows["method"] == "Elastic", "case"].iloc[0]]
    np.testing.assert_allclose(table.loc["SShaDe", "gt_mean_pct"], both["gt_mean_pct"].mean(), rtol=1e-5)
    assert "Over all the cases each method ran on" in (out / "table.md").read_text()
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "done" and info["dataset_build"]["canonical"] is False  # a small build: not canonical
    from eval.present.render import png_size
    for m in ("SShaDe", "Elastic"):  # the first case's frames, on the page
        assert png_size(out / f"frames_{m}.png")[0] >= 4 * 320
        assert f'alt="frames_{m}.png"' in (out / "index.html").read_text()

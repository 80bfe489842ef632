"""defaust.dataset, the dataset's public reader and verifier: loads without Hydra,
OmegaConf or the evaluator; handles and targets follow the stored files; the evaluator
reads the same arrays through it; verify names a changed, missing or unlisted file."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

import defaust
from defaust.dataset import load, load_handles, read_manifest, verify
from eval.datasets.defaust_dataset import DefaustOptions, load_defaust
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh

from .conftest import ROOT, subprocess_env


def test_load_in_a_fresh_process_imports_no_hydra_omegaconf_or_eval(defaust_ci):
    code = ("import sys, defaust; cases = defaust.load(sys.argv[1]); "
            "print(len(cases), cases[0].V.shape[1], sorted(m for m in ('hydra', 'omegaconf', 'eval') "
            "if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code, str(defaust_ci)], capture_output=True, text=True,
                       cwd=ROOT, env=subprocess_env(), timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["4", "3", "[]"]


@pytest.mark.parametrize("resolution", ["low", "high"])
def test_handles_and_targets_follow_the_stored_positions(defaust_ci, resolution):
    cases = load(defaust_ci, resolution=resolution)
    assert [c.name for c in cases] == ["s00_p01", "s00_p02", "s00_p03", "s00_p04"]
    for c in cases:
        H = load_handles(defaust_ci / "subject_00" / f"pose_{c.pose:02d}_handles.npz")
        assert len(c.handles) + c.n_dropped == len(H.rest) and len(np.unique(c.handles)) == len(c.handles)
        np.testing.assert_array_equal(c.targets[c.static], c.V[c.handles[c.static]])
        # a dynamic handle gets its stored displacement, from the vertex it snapped to
        d = ~c.static
        moved = c.targets[d] - c.V[c.handles[d]]
        assert np.abs(moved).max() > 0
        assert c.V_gt is not None and c.V_gt.shape == c.V.shape
        Vr, Fr = read_mesh(defaust_ci / "subject_00" / f"rest_{resolution}.ply")
        np.testing.assert_array_equal(c.V, Vr)
        np.testing.assert_array_equal(c.F, Fr)
        if resolution == "low":
            assert c.n_dropped == 0 and np.abs(c.snap_distance).max() == 0


def test_the_evaluator_reads_the_same_arrays(defaust_ci):
    low = load_defaust(defaust_ci, DefaustOptions(resolution="low"))
    for a, b in zip(load(defaust_ci, resolution="low"), low, strict=True):
        assert a.name == b.name and a.pose_name == b.pose_name and a.seed == b.seed
        for k in ("V", "F", "handles", "targets", "static", "group", "V_gt", "snap_distance"):
            np.testing.assert_array_equal(getattr(a, k), getattr(b, k))


def test_read_manifest_refuses_a_foreign_json(tmp_path):
    (tmp_path / "manifest.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(SShaDeError, match="not a DeFAUST manifest"):
        read_manifest(tmp_path)
    assert defaust.verify(tmp_path) and "not a DeFAUST manifest" in defaust.verify(tmp_path)[0]


def _copy(src, dst):
    shutil.copytree(src, dst)
    return dst


def _cli_verify(root):
    return subprocess.run([sys.executable, "-m", "defaust", "verify", str(root)], capture_output=True, text=True,
                          cwd=ROOT, env=subprocess_env(), timeout=300)


def test_verify_passes_a_good_copy_and_names_the_file_with_one_changed_byte(defaust_ci, tmp_path):
    good = _copy(defaust_ci, tmp_path / "good")
    assert verify(good) == []
    r = _cli_verify(good)
    assert r.returncode == 0 and "every file matches" in r.stdout
    bad = _copy(defaust_ci, tmp_path / "bad")
    f = bad / "subject_00" / "pose_02_high.ply"
    data = bytearray(f.read_bytes())
    data[-5] ^= 0x01
    f.write_bytes(bytes(data))
    assert verify(bad) == [f"{f}: checksum differs from manifest.json"]
    r = _cli_verify(bad)
    assert r.returncode == 2 and str(f) in r.stdout and "1 problem(s)" in r.stdout


def test_verify_names_a_missing_and_an_unlisted_file(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path / "c")
    (c / "subject_00" / "pose_01_low.ply").unlink()
    (c / "subject_00" / "notes.txt").write_text("mine")
    assert sorted(verify(c)) == sorted([f"{c / 'subject_00' / 'pose_01_low.ply'}: missing",
                                        f"{c / 'subject_00' / 'notes.txt'}: not in manifest.json"])
    assert _cli_verify(c).returncode == 2


def test_a_build_of_some_subjects_is_not_loaded_as_the_whole_dataset(tmp_path):
    """A build of subject 1 of 2 (``subjects=[1]``): ``load`` without ``subjects`` refuses in
    one line naming the subjects built and how to load or finish them; ``subjects=[1]`` and
    ``partial=True`` load its 4 cases; ``verify`` says what it holds and exits 0."""
    from defaust.build import build_defaust
    from defaust.cli import compose_config, config_from_omegaconf

    out = tmp_path / "some"
    build_defaust(config_from_omegaconf(compose_config(
        ["preset=ci", "source=synthetic", "n_subjects=2", "subjects=[1]", f"out={out}", "progress=false"])))
    with pytest.raises(SShaDeError, match=r"a DeFAUST build of subject\(s\) 1 \(1 of its 2 not built\), built with "
                                          r"subjects=\[1\]: load those with defaust.load\(\.\.\., subjects=\[1\]\)"):
        load(out)
    assert [c.name for c in load(out, subjects=[1])] == [c.name for c in load(out, partial=True)] == \
        ["s01_p01", "s01_p02", "s01_p03", "s01_p04"]
    assert verify(out) == []
    r = subprocess.run([sys.executable, "-m", "defaust", "verify", str(out)], capture_output=True, text=True,
                       cwd=ROOT, env=subprocess_env(), timeout=300)
    assert r.returncode == 0
    first, canon = r.stdout.strip().splitlines()
    assert first == f"{out}: every file matches its manifest; a build of subject(s) 1 (1 of its 2 not built)"
    assert canon.startswith(f"{out}: not the canonical DeFAUST")  # a ci build of the synthetic source


@pytest.mark.parametrize("partial", ["yes", 1, None])
def test_load_refuses_a_partial_that_is_no_boolean(tmp_path, partial):
    from defaust.dataset import load
    with pytest.raises(SShaDeError, match="partial must be True or False"):
        load(tmp_path, partial=partial)

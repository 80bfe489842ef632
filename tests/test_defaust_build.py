"""DeFAUST builder: layout, determinism, resume, atomicity, handle snapping after
remeshing, and the loader (synthetic source, `preset=ci` settings, one subject)."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

import defaust.build as build_mod
from defaust.build import build_defaust
from defaust.cli import compose_config, config_from_omegaconf
from defaust.dataset import load_handles
from defaust.handles import snap_handles
from defaust.store import sha256_file
from eval.datasets.defaust_dataset import DefaustOptions, load_defaust
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh
from sshade.mesh.validate import validate_mesh

from .conftest import ROOT, subprocess_env  # noqa: E402

POSES = [1, 2, 3, 4]


def _build(out, *extra):
    src = [] if any(str(e).startswith("source=") for e in extra) else ["source=synthetic"]  # not the default (anny)
    cfg = compose_config(["preset=ci", f"out={out}", "n_subjects=1", "progress=false", *src, *extra])
    return build_defaust(config_from_omegaconf(cfg))


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("defaust_a")
    return out, _build(out)


def _mtimes(out: Path) -> dict:
    return {str(p.relative_to(out)): p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}


def test_layout_manifest_and_meshes(built):
    out, rep = built
    items = ["subject_00/rest"] + [f"subject_00/pose_{p:02d}" for p in POSES]
    assert rep.built == items and rep.skipped == []
    m = json.loads((out / "manifest.json").read_text())
    assert m["source"] == "synthetic" and m["parameters"]["seed"] == 0
    assert m["parameters"]["vertex_range"] == [8000, 12000]
    assert m["packages"]["numpy"] and m["packages"]["pymeshlab"]
    want = {"subject_00/rest_low.ply", "subject_00/rest_high.ply"}
    for p in POSES:
        want |= {f"subject_00/pose_{p:02d}_{k}" for k in ("handles.npz", "low.ply", "high.ply")}
    assert set(m["files"]) == want
    for rel, h in m["files"].items():
        assert sha256_file(out / rel) == h
    assert not list(out.rglob("*.tmp"))
    Vl, Fl = read_mesh(out / "subject_00/rest_low.ply")
    Vh, Fh = read_mesh(out / "subject_00/rest_high.ply")
    assert 8000 <= len(Vh) <= 12000 and len(Vh) > 2 * len(Vl)
    validate_mesh(Vh, Fh, allow_boundary=False)
    assert trimesh.Trimesh(Vh, Fh, process=False).is_watertight
    for p in POSES:  # ground truth poses share the rest meshes' faces
        Vp, Fp = read_mesh(out / f"subject_00/pose_{p:02d}_low.ply")
        np.testing.assert_array_equal(Fp, Fl)
        Vq, Fq = read_mesh(out / f"subject_00/pose_{p:02d}_high.ply")
        np.testing.assert_array_equal(Fq, Fh)
    # the last target uses more landmarks (paper appendix)
    n_lm = [len(load_handles(out / f"subject_00/pose_{p:02d}_handles.npz").landmark_names) for p in POSES]
    assert n_lm[:-1] == [6, 6, 6] and n_lm[-1] == 11


def test_two_builds_are_byte_identical(built, tmp_path):
    out, _ = built
    _build(tmp_path)
    a = json.loads((out / "manifest.json").read_text())
    b = json.loads((tmp_path / "manifest.json").read_text())
    assert a["files"] == b["files"]
    assert (out / "manifest.json").read_bytes() == (tmp_path / "manifest.json").read_bytes()


def test_resume_skips_finished_and_rebuilds_damaged(built, tmp_path):
    src, _ = built
    out = tmp_path / "copy"
    shutil.copytree(src, out)
    before = _mtimes(out)
    rep = _build(out)
    assert rep.built == [] and len(rep.skipped) == 5
    assert _mtimes(out) == before  # nothing rewritten, not even the manifest's content
    # corrupt one file, delete another: exactly their items are rebuilt
    (out / "subject_00/pose_02_handles.npz").write_bytes(b"garbage")
    (out / "subject_00/pose_03_high.ply").unlink()
    rep = _build(out)
    assert rep.built == ["subject_00/pose_02", "subject_00/pose_03"]
    ref = json.loads((src / "manifest.json").read_text())["files"]
    for rel, h in ref.items():
        assert sha256_file(out / rel) == h, rel
    after = _mtimes(out)
    untouched = [k for k in before if "pose_02" not in k and "pose_03" not in k and k != "manifest.json"]
    assert all(after[k] == before[k] for k in untouched)
    # other parameters: the folder holds another dataset, which is never overwritten
    after = _mtimes(out)
    with pytest.raises(SShaDeError, match=r"static_threshold: 0.02 there, 0.05 asked"):
        _build(out, "handles.static_threshold=0.05")
    assert _mtimes(out) == after


def test_interrupted_build_resumes(built, tmp_path, monkeypatch):
    src, _ = built
    real = build_mod._build_pose
    calls = {"n": 0}

    def flaky(*a, **k):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt("simulated interruption")
        return real(*a, **k)

    monkeypatch.setattr(build_mod, "_build_pose", flaky)
    with pytest.raises(KeyboardInterrupt):
        _build(tmp_path)
    m = json.loads((tmp_path / "manifest.json").read_text())
    assert sorted(m["items"]) == ["subject_00/pose_01", "subject_00/pose_02", "subject_00/rest"]
    assert not list(tmp_path.rglob("*.tmp"))
    monkeypatch.setattr(build_mod, "_build_pose", real)
    rep = _build(tmp_path)
    assert rep.built == ["subject_00/pose_03", "subject_00/pose_04"]
    assert (tmp_path / "manifest.json").read_bytes() == (src / "manifest.json").read_bytes()


def test_handles_snap_to_the_right_vertices_after_remeshing(built):
    out, _ = built
    Vl, Fl = read_mesh(out / "subject_00/rest_low.ply")
    Vh, Fh = read_mesh(out / "subject_00/rest_high.ply")
    E = np.concatenate([Fh[:, [0, 1]], Fh[:, [1, 2]], Fh[:, [2, 0]]])
    edge = float(np.linalg.norm(Vh[E[:, 0]] - Vh[E[:, 1]], axis=1).mean())
    for p in POSES:
        H = load_handles(out / f"subject_00/pose_{p:02d}_handles.npz")
        # stored rest positions are exactly the low-res vertices they were drawn on
        np.testing.assert_array_equal(H.rest, Vl[H.index])
        s = snap_handles(Vl, H.rest)
        np.testing.assert_array_equal(s.index, H.index)
        assert s.distance.max() == 0
        # on the remeshed high-res surface they land on a vertex within about an edge
        s = snap_handles(Vh, H.rest)
        assert s.distance.max() < edge
        assert s.n_dropped <= 0.02 * len(H)
        # ... which is the right one: its true (skinned) target position is next to the
        # stored target (for dynamic handles the whole body part moved)
        Vg, _ = read_mesh(out / f"subject_00/pose_{p:02d}_high.ply")
        dyn = ~H.static[s.keep]
        err = np.linalg.norm(Vg[s.index[dyn]] - H.target[s.keep][dyn], axis=1)
        assert err.max() < 2 * edge, (p, err.max(), edge)


def test_loader(built):
    out, _ = built
    hi = load_defaust(out)
    assert [c.name for c in hi] == [f"s00_p{p:02d}" for p in POSES]
    c = hi[1]
    assert c.resolution == "high" and c.pose_name == "knees_bent" and c.V_gt.shape == c.V.shape
    assert c.handles.dtype == np.int64 and len(np.unique(c.handles)) == len(c.handles)
    assert c.targets.shape == (len(c.handles), 3) and c.static.shape == (len(c.handles),)
    np.testing.assert_array_equal(c.targets[c.static], c.V[c.handles[c.static]])  # static = in place
    lo = load_defaust(out, DefaustOptions(resolution="low", limit=2))
    assert len(lo) == 2 and lo[0].n_dropped == 0
    H = load_handles(out / "subject_00/pose_01_handles.npz")
    np.testing.assert_array_equal(lo[0].targets, H.target)
    np.testing.assert_array_equal(lo[0].handles, H.index)
    with pytest.raises(SShaDeError, match="not in"):
        load_defaust(out, DefaustOptions(subjects=[7]))


def test_loader_detects_corruption(built, tmp_path):
    src, _ = built
    out = tmp_path / "c"
    shutil.copytree(src, out)
    p = out / "subject_00/rest_high.ply"
    b = bytearray(p.read_bytes())
    b[-5] ^= 0xFF
    p.write_bytes(bytes(b))
    with pytest.raises(SShaDeError, match="checksum"):
        load_defaust(out)
    with pytest.raises(SShaDeError, match="manifest"):
        load_defaust(tmp_path)


def test_bad_input_messages(tmp_path):
    with pytest.raises(SShaDeError, match=re.escape(str(tmp_path / "nope"))):
        _build(tmp_path / "o", "source=faust", f"faust.root={tmp_path / 'nope'}")
    (tmp_path / "empty").mkdir()
    with pytest.raises(SShaDeError, match="no FAUST registrations"):
        _build(tmp_path / "o", "source=faust", f"faust.root={tmp_path / 'empty'}")
    with pytest.raises(SShaDeError, match="faust.root"):
        config_from_omegaconf(compose_config(["source=faust", f"out={tmp_path}"]))
    with pytest.raises(SShaDeError, match="unknown source"):
        config_from_omegaconf(compose_config(["source=scan", f"out={tmp_path}"]))
    r = subprocess.run([sys.executable, "-m", "defaust"], cwd=ROOT, env=subprocess_env(), capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and "out=DIR" in r.stderr


@pytest.mark.slow
@pytest.mark.parametrize("point", ["first pose", "third pose", "before the manifest"])
def test_a_build_killed_at_three_points_is_partial_to_load_and_verify_and_the_same_command_finishes_it(
        built, tmp_path, monkeypatch, point):
    from defaust.dataset import load, verify
    src, _ = built
    real_pose, real_merge = build_mod._build_pose, build_mod._merge
    calls = {"n": 0}

    def pose(*a, **k):
        calls["n"] += 1
        if point != "before the manifest" and calls["n"] == {"first pose": 1, "third pose": 3}[point]:
            raise KeyboardInterrupt("simulated kill")
        return real_pose(*a, **k)

    def merge(*a, **k):
        raise KeyboardInterrupt("simulated kill")

    monkeypatch.setattr(build_mod, "_build_pose", pose)
    if point == "before the manifest":
        monkeypatch.setattr(build_mod, "_merge", merge)
    with pytest.raises(KeyboardInterrupt):
        _build(tmp_path)
    with pytest.raises(SShaDeError, match=r"a partial DeFAUST build \(subject\(s\) 0 of 1 not finished; 0 complete\)"
                                          r".* Run the command that built it again") as e:
        load(tmp_path)
    assert "\n" not in str(e.value)
    problems = verify(tmp_path)
    assert problems and "a partial DeFAUST build" in problems[0]
    with pytest.raises(SShaDeError, match="no DeFAUST case"):  # partial=True: only complete subjects, none here
        load(tmp_path, partial=True)
    monkeypatch.setattr(build_mod, "_build_pose", real_pose)
    monkeypatch.setattr(build_mod, "_merge", real_merge)
    _build(tmp_path)  # the same command
    assert verify(tmp_path) == [] and len(load(tmp_path)) == len(POSES)
    assert (tmp_path / "manifest.json").read_bytes() == (src / "manifest.json").read_bytes()


# ----------------------------------------------------------------------------- resolutions


def test_an_extra_resolution_is_a_remesh_with_its_own_ground_truth(built, tmp_path, monkeypatch):
    """``resolutions=[high, 2000]``: ``rest_r2000.ply`` has 2000 vertices within 5 % and
    its ground truth shares its faces; the skinning at r2000 agrees with the high-res one
    (each r2000 vertex moves as the nearest high-res rest vertex does, within a few mm);
    ``load`` reads it as ``r2000`` and its rest/pose files are the only new ones."""
    from scipy.spatial import cKDTree

    import defaust
    out = tmp_path / "r"
    rep = _build(out, "resolutions=[high,2000]")
    m = json.loads((out / "manifest.json").read_text())
    assert m["parameters"]["resolutions"] == ["high", 2000]
    base = json.loads((built[0] / "manifest.json").read_text())
    extra = {f for f in m["files"] if "_r2000" in f}
    assert set(m["files"]) - extra == set(base["files"])
    assert extra == {"subject_00/rest_r2000.ply"} | {f"subject_00/pose_{p:02d}_r2000.ply" for p in POSES}
    info = m["items"]["subject_00/rest"]["info"]["resolutions"]["r2000"]
    assert 1900 <= info["n_vertices"] <= 2100 and rep.built[0] == "subject_00/rest"
    hi, r = defaust.load(out, resolution="high"), defaust.load(out, resolution="r2000")
    assert len(r) == len(hi) == 4
    for ch, cr in zip(hi, r):
        assert len(cr.V) == info["n_vertices"] and cr.V_gt.shape == cr.V.shape
        d, j = cKDTree(ch.V).query(cr.V)
        move_r, move_h = cr.V_gt - cr.V, ch.V_gt[j] - ch.V[j]
        assert np.median(np.linalg.norm(move_r - move_h, axis=1)) < 0.003  # metres
        assert len(cr.handles) > 0
    with pytest.raises(SShaDeError, match="no resolution 'r7000'; it has low, high, r2000"):
        defaust.load(out, resolution="r7000")

    # a handle farther from the coarse mesh than the tolerance is dropped and counted at rN,
    # refused when the caller gives the tolerance (as at high and low)
    import defaust.dataset as ds_mod
    with pytest.raises(SShaDeError, match="off the surface"):
        defaust.load(out, resolution="r2000", tol=1e-4, eager=True)
    base = [c.n_dropped for c in defaust.load(out, resolution="r2000")]
    orig, tight = ds_mod.CaseReader._tol, {}

    def tol(self, V, F):
        tight["tol"] = 0.3 * orig(self, V, F)
        return tight["tol"]
    monkeypatch.setattr(ds_mod.CaseReader, "_tol", tol)
    for c, b in zip(defaust.load(out, resolution="r2000"), base):
        assert c.n_dropped > b and np.all(c.snap_distance <= tight["tol"])


def test_resolutions_without_high_build_no_high_res_mesh(tmp_path):
    import defaust
    out = tmp_path / "nohigh"
    _build(out, "resolutions=[1500]")
    m = json.loads((out / "manifest.json").read_text())
    assert not [f for f in m["files"] if "_high" in f]
    assert "n_vertices_high" not in m["items"]["subject_00/rest"]["info"]
    assert len(defaust.load(out, resolution="r1500")) == 4
    with pytest.raises(SShaDeError, match="no resolution 'high'; it has low, r1500: choose one .*--resolution"):
        defaust.load(out)


@pytest.mark.parametrize("value,word", [("[]", "non-empty"), ("[high,high]", "repeats"), ("[100]", "resolutions"),
                                        ("[2000,2000]", "repeats"), ("[abc]", "resolutions")])
def test_bad_resolutions_are_refused_before_any_work(tmp_path, value, word):
    cfg = compose_config(["preset=ci", f"out={tmp_path / 'x'}", f"resolutions={value}"])
    with pytest.raises(SShaDeError, match=word):
        config_from_omegaconf(cfg).validate()
    assert not (tmp_path / "x").exists()


# ----------------------------------------------------------------------------- a job array


def _task_pids(folder: Path) -> list[int]:
    """PIDs of the submitit task processes whose job folder lies under ``folder``."""
    out = []
    for proc in Path("/proc").iterdir():
        try:
            cmd = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"submitit.core._submit" in cmd and any(str(folder).encode() in c for c in cmd):
            out.append(int(proc.name))
    return out


@pytest.mark.slow
def test_an_array_build_with_a_task_killed_resumes_to_the_local_builds_bytes(tmp_path):
    """``cluster=slurm cluster.executor=local`` (submitit's local executor: the array path
    without SLURM; .ci/slurm_build.sh runs it on SLURM): one task killed (SIGKILL) while
    it builds: the command exits 2 naming the subject, the manifest is partial and loads
    refuse it; the same command builds only that subject, and the build's manifest (every
    checksum) equals a local build's byte for byte."""
    import signal
    import time

    import defaust
    local, arr = tmp_path / "local", tmp_path / "arr"
    _build(local, "n_subjects=3", "workers=1")
    cmd = [sys.executable, "-m", "defaust", "source=synthetic", "preset=ci", f"out={arr}", "n_subjects=3",
           "progress=false", "cluster=slurm", "cluster.executor=local", "cluster.poll_s=0.2"]
    p = subprocess.Popen(cmd, cwd=ROOT, env=subprocess_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True)
    killed, t_end = None, time.monotonic() + 120
    while killed is None and p.poll() is None and time.monotonic() < t_end:
        pids = _task_pids(tmp_path / "arr_slurm")
        if pids:
            time.sleep(0.5)  # inside its subject's work
            os.kill(pids[0], signal.SIGKILL)
            killed = pids[0]
        time.sleep(0.05)
    out, _ = p.communicate(timeout=300)
    assert killed is not None and p.returncode == 2, out
    assert "1 subject(s) not built" in out and "run the same command again" in out
    m = json.loads((arr / "manifest.json").read_text())
    assert m["complete"] is False and len(m["subjects"]) == 2
    with pytest.raises(SShaDeError, match="partial"):
        defaust.load(arr)
    again = subprocess.run(cmd, cwd=ROOT, env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stdout + again.stderr
    assert "5 item(s) built, 10 skipped" in again.stdout + again.stderr
    assert (arr / "manifest.json").read_bytes() == (local / "manifest.json").read_bytes()
    assert defaust.verify(arr) == []


def test_a_subset_build_keeps_the_folders_other_subjects(tmp_path):
    """``subjects=[1]`` on a complete 2-subject build: subject 0 stays listed (it was being
    dropped from the manifest, its files left unlisted), and the manifest is the full
    build's byte for byte."""
    import defaust
    out = tmp_path / "b"
    _build(out, "n_subjects=2", "workers=1")
    before = (out / "manifest.json").read_bytes()
    rep = _build(out, "n_subjects=2", "subjects=[1]", "workers=1")
    assert rep.built == [] and (out / "manifest.json").read_bytes() == before
    assert defaust.verify(out) == [] and len(defaust.load(out)) == 8


def test_an_array_build_refuses_a_logs_folder_that_is_not_its_own(tmp_path):
    """``OUT_slurm`` beside the build holding other files, or being a link, is refused
    before anything is submitted or built."""
    out = tmp_path / "b"
    (tmp_path / "b_slurm").mkdir()
    (tmp_path / "b_slurm" / "notes.txt").write_text("mine")
    with pytest.raises(SShaDeError, match="holds notes.txt"):
        _build(out, "cluster=slurm", "cluster.executor=local")
    assert (tmp_path / "b_slurm" / "notes.txt").read_text() == "mine" and not (out / "subject_00").exists()


@pytest.mark.parametrize("subjects, why", [("[]", ": none"), ("[0,0]", ": 0 more than once")])
def test_subjects_naming_no_subject_or_one_twice_are_refused_before_any_file(tmp_path, subjects, why):
    out = tmp_path / "b"
    with pytest.raises(SShaDeError, match=f"subjects must name each subject to build once.*{why}"):
        _build(out, f"subjects={subjects}")
    assert not out.exists() or not any(out.iterdir())


def _edit_manifest(out: Path, edit) -> None:
    m = json.loads((out / "manifest.json").read_text())
    edit(m)
    (out / "manifest.json").write_text(json.dumps(m))
    for name in ("croissant.json", "datasheet.md"):  # they hold the manifest's digest: gone with it
        (out / name).unlink(missing_ok=True)


def test_a_manifest_that_contradicts_itself_is_refused_by_verify_and_load(tmp_path):
    """A 1-subject build whose manifest loses parameters.subjects and claims
    planned_subjects=[0, 1] of n_subjects=2; a pose's ground truth deleted with its
    entries: ``verify`` names each, ``load`` refuses (it loaded them as whole)."""
    from defaust.dataset import load, verify
    out = tmp_path / "one"
    _build(out, "n_subjects=2", "subjects=[0]")
    assert verify(out) == []

    def widen(m):
        m["parameters"].pop("subjects", None)
        m["planned_subjects"] = [0, 1]
    _edit_manifest(out, widen)
    problems = verify(out)
    assert any("holding subject(s) [0], but its parameters name [0, 1]" in p for p in problems), problems
    with pytest.raises(SShaDeError, match="an edited or cut manifest"):
        load(out)
    out2 = tmp_path / "gt"
    _build(out2)
    gt = "subject_00/pose_01_high.ply"
    (out2 / gt).unlink()

    def cut(m):
        m["files"].pop(gt)
        m["items"]["subject_00/pose_01"]["files"].pop(gt)
    _edit_manifest(out2, cut)
    assert any("item subject_00/pose_01 lacks _high.ply" in p for p in verify(out2))
    with pytest.raises(SShaDeError, match="lacks _high.ply, which every other pose item holds"):
        load(out2)

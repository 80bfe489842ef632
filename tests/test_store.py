"""The evaluator's per-(case, method) result store (eval/run/result_store.py), resume after
a kill -9, a method added later, a record restored where the same data is read from
another folder, the baseline subset rule (eval/run/subset.py) and the
cost-weighted progress estimate (eval/run/progress.py)."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from eval.reproduce import main as reproduce_main
from eval.run.result_store import ResultStore, case_identity, pair_key
from eval.run.runinfo import machine_info
from eval.run.subset import baseline_selection, check_baseline_cases
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env
from .store_methods import kill_at_call

PLUGIN = "{_target_:tests.store_methods.Counted,name:%s}"
TIME_COLUMNS = ("time_s", "compile_s")


def _case(name="c", seed=0):
    rng = np.random.default_rng(seed)
    return SimpleNamespace(name=name, seed=seed, V=rng.random((5, 3)), F=np.array([[0, 1, 2]]),
                           handles=np.array([0, 1]), targets=rng.random((2, 3)))


# ----------------------------------------------------------------------------- store, unit
def test_store_keys_round_trip_and_clear(tmp_path):
    c = _case()
    ident = case_identity(c, dataset="faust", seed=0)
    k1, f1 = pair_key({"_target_": "x.A", "tol": 1e-4}, ident, {"guard": {"timeout_s": None}})
    assert k1 == pair_key({"tol": 1e-4, "_target_": "x.A"}, dict(ident), {"guard": {"timeout_s": None}})[0]
    assert k1 != pair_key({"_target_": "x.A", "tol": 1e-3}, ident)[0]  # another parameter: another key
    c2 = _case()
    c2.targets = c2.targets + 1e-9  # another handle target: another case
    assert k1 != pair_key({"_target_": "x.A", "tol": 1e-4}, case_identity(c2, dataset="faust", seed=0),
                          {"guard": {"timeout_s": None}})[0]
    st = ResultStore(tmp_path, meshes=True)
    row = {"case": "c/1", "method": "SShaDe+refine", "volume_err_pct": float("nan"), "n": np.int64(3), "error": "",
           "time_s": 1.5}
    p = st.save("c/1", "SShaDe+refine", k1, f1, row, {"per": [{"a": np.float32(1.5)}]}, np.ones((5, 3)))
    assert p == tmp_path / "runs" / "c_1" / "SShaDe+refine.json"
    rec = st.load("c/1", "SShaDe+refine", k1)
    assert rec["row"] == {"case": "c/1", "method": "SShaDe+refine", "volume_err_pct": None, "n": 3, "error": "",
                          "time_s": 1.5}
    assert rec["info"] == {"per": [{"a": 1.5}]} and np.array_equal(st.load_mesh(rec, 5), np.ones((5, 3)))
    assert rec["machine"] == machine_info()  # which machine made the row, beside the commit
    assert st.load("c/1", "SShaDe+refine", "other") is None  # stale key
    assert st.load("c/1", "ARAP", k1) is None
    (tmp_path / "runs" / "c_1" / "notes.txt").write_text("mine")
    assert st.clear() == 1
    assert sorted(p.name for p in (tmp_path / "runs" / "c_1").iterdir()) == ["notes.txt"]  # not a record: kept
    assert not list(tmp_path.glob("*.tmp")) and not list((tmp_path / "runs").rglob("*.tmp"))


def test_a_record_holds_its_output_digest_and_names_a_replaced_record_with_the_same_bytes(tmp_path):
    """Each record holds the sha256 of its output vertices; one that replaces a record of
    another key with the very same bytes says so (its commit and key), any other does not;
    the extra fields are covered by the record's digest (an edit makes it invalid)."""
    from eval.run.result_store import output_digest
    st = ResultStore(tmp_path)
    row = {"case": "c", "method": "A", "error": "", "time_s": 1.0}
    U = np.arange(15, dtype=np.float64).reshape(5, 3)
    (k1, f1), (k2, f2), (k3, f3) = (pair_key({"_target_": "x.A", "tol": t}, {"case": "c"}) for t in (1, 2, 3))
    st.save("c", "A", k1, f1, row, {}, U, git={"commit": "a" * 40, "dirty": False})
    first = st.load("c", "A", k1)
    assert first["output"] == output_digest(U) == output_digest(np.asfortranarray(U)) and "same_output_as" not in first
    st.save("c", "A", k2, f2, row, {}, U.copy())
    second = st.load("c", "A", k2)
    assert second["same_output_as"] == {"commit": "a" * 40, "key": k1}
    st.save("c", "A", k2, f2, row, {}, U)  # the same key again: not a reproduction of other code
    assert "same_output_as" not in st.load("c", "A", k2)
    U2 = U.copy()
    U2[0, 0] = np.nextafter(U2[0, 0], 1.0)
    st.save("c", "A", k3, f3, row, {}, U2)
    assert "same_output_as" not in st.load("c", "A", k3) and output_digest(U2) != output_digest(U)
    p = st.path("c", "A")
    rec = json.loads(p.read_text())
    rec["output"] = output_digest(U)
    p.write_text(json.dumps(rec))
    assert st.read("c", "A").why.startswith("invalid: edited")


def test_a_stored_mesh_is_read_only_when_it_is_the_records_output_and_never_from_a_fifo(tmp_path):
    """``load_mesh`` reads a mesh as untrusted input: an edited mesh (scaled), a header
    of another vertex count, a sparse giant that its header calls (89478485, 3), and a
    FIFO put in its place give None, without blocking and without reading the giant."""
    import os
    st = ResultStore(tmp_path, meshes=True)
    U = np.arange(15, dtype=np.float64).reshape(5, 3)
    k, f = pair_key({"_target_": "x.A"}, {"case": "c"})
    st.save("c", "A", k, f, {"case": "c", "method": "A", "error": "", "time_s": 1.0}, {}, U)
    rec = st.load("c", "A", k)
    mesh = st.path("c", "A").with_suffix(".npy")
    assert np.array_equal(st.load_mesh(rec, 5), U) and st.load_mesh(rec, 6) is None
    np.save(mesh, 3 * U)  # edited: a valid array, not the output the record names
    assert st.load_mesh(rec, 5) is None
    giant = np.lib.format.open_memmap(tmp_path / "g.npy", mode="w+", dtype="<f8", shape=(89478485, 3))
    del giant  # a sparse file of 2 GB
    os.replace(tmp_path / "g.npy", mesh)
    assert st.load_mesh(rec, 5) is None
    mesh.unlink()
    os.mkfifo(mesh)
    assert st.load_mesh(rec, 5) is None  # returns at once: the FIFO is never read


def test_the_static_handles_and_groups_are_part_of_a_case_and_an_earlier_record_is_matched_without_them(tmp_path):
    """What a case-aware method is told besides the arrays (which handles are static, their
    groups) is part of the case's key, so a loader that changes them makes other rows; a
    record stored before they were keyed (its case identity lacks them) is found when it
    agrees on all it holds, and stale when it does not."""
    from eval.run.result_store import LATER_CASE_FIELDS
    c = _case()
    c.static, c.group = np.array([True, False]), np.array([0, 1])
    ident = case_identity(c, dataset="faust", seed=0)
    method, extra, code = {"_target_": "x.A"}, {"guard": {"timeout_s": None}}, {"sources": "s", "plugin": None}
    key, fields = pair_key(method, ident, extra, code)
    for change in ({"static": np.array([False, False])}, {"group": np.array([0, 0])}, {"group": None}):
        other = SimpleNamespace(**{**vars(c), **change})
        assert pair_key(method, case_identity(other, dataset="faust", seed=0), extra, code)[0] != key
    st = ResultStore(tmp_path)
    row = {"case": "c", "method": "A", "error": "", "time_s": 1.0}
    earlier = {k: v for k, v in ident.items() if k not in LATER_CASE_FIELDS}
    st.save("c", "A", *pair_key(method, earlier, extra, code), row, {})
    found = st.lookup("c", "A", key, fields)
    assert found.why is None and found.record["key_fields"]["case"] == earlier  # kept as stored
    moved = SimpleNamespace(**{**vars(c), "targets": c.targets + 1.0})
    key2, fields2 = pair_key(method, case_identity(moved, dataset="faust", seed=0), extra, code)
    assert st.lookup("c", "A", key2, fields2).why == "other settings: case data"
    st.save("c", "A", key, fields, row, {})  # stored now: keyed with them
    other = SimpleNamespace(**{**vars(c), "static": np.array([False, False])})
    key3, fields3 = pair_key(method, case_identity(other, dataset="faust", seed=0), extra, code)
    assert st.lookup("c", "A", key3, fields3).why == "other settings: case data"


# ----------------------------------------------------------------------------- subset rule
def test_baseline_subset_rules():
    cases = [SimpleNamespace(subject=s, pose=p) for s in range(10) for p in (1, 2, 3, 4)]  # DeFAUST: 40
    sel, rule = baseline_selection(cases, "per_pose")
    picked = sorted((cases[i].subject, cases[i].pose) for i in sel)
    assert picked == [(0, 1), (1, 2), (2, 3), (3, 4)]  # pose p from subject (p - 1) mod 10
    assert "per_pose" in rule and "4 cases" in rule
    assert baseline_selection(cases, 2) == ({0, 1}, "the first 2 case(s)")
    assert baseline_selection(cases, "all")[0] is None and baseline_selection(cases, None)[0] is None
    # a limited set (subject 0 only): every pose still from some subject that has it
    sel, _ = baseline_selection(cases[:4], "per_pose")
    assert sorted(cases[i].pose for i in sel) == [1, 2, 3, 4]
    # subjects 0-1 only: pose p_j from subject j mod 2
    two = [c for c in cases if c.subject < 2]
    assert sorted((two[i].subject, two[i].pose) for i in baseline_selection(two, "per_pose")[0]) == \
        [(0, 1), (0, 3), (1, 2), (1, 4)]
    for bad in ("abc", -1, True, 1.5):
        with pytest.raises(SShaDeError, match="baseline_cases"):
            check_baseline_cases(bad)


def test_defaust_default_is_per_pose(capsys):
    from omegaconf import OmegaConf
    assert OmegaConf.load(ROOT / "conf" / "dataset" / "defaust.yaml").baseline_cases == "per_pose"
    assert reproduce_main(["--dry-run", "--any-machine", "--only", "defaust,defaust_paper"]) == 0
    lines = {ln.split(":")[0]: ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("== ")}
    for step in ("== defaust", "== defaust_paper"):  # every method on all 40 DeFAUST cases
        assert "dataset.baseline_cases=all" in lines[step] and "dataset.limit" not in lines[step]
    # the main job's references: none on DeFAUST (its deep solves would add ~30 min; the
    # reproduce run computes them on the per_pose cases), the baseline cases elsewhere
    from hydra import compose, initialize_config_dir

    import eval.app  # noqa: F401 -- stores every typed schema the config names, as python -m eval does
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base=None):
        assert compose("config").reference.cases == "none"
        assert compose("config", overrides=["dataset=faust"]).reference.cases == "baseline"
        assert compose("config", overrides=["reference.cases=2"]).reference.cases == 2
    assert "reference.cases=per_pose" in lines["== defaust"]


# ----------------------------------------------------------------------------- resume after kill -9
def _eval(out, methods, *extra, env=None, popen=False):
    items = ",".join(m if "{" in m else PLUGIN % m for m in methods)
    cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={out.parent / 'faust'}",
           "dataset.limit=2", "reference.cases=none", f"methods=[{items}]",
           f"out_dir={out}", *extra]
    kw = dict(cwd=ROOT, env=dict(subprocess_env(), **(env or {})), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
              text=True)
    if popen:
        return subprocess.Popen(cmd, **kw)
    r = subprocess.run(cmd, timeout=600, **kw)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def _snapshot(out):
    return {str(p.relative_to(out)): (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted((out / "runs").rglob("*"))
            if p.is_file()}


def _no_time(md: str) -> str:
    """table.md without its Time column (the only cells a rerun may change)."""
    out, drop = [], None
    for line in md.splitlines():
        cells = line.split("|")
        if line.startswith("| Method"):
            drop = [i for i, c in enumerate(cells) if "Time" in c]
        if drop and line.startswith("|"):
            cells = [c for i, c in enumerate(cells) if i not in drop]
        out.append("|".join(cells))
    return "\n".join(out)


def _counts(path):
    return pd.Series([ln.split()[1] for ln in path.read_text().splitlines()]).value_counts().to_dict() \
        if path.exists() else {}


@pytest.mark.slow
def test_resume_after_kill_runs_only_missing_pairs(tmp_path, faust_root):
    (tmp_path / "faust").symlink_to(faust_root)
    out, full = tmp_path / "out", tmp_path / "full"
    counter = tmp_path / "calls.txt"
    # 1. killed (SIGKILL) while its third pair runs: two pairs (s0_p1 A and B) are stored
    p = _eval(out, ["A", "B"], env={"SSHADE_TEST_COUNTER": str(counter), "SSHADE_TEST_HANG_AFTER": "2"}, popen=True)
    kill_at_call(p, counter, 3)
    assert sorted(x.name for x in (out / "runs").rglob("*.json")) == ["A.json", "B.json"]
    before = _snapshot(out)
    counter.unlink()
    # 2. resume: the earlier run's files are kept, only the two missing pairs run
    r = _eval(out, ["A", "B"], "resume=true", env={"SSHADE_TEST_COUNTER": str(counter)})
    assert "continuing the earlier eval output" in r.stdout + r.stderr
    assert _counts(counter) == {"A": 1, "B": 1}
    after = _snapshot(out)
    assert all(after[k] == v for k, v in before.items())  # same bytes, same mtime: not recomputed
    assert len(after) == 4
    # 3. the tables equal an uninterrupted run's (time columns excluded)
    _eval(full, ["A", "B"])
    a, b = pd.read_csv(out / "cases.csv"), pd.read_csv(full / "cases.csv")
    pd.testing.assert_frame_equal(a.drop(columns=list(TIME_COLUMNS)), b.drop(columns=list(TIME_COLUMNS)))
    assert _no_time((out / "table.md").read_text()) == _no_time((full / "table.md").read_text())
    assert (out / "breakdown.md").read_text() == (full / "breakdown.md").read_text()
    assert json.loads((out / "run.json").read_text())["status"] == "done"
    # 4. a method added later runs only its own cases; a changed parameter reruns that method
    counter.unlink()
    _eval(out, ["A", "B", "C"], "resume=true", env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {"C": 2}
    assert len(pd.read_csv(out / "cases.csv")) == 6
    counter.unlink()
    _eval(out, ["{_target_:tests.store_methods.Counted,name:A,iterations:5}"], "resume=true",
          env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {"A": 2}
    # 5. without resume the store starts empty: everything runs again
    counter.unlink()
    _eval(out, ["A", "B"], env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {"A": 2, "B": 2}
    assert sorted(str(p.relative_to(out)) for p in (out / "runs").rglob("*.json")) == \
        ["runs/s0_p1/A.json", "runs/s0_p1/B.json", "runs/s0_p2/A.json", "runs/s0_p2/B.json"]


@pytest.mark.slow
def test_the_same_data_read_from_another_folder_restores_and_other_data_recomputes(tmp_path, faust_root):
    (tmp_path / "faust").symlink_to(faust_root)
    out, counter = tmp_path / "out", tmp_path / "calls.txt"
    _eval(out, ["A"], env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {"A": 2}
    # a clean checkout elsewhere: the run folder and a copy of the data under another root
    there = tmp_path / "elsewhere"
    shutil.copytree(out, there / "out")
    (there / "faust").mkdir()
    for f in faust_root.glob("*.ply"):
        shutil.copyfile(f, there / "faust" / f.name)
    before = _snapshot(there / "out")
    counter.unlink()
    r = _eval(there / "out", ["A"], "resume=true", env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {} and "2 run(s) restored" in r.stdout + r.stderr
    assert _snapshot(there / "out") == before  # the records as they were: restored, not rewritten
    # other data under that root (another rest mesh): recomputed, whatever the folder
    shutil.copyfile(faust_root / "tr_reg_010.ply", there / "faust" / "tr_reg_000.ply")
    _eval(there / "out", ["A"], "resume=true", env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {"A": 2}

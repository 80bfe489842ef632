"""eval/run/stale_rows.py: which committed rows are stale, and re-keying records of the
earlier key layout from the commit that made them, never recomputing them.

A record of store version 3 (from git's history of results/faust) re-keyed here keeps its
row bit for bit and becomes current; an edited, dirty, unknown-commit or wrong-identity
record is refused; an edit of SShaDe's transfer makes ``--check --json`` report SShaDe's
rows stale and no baseline's.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys

import pytest

from eval.run.code_identity import PACKAGES
from eval.run.result_store import STORE_VERSION, ResultStore, pair_key, record_digest
from eval.run.stale_rows import REKEY_FROM, CommitTrees, check_folders, rekey_record, row_state, run_folders

from .conftest import ROOT, edit_syntax_tree, subprocess_env

#: a commit whose results/faust records are of store version 3, made by 3e79476's code
OLD = "8d866e5"
OLD_RECORD = "results/faust/runs/s0_p1/{}.json"


def _git_show(rev: str, path: str) -> str:
    r = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"], capture_output=True, text=True,
                       timeout=60, check=False)
    if r.returncode != 0:
        pytest.skip(f"git history without {rev}:{path} (a shallow clone?)")
    return r.stdout


def _old_store(tmp_path, *methods):
    """A run folder holding results/faust's s0_p1 records of ``methods`` as committed at :data:`OLD`."""
    out = tmp_path / "run"
    (out / "runs" / "s0_p1").mkdir(parents=True)
    for m in methods:
        (out / "runs" / "s0_p1" / f"{m}.json").write_text(_git_show(OLD, OLD_RECORD.format(m)))
    return out


def test_rekey_keeps_the_row_and_makes_an_earlier_record_current(tmp_path):
    """ARAP's and SShaDe's s0_p1 records of 3e79476 re-keyed: rows kept bit for bit, keys
    their new key fields' digests, the data folder out of the case identity; ARAP's is
    current (its code is the same at this checkout); SShaDe's new identity is computed from
    its own commit's sources, so it is stale since SShaDe's transfer changed after it."""
    out = _old_store(tmp_path, "ARAP", "SShaDe")
    before = {m: json.loads((out / "runs" / "s0_p1" / f"{m}.json").read_text()) for m in ("ARAP", "SShaDe")}
    assert {r["version"] for r in before.values()} == {REKEY_FROM}
    with CommitTrees() as trees:
        assert {m: rekey_record(out, out / "runs" / "s0_p1" / f"{m}.json", trees) for m in before} == \
            {"ARAP": "rekeyed", "SShaDe": "rekeyed"}
        for m, old in before.items():
            found = ResultStore(out).read("s0_p1", m)
            rec = found.record
            assert found.why is None and rec["version"] == STORE_VERSION
            assert rec["row"] == old["row"] and rec["info"] == old["info"] and rec["git"] == old["git"]
            assert "root" not in rec["key_fields"]["case"]  # the data folder is no part of the key any more
            assert pair_key(rec["key_fields"]["method"], rec["key_fields"]["case"], rec["key_fields"]["extra"],
                            rec["key_fields"]["code"])[0] == rec["key"]
            assert rec["rekeyed"] == {"from_version": REKEY_FROM, "from_key": old["key"],
                                      "commit": old["git"]["commit"]}
        assert not row_state(out, ResultStore(out).read("s0_p1", "ARAP").record, trees).stale
        sshade = row_state(out, ResultStore(out).read("s0_p1", "SShaDe").record, trees)
        assert sshade.stale and "sshade.smooth_transfer changed since 3e79476" in sshade.why
        assert rekey_record(out, out / "runs" / "s0_p1" / "ARAP.json", trees) == "current"  # idempotent


def _resign(rec: dict) -> dict:
    text = json.dumps(rec["key_fields"], sort_keys=True, separators=(",", ":"))
    rec["key"] = hashlib.sha256(text.encode()).hexdigest()
    rec["digest"] = record_digest(rec)
    return rec


@pytest.mark.parametrize("edit, why", [
    (lambda r: r["row"].update(volume_err_pct=0.0), "edited"),
    (lambda r: r["git"].update(dirty=True), "uncommitted changes"),
    (lambda r: r["git"].update(commit="0" * 40), "is not in this repository"),
    (lambda r: _resign(dict(r, key_fields=dict(r["key_fields"], code=dict(r["key_fields"]["code"], sources="0" * 64)))),
     "is not that of"),
])
def test_rekey_refuses_what_it_cannot_verify_and_leaves_the_file(tmp_path, edit, why):
    out = _old_store(tmp_path, "Elastic")
    path = out / "runs" / "s0_p1" / "Elastic.json"
    rec = json.loads(path.read_text())
    rec = edit(rec) or rec
    path.write_text(json.dumps(rec, indent=1))
    text = path.read_text()
    with CommitTrees() as trees:
        got = rekey_record(out, path, trees)
    assert got.startswith("refused") and why in got
    assert path.read_text() == text


def _check_json(tree):
    env = dict(subprocess_env(), PYTHONPATH=str(tree))
    r = subprocess.run([sys.executable, "-m", "eval.reproduce", "--check", "--json"], cwd=tree, env=env,
                       capture_output=True, text=True, timeout=300)
    return r.returncode, json.loads(r.stdout), r.stderr


def test_an_edit_of_sshade_transfer_makes_only_sshade_rows_stale(tmp_path):
    """``--check --json`` in a copy of the checkout with results/faust: current (exit 0);
    after an edit of sshade/smooth_transfer.py's syntax tree, SShaDe's 8 rows are stale
    and no ARAP, Elastic, ARAP-SR or Implicit-ARAP row is (exit 1)."""
    tree = tmp_path / "tree"
    for d in (*PACKAGES, "conf"):
        shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(ROOT / "results" / "faust", tree / "results" / "faust")
    rc, got, err = _check_json(tree)
    assert rc == 0, err
    assert {m: v["stale"] for m, v in got["results/faust"].items()} == \
        {"ARAP": 0, "Elastic": 0, "ARAP-SR": 0, "Implicit-ARAP": 0, "SShaDe": 0}
    edit_syntax_tree(tree / "sshade" / "smooth_transfer.py")
    rc, got, err = _check_json(tree)
    assert rc == 1 and "stale: 8 of 40" in err
    assert {m: v["stale"] for m, v in got["results/faust"].items()} == \
        {"ARAP": 0, "Elastic": 0, "ARAP-SR": 0, "Implicit-ARAP": 0, "SShaDe": 8}


def test_committed_results_are_current_at_this_checkout():
    """Every committed row's identity equals this checkout's (``--check`` passes): the rule
    for results/ (a change to a row's code regenerates that row, only it)."""
    with CommitTrees() as trees:
        states = check_folders(run_folders(ROOT / "results"), trees, None)
    stale = {f: {m: v["why"] for m, v in ms.items() if v["stale"]} for f, ms in states.items()}
    assert not {f: s for f, s in stale.items() if s}
    assert sum(v["rows"] for ms in states.values() for v in ms.values()) > 0


def test_run_folders_finds_stores_and_enters_no_link(tmp_path):
    (tmp_path / "a" / "runs" / "c").mkdir(parents=True)
    (tmp_path / "sweeps" / "0" / "runs" / "runs").mkdir(parents=True)  # a case named "runs"
    (tmp_path / "outside" / "runs").mkdir(parents=True)
    os.symlink(tmp_path / "outside", tmp_path / "a" / "link")
    assert run_folders(tmp_path) == [tmp_path / "a", tmp_path / "outside", tmp_path / "sweeps" / "0"]
    assert run_folders(tmp_path / "a") == [tmp_path / "a"]

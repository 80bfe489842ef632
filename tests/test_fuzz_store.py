"""The result store read as untrusted input (eval/run/result_store.py): edited, truncated, foreign
records are never tabulated.

Seeded mutations of stored records (truncation, flipped bytes, edited cells of every
kind, a record of another pair, of another store version, of another code, a mesh path
that leaves the folder) are looked up: each is either refused with its reason in words
(and so recomputed by a resume) or is, cell for cell, the record that was stored. A
resume over a store with such records recomputes exactly those pairs, says why, and
gives the table of an uninterrupted run.
"""
from __future__ import annotations

import copy
import json
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from eval.run.result_store import ResultStore, check_row, pair_key, record_digest
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env

SEED = 32
N_MUTATIONS = 400
REFUSED = ("invalid: ", "other code: ", "other settings")


def _row(case, method, **kw):
    row = {"case": case, "subject": 0, "pose": 1, "method": method, "n_vertices": 5, "n_faces": 1, "n_handles": 2,
           "error": "", "compile_s": 0.0, "time_s": 0.25, "volume_err_pct": 1.5, "edge_err_pct": 0.5,
           "angle_err_deg": 0.1, "handle_err_pct": 0.0, "iterations": 12, "converged": True, "protocol": "converged"}
    row.update(kw)
    return row


def _stored(tmp_path):
    """A store with two valid records; returns (store, {pair: (key, fields)})."""
    st = ResultStore(tmp_path, meshes=True)
    keys = {}
    for case, method in (("s0_p1", "A"), ("s0_p2", "B")):
        ident = {"dataset": "faust", "case": case}
        keys[case, method] = pair_key({"_target_": "x.A", "name": method}, ident, {},
                                      {"sources": "s", "versions": {"numpy": "2"}, "plugin": None})
        st.save(case, method, *keys[case, method], _row(case, method), {"iterations": 12},
                np.zeros((5, 3)), git={"commit": "c", "dirty": False})
    return st, keys


def _mutate(rec: dict, other: dict, rng) -> tuple[str, dict | bytes]:
    """One mutation of a record (JSON data) or of its text (bytes)."""
    kind = rng.integers(12)
    r = copy.deepcopy(rec)
    text = json.dumps(rec, indent=1).encode()
    values = ["abc", -1.0, -5, None, True, [1, 2], {"a": 1}, 1e308, 2 ** 70, "", "nan", 0]
    if kind == 0:
        return "truncated", text[: int(rng.integers(len(text)))]
    if kind == 1:
        b = bytearray(text)
        for i in rng.integers(len(b), size=int(rng.integers(1, 6))):
            b[i] = int(rng.integers(256))
        return "flipped bytes", bytes(b)
    if kind == 2:  # a cell edited, digest left as it was
        k = list(r["row"])[int(rng.integers(len(r["row"])))]
        r["row"][k] = values[int(rng.integers(len(values)))]
        return f"row[{k}] edited", r
    if kind == 3:  # a cell edited and the digest recomputed: caught by the row check, or a valid cell
        k = list(r["row"])[int(rng.integers(len(r["row"])))]
        r["row"][k] = values[int(rng.integers(len(values)))]
        r["digest"] = record_digest(r)
        return f"row[{k}] edited, digest redone", r
    if kind == 4:
        r["row"] = {}
        r["digest"] = record_digest(r)
        return "empty row, digest redone", r
    if kind == 5:
        return "another pair's record", copy.deepcopy(other)
    if kind == 6:  # another pair's row under this pair's record
        r["row"] = copy.deepcopy(other["row"])
        r["digest"] = record_digest(r)
        return "another pair's row, digest redone", r
    if kind == 7:
        r["version"] = int(rng.integers(-3, 5))
        return "version", r
    if kind == 8:
        r["key"] = "0" * 64
        return "another key", r
    if kind == 9:
        r["mesh"] = ["../../etc/x.npy", "/abs.npy", "B.npy", 5][int(rng.integers(4))]
        r["digest"] = record_digest(r)
        return "mesh path, digest redone", r
    if kind == 10:
        r.pop(["row", "info", "digest", "case", "method", "key"][int(rng.integers(6))], None)
        return "key dropped", r
    r["info"] = values[int(rng.integers(len(values)))]
    r["digest"] = record_digest(r)
    return "info replaced, digest redone", r


def test_mutated_records_are_refused_with_a_reason_or_read_unchanged(tmp_path):
    st, keys = _stored(tmp_path)
    (case, method), (case2, method2) = list(keys)
    path = st.path(case, method)
    original = json.loads(path.read_text())
    other = json.loads(st.path(case2, method2).read_text())
    rng = np.random.default_rng(SEED)
    seen = {}
    for _ in range(N_MUTATIONS):
        what, data = _mutate(original, other, rng)
        path.write_bytes(data if isinstance(data, bytes) else json.dumps(data).encode())
        found = st.lookup(case, method, *keys[case, method])
        if found.record is None:
            assert found.why.startswith(REFUSED), (what, found.why)
            kind = what.split("[")[0].split(",")[0]
            seen[kind] = seen.get(kind, 0) + 1
        else:  # accepted: then it is what was stored, or a valid row with a valid cell
            assert not check_row(found.record["row"], case, method), what
            assert found.record["key"] == original["key"] and found.record["case"] == case
            if "digest redone" not in what:
                assert found.record["row"] == original["row"] and found.record["info"] == original["info"], what
            U = st.load_mesh(found.record, n=5)
            assert U is None or U.shape == (5, 3)
    assert len(seen) >= 10  # every kind of mutation met a refusal
    path.write_text(json.dumps(original))
    assert st.lookup(case, method, *keys[case, method]).record == original  # the untouched record is read


@pytest.mark.parametrize("cell, value, why", [
    ("time_s", -1.0, "time_s is negative"), ("volume_err_pct", "abc", "volume_err_pct is not a number"),
    ("case", "s0_p2", "another pair"), ("n_handles", [1], "not a table cell")])
def test_an_invalid_row_with_a_valid_digest_is_refused(tmp_path, cell, value, why):
    st, keys = _stored(tmp_path)
    p = st.path("s0_p1", "A")
    rec = json.loads(p.read_text())
    rec["row"][cell] = value
    rec["digest"] = record_digest(rec)
    p.write_text(json.dumps(rec))
    found = st.lookup("s0_p1", "A", *keys["s0_p1", "A"])
    assert found.record is None and why in found.why


def test_record_of_other_code_is_refused_saying_what_changed(tmp_path):
    st, keys = _stored(tmp_path)
    key, fields = keys["s0_p1", "A"]
    new = pair_key(fields["method"], fields["case"], fields["extra"],
                   {"sources": "t", "versions": {"numpy": "3"}, "plugin": None})
    found = st.lookup("s0_p1", "A", *new)
    assert found.record is None
    assert found.why == "other code: the project's sources changed; numpy 2 -> 3"
    other = pair_key(dict(fields["method"], tol=1), fields["case"], fields["extra"], fields["code"])
    assert st.lookup("s0_p1", "A", *other).why == "other settings: method definition"


PLUGIN = "{_target_:tests.store_methods.Counted,name:%s}"


def _eval(out, *extra, env=None, rc=0):
    cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={out.parent / 'faust'}",
           "dataset.limit=2", "reference.cases=none", "report.enabled=false", "jobs=1",
           f"methods=[{PLUGIN % 'A'},{PLUGIN % 'B'}]", f"out_dir={out}", *extra]
    r = subprocess.run(cmd, cwd=ROOT, env=dict(subprocess_env(), **(env or {})), capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == rc, r.stderr[-3000:]
    return r


@pytest.mark.slow
def test_resume_recomputes_edited_truncated_and_foreign_records(tmp_path, faust_root):
    (tmp_path / "faust").symlink_to(faust_root)
    out, full, counter = tmp_path / "out", tmp_path / "full", tmp_path / "calls.txt"
    _eval(out)
    _eval(full)
    runs = out / "runs"
    # edited (the volume cell made text), truncated, and a foreign record (another pair's, renamed)
    rec = json.loads((runs / "s0_p1" / "A.json").read_text())
    rec["row"]["volume_err_pct"] = "abc"
    (runs / "s0_p1" / "A.json").write_text(json.dumps(rec))
    text = (runs / "s0_p1" / "B.json").read_text()
    (runs / "s0_p1" / "B.json").write_text(text[: len(text) // 2])
    (runs / "s0_p2" / "A.json").write_text((runs / "s0_p2" / "B.json").read_text())
    untouched = (runs / "s0_p2" / "B.json").read_bytes()
    r = _eval(out, "resume=true", env={"SSHADE_TEST_COUNTER": str(counter)})
    log = r.stdout + r.stderr
    calls = sorted(counter.read_text().split("\n")[:-1])
    assert [c.split()[1] for c in calls] == ["A", "A", "B"], log  # the three bad records, not the good one
    assert "invalid: edited" in log and "invalid: unreadable" in log and "invalid: it names another pair" in log
    assert (runs / "s0_p2" / "B.json").read_bytes() == untouched
    a, b = pd.read_csv(out / "cases.csv"), pd.read_csv(full / "cases.csv")
    drop = ["time_s", "compile_s"]
    pd.testing.assert_frame_equal(a.drop(columns=drop), b.drop(columns=drop))
    assert json.loads((out / "run.json").read_text())["resumed"]["restored"] == 1
    assert not os.environ.get("SSHADE_TEST_HANG_AFTER")


@pytest.mark.parametrize("linked", ["runs", "runs/s0_p1", "runs/s0_p1/A.json"])
def test_a_store_with_a_link_out_is_refused_and_nothing_is_written_outside(tmp_path, linked):
    """A link in runs/ (the store itself, a case folder or a record made a link to a
    folder elsewhere) is refused before a resume reads or writes a record: the link is
    named, nothing outside the folder changes."""
    st, keys = _stored(tmp_path / "out")
    outside = tmp_path / "elsewhere"
    src = tmp_path / "out" / linked
    os.replace(src, outside)
    src.symlink_to(outside)
    before = {p: p.read_bytes() for p in sorted(outside.rglob("*")) if p.is_file()} if outside.is_dir() else {
        outside: outside.read_bytes()}
    with pytest.raises(SShaDeError, match="is a link"):
        ResultStore(tmp_path / "out").check_links()
    with pytest.raises(SShaDeError, match="is a link"):
        st.save("s0_p1", "A", *keys["s0_p1", "A"], _row("s0_p1", "A"), {}, None, git={})
    with pytest.raises(SShaDeError, match="is a link"):
        st.lookup("s0_p1", "A", *keys["s0_p1", "A"])
    after = {p: p.read_bytes() for p in sorted(outside.rglob("*")) if p.is_file()} if outside.is_dir() else {
        outside: outside.read_bytes()}
    assert after == before


@pytest.mark.slow
def test_resume_through_a_linked_case_folder_is_refused_with_one_line(tmp_path, faust_root):
    (tmp_path / "faust").symlink_to(faust_root)
    out = tmp_path / "out"
    _eval(out)
    outside = tmp_path / "elsewhere"
    os.replace(out / "runs" / "s0_p1", outside)
    (out / "runs" / "s0_p1").symlink_to(outside)
    rec = json.loads((outside / "A.json").read_text())
    rec["row"]["volume_err_pct"] = 0.5  # edited: a resume would recompute it into the link's target
    (outside / "A.json").write_text(json.dumps(rec))
    before = {p.name: p.read_bytes() for p in outside.iterdir()}
    r = _eval(out, "resume=true", rc=2)
    errors = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    # refused by the output folder's claim (a link anywhere in it), before the store's own check
    assert len(errors) == 1 and "is a symbolic link" in errors[0] and "s0_p1" in errors[0], r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert {p.name: p.read_bytes() for p in outside.iterdir()} == before

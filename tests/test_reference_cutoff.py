"""Early cutoff of the reference columns (eval/experiments/cases/reference_cutoff.py): a
row records the reference it was scored against; after a change of the code that solves
references, a resumed run solves them again and keeps the rows whose reference comes out
bit for bit the same, and runs exactly those scored against one that differs."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from eval.experiments.cases.reference_cutoff import cutoff_candidate, reference_digest
from eval.metrics.reference import Reference
from eval.present.meshview import read_view
from eval.run.code_identity import PACKAGES

from .conftest import ROOT, subprocess_env

A = "{_target_:tests.store_methods.Counted,name:A}"  # scored against spokes-and-rims
B = "{_target_:tests.store_methods.CountedSpokes,name:B}"  # scored against spokes
#: where the tree's reference solver returns its minimiser
SOLVED = 'return np.asarray(res.V, np.float64), float(res.info.get("energy", np.nan)), res'


def _eval(tree, out, counter, cache):
    env = dict(subprocess_env(), PYTHONPATH=f"{tree}:{ROOT}", SSHADE_TEST_COUNTER=str(counter))
    cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tree / 'faust'}", "dataset.limit=1",
           "reference.cases=all", f"reference.cache={cache}", f"methods=[{A},{B}]", f"out_dir={out}", "resume=true"]
    r = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def _records(out) -> dict:
    return {p.stem: json.loads(p.read_text()) for p in sorted((out / "runs").rglob("*.json"))}


@pytest.mark.slow
def test_a_reference_solved_again_bit_for_bit_keeps_its_rows_and_one_that_differs_reruns_its_rows(
        tmp_path, faust_root):
    tree, out, counter, cache = tmp_path / "tree", tmp_path / "out", tmp_path / "calls.txt", tmp_path / "refs"
    for d in (*PACKAGES, "conf"):
        shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tree)
    (tree / "faust").symlink_to(faust_root)
    _eval(tree, out, counter, cache)
    first = _records(out)
    assert {m: r["reference"]["energy"] for m, r in first.items()} == {"A": "spokes_and_rims", "B": "spokes"}
    assert all(len(r["output"]) == 64 and len(r["reference"]["digest"]) == 64 for r in first.values())
    rows = (out / "cases.csv").read_text()
    # the solver's code changes, not what it gives: both rows kept, no method runs
    ref = tree / "eval" / "metrics" / "reference.py"
    ref.write_text(ref.read_text() + "\n_PROBE = 1\n")
    calls, log = counter.read_text(), (out / "eval.log").read_text()
    _eval(tree, out, counter, cache)
    assert counter.read_text() == calls
    assert (out / "eval.log").read_text()[len(log):].count("solved again by this code is bit for bit the same") == 2
    kept = _records(out)
    for m in ("A", "B"):
        assert kept[m]["row"] == first[m]["row"] and kept[m]["reference"]["digest"] == first[m]["reference"]["digest"]
        assert kept[m]["key"] != first[m]["key"] and kept[m]["reproduced"]["from_key"] == first[m]["key"]
    assert (out / "cases.csv").read_text() == rows
    # the kept runs (no mesh stored) keep their panels of the case's 3D view: its earlier
    # view shows them under the keys they had before they were kept
    views = [read_view(p) for p in sorted((out / "report").glob("*.js"))]
    assert views and all(m["pos"] and m["kind"] == "result" and m["carried"]
                         for v in views for m in v["meshes"] if m["label"] in ("A", "B"))
    # the spokes reference now differs by one part in 10^9: B runs again, A stays
    text = ref.read_text()
    assert SOLVED in text
    moved = "np.asarray(res.V, np.float64) * (1 + 1e-9 * (energy == 'spokes'))"
    ref.write_text(text.replace(SOLVED, SOLVED.replace("np.asarray(res.V, np.float64)", moved)))
    _eval(tree, out, counter, cache)
    assert counter.read_text()[len(calls):].split() == ["6890", "B"]
    last = _records(out)
    assert last["A"]["row"] == first["A"]["row"] and "reproduced" in last["A"]
    assert last["B"]["reference"]["digest"] != first["B"]["reference"]["digest"] and "reproduced" not in last["B"]
    assert last["B"]["output"] == first["B"]["output"]  # the method gave the same bytes; its reference moved
    assert last["B"]["same_output_as"]["key"] == kept["B"]["key"]  # and its record says so


def _record(fields, ref_code="r1", digest="d" * 64):
    code = {"sources": "s", "modules": [], "constants": [], "versions": {}, "plugin": None,
            "reference": {"sources": ref_code, "modules": [], "constants": []}}
    return {"key_fields": {"version": 6, "method": {"name": "A"}, "case": {"V": "v"}, "extra": {}, "code": code,
                           **fields},
            "reference": {"energy": "spokes", "key": "k", "digest": digest}}


def test_a_cutoff_candidate_differs_only_in_its_reference_solver_and_records_its_reference():
    now = _record({}, ref_code="r2")["key_fields"]
    assert cutoff_candidate(_record({}), now)
    assert not cutoff_candidate(_record({"case": {"V": "w"}}), now)  # other data
    assert not cutoff_candidate(_record({"method": {"name": "A", "tol": 1}}), now)  # other settings
    other_code = _record({})
    other_code["key_fields"]["code"]["sources"] = "t"
    assert not cutoff_candidate(other_code, now)  # its own code changed
    unrecorded = _record({})
    del unrecorded["reference"]
    assert not cutoff_candidate(unrecorded, now)  # a record of older code: no digest to compare
    assert not cutoff_candidate(None, now) and not cutoff_candidate({"reference": "x"}, now)


def test_a_reference_digest_changes_with_any_bit_of_the_solution():
    import numpy as np
    U = np.random.default_rng(0).standard_normal((5, 3))
    ref = Reference(U=U, energy=1.5, energy_type="spokes", key="k", path=None)
    d = reference_digest(ref)
    U2 = U.copy()
    U2[2, 1] = np.nextafter(U2[2, 1], 1.0)
    assert reference_digest(Reference(U=U2, energy=1.5, energy_type="spokes", key="k", path=None)) != d
    assert reference_digest(Reference(U=U, energy=np.nextafter(1.5, 2), energy_type="spokes", key="k",
                                      path=None)) != d
    assert reference_digest(Reference(U=U, energy=1.5, energy_type="spokes_and_rims", key="k", path=None)) != d
    assert reference_digest(Reference(U=U.copy(order="F"), energy=1.5, energy_type="spokes", key="other",
                                      path=None)) == d

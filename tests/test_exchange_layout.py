"""eval/exchange/layout.py: ``python -m eval experiment=export`` writes every case in files
that libigl, JSON and CSV readers give back exactly, named as the evaluator names them,
without the ground truth; the times file is read or refused with its line."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from eval.datasets.deformation_case import DeformationCase
from eval.exchange.layout import CASE_FILES, INDEX, read_times, result_path, write_case
from sshade.errors import SShaDeError
from tests.conftest import ROOT, icosphere, subprocess_env
from tests.optional import optional_import


def _case(name="c", group=True) -> DeformationCase:
    V, F = icosphere()
    h = np.array([0, 5, 17])
    T = V[h] + [[0.1, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, -0.2, 0.05]]
    return DeformationCase(name=name, subject=0, pose=1, V=V, F=F, handles=h, targets=T,
                           static=np.array([False, True, False]), V_gt=V + 1.0,
                           group=np.array([0, 1, 2]) if group else None)


def test_each_file_of_a_case_reads_back_exactly_with_outside_readers(tmp_path):
    import igl
    c = _case()
    entry = write_case(tmp_path / c.name, c)
    d = tmp_path / c.name
    assert sorted(p.name for p in d.iterdir()) == sorted(CASE_FILES.values())
    for key in ("rest_obj", "rest_ply"):
        V, F = igl.read_triangle_mesh(str(tmp_path / entry["files"][key]))
        assert np.array_equal(V, c.V) and np.array_equal(F, c.F), key
    doc = json.loads((d / "handles.json").read_text())
    assert doc["handles"] == c.handles.tolist() and np.array_equal(doc["targets"], c.targets)
    assert doc["static"] == c.static.tolist() and doc["group"] == [0, 1, 2] and doc["index_base"] == 0
    with open(d / "handles.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["handle"]) for r in rows] == c.handles.tolist()
    assert np.array_equal([[float(r[k]) for k in "xyz"] for r in rows], c.targets)
    assert [int(r["static"]) for r in rows] == [0, 1, 0]
    assert np.array_equal(igl.readDMAT(str(d / "handles.dmat")).ravel(), c.handles)
    assert np.array_equal(igl.readDMAT(str(d / "targets.dmat")), c.targets)
    assert np.array_equal(igl.readDMAT(str(d / "static.dmat")).ravel(), c.static)
    assert entry["has_ground_truth"] and not any("gt" in v for v in entry["files"].values())


def test_export_names_cases_as_the_evaluator_and_leaves_out_the_truth(tmp_path, faust_root):
    out = tmp_path / "export"
    r = subprocess.run([sys.executable, "-m", "eval", "experiment=export", "dataset=faust",
                        f"dataset.root={faust_root}", "dataset.limit=2", f"out_dir={out}"],
                       cwd=ROOT, env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    index = json.loads((out / INDEX).read_text())
    from eval.datasets import load_cases
    cases = load_cases("faust", faust_root, limit=2)
    assert [e["name"] for e in index["cases"]] == [c.name for c in cases] == ["s0_p1", "s0_p2"]
    for e, c in zip(index["cases"], cases):
        doc = json.loads((out / e["files"]["handles_json"]).read_text())
        assert doc["handles"] == c.handles.tolist() and np.array_equal(doc["targets"], c.targets)
        assert e["n_vertices"] == len(c.V) == 6890
    written = [p for p in out.rglob("*") if p.is_file()]
    assert not any("gt" in p.name or p.suffix == ".npz" for p in written)
    jsonschema = optional_import("jsonschema")  # cases.json and run.json against their schemas
    for doc, schema in ((index, ROOT / "eval" / "exchange" / "cases.schema.json"),
                        (json.loads((out / "run.json").read_text()), ROOT / "eval" / "run" / "run.schema.json")):
        jsonschema.Draft202012Validator(json.loads(schema.read_text())).validate(doc)


def test_times_file_is_read_and_bad_lines_are_named(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("case,time_s,machine\ns0_p1,1.5,laptop i7\ns0_p2,0,\n")
    assert read_times(p) == {"s0_p1": (1.5, "laptop i7", None, None), "s0_p2": (0.0, "", None, None)}
    for body, where in (("case,seconds\na,1\n", "line 1"), ("case,time_s\na,-1\n", "line 2"),
                        ("case,time_s\na,nan\n", "line 2"), ("case,time_s\na,1\na,2\n", "line 3"),
                        ("case,time_s\na,1,extra\n", "line 2"), ("case,time_s\na,fast\n", "line 2")):
        p.write_text(body)
        with pytest.raises(SShaDeError, match=f"t.csv, {where}"):
            read_times(p)
    p.write_bytes(b"case,time_s\n\xff\xfe,1\n")
    with pytest.raises(SShaDeError, match="not a UTF-8 text file"):
        read_times(p)


def test_result_path_wants_exactly_one_mesh_per_case(tmp_path):
    with pytest.raises(SShaDeError, match="no result for case a"):
        result_path(tmp_path, "a")
    (tmp_path / "a.OBJ").write_text("")
    assert result_path(tmp_path, "a").name == "a.OBJ"
    (tmp_path / "a.ply").write_text("")
    with pytest.raises(SShaDeError, match="two results for case a"):
        result_path(tmp_path, "a")


def test_a_result_that_is_a_link_a_folder_or_a_fifo_is_refused_in_one_line_and_never_followed(tmp_path):
    import os
    (tmp_path / "secret").write_text("root:x:0:0\n")
    os.symlink(tmp_path / "secret", tmp_path / "s0_p1.obj")
    os.symlink(tmp_path / "gone", tmp_path / "s0_p2.obj")  # dangling
    (tmp_path / "s0_p3.obj").mkdir()
    os.mkfifo(tmp_path / "s0_p4.obj")
    for case, words in (("s0_p1", "is a link"), ("s0_p2", "is a link"), ("s0_p3", "not a regular file"),
                        ("s0_p4", "not a regular file")):
        with pytest.raises(SShaDeError, match=words) as e:
            result_path(tmp_path, case)
        assert "\n" not in str(e.value) and "root:x" not in str(e.value)


def test_times_past_the_bound_are_refused_and_a_machine_field_is_plain_text(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("case,time_s\ns0_p1,1e308\n")
    with pytest.raises(SShaDeError, match=r"line 2: time_s '1e308' must be a number of seconds in \[0, 1e\+07\]"):
        read_times(p)
    p.write_text("case,time_s,machine\ns0_p1,1,=cmd|' /C calc'!A0\ns0_p2,2,<script>alert(1)</script>\n"
                 "s0_p3,3,-2+3\n")
    got = {k: t.machine for k, t in read_times(p).items()}
    assert got["s0_p1"][0] not in "=+-@" and not any(c in got["s0_p2"] for c in "<>|'!")
    assert got["s0_p3"] == "2+3" and all("|" not in m for m in got.values())


def test_an_stl_result_is_refused_naming_why_and_no_other_format_is_taken_for_it(tmp_path):
    (tmp_path / "s0_p1.stl").write_bytes(b"solid x\nendsolid x\n")
    with pytest.raises(SShaDeError, match="an STL result cannot be scored .* write OBJ, PLY or OFF"):
        result_path(tmp_path, "s0_p1")
    with pytest.raises(SShaDeError, match=r"has no s0_p2.obj \(nor .ply, .off\)"):
        result_path(tmp_path, "s0_p2")


def test_a_times_file_says_how_the_method_stopped_and_a_bad_cell_is_named():
    import tempfile
    p = Path(tempfile.mkdtemp()) / "t.csv"
    p.write_text("case,time_s,iterations,converged\ns0_p1,2.5,1000,false\ns0_p2,1,57,TRUE\ns0_p3,1,,\n")
    t = read_times(p)
    assert (t["s0_p1"].iterations, t["s0_p1"].converged) == (1000, False)
    assert (t["s0_p2"].iterations, t["s0_p2"].converged) == (57, True)
    assert (t["s0_p3"].iterations, t["s0_p3"].converged) == (None, None)
    p.write_text("case,time_s,iterations\ns0_p1,2.5,-3\n")
    with pytest.raises(SShaDeError, match="line 2: iterations '-3' is not an integer >= 0"):
        read_times(p)
    p.write_text("case,time_s,converged\ns0_p1,2.5,maybe\n")
    with pytest.raises(SShaDeError, match="line 2: converged 'maybe' is not true or false"):
        read_times(p)

"""eval/exchange/scored.py: results computed outside the harness are scored like any row.
Export, deform in a separate process that knows nothing of the evaluator, score: the
quality columns equal the built-in SShaDe row's; bad result files are failed cases with
their reasons; the Time column is the method's reported time, or empty."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from eval.exchange.scored import ScoredResults, same_faces
from sshade.errors import SShaDeError
from sshade.mesh.io import write_mesh
from tests.conftest import ROOT, subprocess_env

QUALITY = ("volume_err_pct", "area_err_pct", "edge_err_pct", "angle_err_deg", "handle_err_pct", "gt_vertex_mean_pct")
FAST = ["reference.cases=none", "report.enabled=false"]

#: A program outside the evaluator: reads the exchange layout, deforms with SShaDe's
#: Python API, writes <case>.obj and the times it measured itself.
OUTSIDE = textwrap.dedent('''
    import csv, json, sys, time
    from pathlib import Path
    import numpy as np
    import sshade
    from sshade.mesh.io import read_mesh, write_mesh
    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    rows = []
    for c in json.loads((src / "cases.json").read_text())["cases"]:
        V, F = read_mesh(src / c["files"]["rest_obj"], allow_components=True)
        h = json.loads((src / c["files"]["handles_json"]).read_text())
        t0 = time.perf_counter()
        U = sshade.SShaDe(n_low=300, n_samplings=2, seed=0).deform(V, F, np.array(h["handles"]),
                                                                   np.array(h["targets"]))
        rows.append((c["name"], round(time.perf_counter() - t0, 4) + 100.0, "outside box", 1000, "false"))
        write_mesh(dst / (c["name"] + ".obj"), U, F)
    with open(dst / "times.csv", "w", newline="") as f:
        w = csv.writer(f); w.writerow(["case", "time_s", "machine", "iterations", "converged"]); w.writerows(rows)
''')


def _eval(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "eval", *args], cwd=cwd, env=subprocess_env(),
                          capture_output=True, text=True, timeout=600)


def _rows(folder):
    with open(folder / "cases.csv") as f:
        return {(r["case"], r["method"]): r for r in csv.DictReader(f)}


def _round_trip(tmp_path, data: list[str]):
    ex, res = tmp_path / "export", tmp_path / "results"
    res.mkdir()
    r = _eval("experiment=export", *data, f"out_dir={ex}")
    assert r.returncode == 0, r.stderr[-2000:]
    (tmp_path / "outside.py").write_text(OUTSIDE)
    r = subprocess.run([sys.executable, str(tmp_path / "outside.py"), str(ex), str(res)], env=subprocess_env(),
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    both = tmp_path / "both"
    scored = (f"{{_target_:eval.exchange.scored.ScoredResults,name:Outside,results:'{res}',"
              f"times:'{res / 'times.csv'}'}}")
    r = _eval(*data, "sshade.n_low=300", "sshade.n_samplings=2", *FAST, f"out_dir={both}",
              f"methods=[SShaDe,{scored}]")
    assert r.returncode == 0, r.stderr[-2000:]
    rows = _rows(both)
    names = sorted({c for c, _ in rows})
    assert names and all((c, "Outside") in rows for c in names)
    for c in names:
        ours, theirs = rows[c, "SShaDe"], rows[c, "Outside"]
        assert ours["error"] == theirs["error"] == ""
        for k in QUALITY:
            if ours.get(k):
                assert float(theirs[k]) == pytest.approx(float(ours[k]), rel=1e-9, abs=1e-12), (c, k)
        assert float(theirs["time_s"]) >= 100.0 and theirs["time_machine"] == "outside box"
    table = (both / "table.md").read_text()
    line = next(ln for ln in table.splitlines() if ln.startswith("| Outside"))
    time_cell = next(x.strip() for x in line.split("|") if "(reported)" in x)
    assert not time_cell.startswith("**")  # a reported time is never compared in bold
    stop = next(ln for ln in table.splitlines() if ln.startswith("- Outside: "))  # how it stopped, as reported
    assert "1000 iterations" in stop and f"converged on 0/{len(names)} runs" in stop
    assert "as the method reported" in stop and "reported as stopped before its criterion on" in stop
    return both


@pytest.mark.slow
def test_faust_round_trip_through_an_outside_process_equals_the_builtin_row(tmp_path, faust_root):
    both = _round_trip(tmp_path, ["dataset=faust", f"dataset.root={faust_root}", "dataset.limit=2"])
    r = subprocess.run([sys.executable, "-m", "eval.report", str(both)], cwd=ROOT, env=subprocess_env(),
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    page = (both / "index.html").read_text()
    assert page.count(" (reported)</td>") == 1 and "the time the method reported for itself" in page


@pytest.mark.slow
def test_defaust_round_trip_through_an_outside_process_equals_the_builtin_row(tmp_path, defaust_ci):
    _round_trip(tmp_path, ["dataset=defaust", f"dataset.root={defaust_ci}", "dataset.limit=2",
                           "dataset.resolution=low", "dataset.build.enabled=false"])


@pytest.mark.slow
def test_bad_result_files_are_failed_cases_with_reasons_and_the_rest_is_tabulated(tmp_path, faust_root):
    from eval.datasets import load_cases
    cases = load_cases("faust", faust_root, limit=5)
    res = tmp_path / "results"
    res.mkdir()
    good = {}
    for c in cases:
        U = c.V.copy()
        U[c.handles] = c.targets
        good[c.name] = U
    names = [c.name for c in cases]
    # names[0]: missing; [1]: NaN; [2]: wrong vertex count; [3]: not a mesh; [4]: good
    U = good[names[1]].copy()
    U[7] = np.nan
    (res / f"{names[1]}.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in U) +
                                         "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in cases[1].F))
    F2 = cases[2].F
    write_mesh(res / f"{names[2]}.obj", good[names[2]][:-1], F2[(F2 < len(cases[2].V) - 1).all(axis=1)])
    (res / f"{names[3]}.ply").write_text("this is not a mesh\n")
    write_mesh(res / f"{names[4]}.ply", good[names[4]], cases[4].F)
    out = tmp_path / "run"
    r = _eval("experiment=score", f"score.results={res}", "score.name=Mine", "dataset=faust",
              f"dataset.root={faust_root}", "dataset.limit=5", *FAST, f"out_dir={out}")
    assert r.returncode == 0, r.stderr[-2000:]
    rows = _rows(out)
    err = {c: rows[c, "Mine"]["error"] for c in names}
    assert "no result for case" in err[names[0]]
    assert "not finite" in err[names[1]] or "nan" in err[names[1]].lower()
    assert "6889 vertices" in err[names[2]] and "has 6890" in err[names[2]]
    assert "PLY" in err[names[3]] or "ply" in err[names[3]]
    assert err[names[4]] == "" and rows[names[4], "Mine"]["time_s"] == ""  # no times file: no time
    assert float(rows[names[4], "Mine"]["handle_err_pct"]) == 0.0
    table = (out / "table.md").read_text()
    assert "| Mine | 1 | 4 |" in table  # one case averaged, four failed


def test_a_malformed_times_file_is_refused_before_any_case(tmp_path, faust_root):
    res = tmp_path / "results"
    res.mkdir()
    (res / "times.csv").write_text("case,time_s\ns0_p1,soon\n")
    out = tmp_path / "run"
    r = _eval("experiment=score", f"score.results={res}", "score.name=Mine", f"score.times={res / 'times.csv'}",
              "dataset=faust", f"dataset.root={faust_root}", "dataset.limit=1", *FAST, f"out_dir={out}")
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and lines[-1].startswith("error: ") and "times.csv, line 2" in lines[-1]
    assert "Traceback" not in r.stderr and not (out / "cases.csv").exists()


def test_a_case_aware_method_is_told_its_case_but_not_the_truth(faust_root):
    from eval.datasets import load_cases
    from eval.experiments.cases.case_references import CaseReferences
    from eval.experiments.cases.pair import run_pair
    case = load_cases("faust", faust_root, limit=1)[0]

    class Aware:
        name, case, info = "Aware", None, {}
        seen = []

        def deform(self, V, F, handles, targets):
            self.seen.append(self.case)
            U = np.array(V)
            U[handles] = targets
            return U

    m = Aware()
    from eval.run.spec import ReferenceOptions
    refs = CaseReferences(ReferenceOptions(cases="none"))
    row, U, _ = run_pair(m, "Aware", case, refs, {"timeout_s": None, "handle_error_max_pct": 1.0})
    told = m.seen[0]
    assert row["error"] == "" and told.name == case.name and np.array_equal(told.static, case.static)
    assert not hasattr(told, "V_gt") and not hasattr(told, "V")


def test_scored_results_outside_the_evaluator_say_they_need_a_case(tmp_path):
    m = ScoredResults(tmp_path, "Mine")
    with pytest.raises(SShaDeError, match="no case given"):
        m.deform(np.zeros((3, 3)), np.array([[0, 1, 2]]), np.array([0]), np.zeros((1, 3)))
    with pytest.raises(SShaDeError, match="is not a folder"):
        ScoredResults(tmp_path / "absent", "Mine")


def test_same_faces_ignores_face_order_and_rotation_but_not_orientation():
    F = np.array([[0, 1, 2], [2, 1, 3]])
    assert same_faces(F, np.array([[1, 3, 2], [1, 2, 0]]))
    assert not same_faces(F, np.array([[0, 2, 1], [2, 1, 3]]))  # flipped
    assert not same_faces(F, F[:1])
    assert json.dumps(same_faces(F, F)) == "true"


def test_a_result_with_reordered_vertices_is_named_as_such_not_as_a_face_count(tmp_path):
    from types import SimpleNamespace

    from eval.exchange.scored import ScoredResults
    from sshade.errors import SShaDeError
    from sshade.mesh.io import write_mesh
    from tests.conftest import icosphere
    V, F = icosphere()
    perm = np.roll(np.arange(len(V)), 1)  # what a reader that reorders vertices writes back
    inv = np.argsort(perm)
    write_mesh(tmp_path / "c.ply", V[perm], inv[F])
    s = ScoredResults(tmp_path, "Theirs")
    s.case = SimpleNamespace(name="c")
    with pytest.raises(SShaDeError, match=r"join other vertices than the rest mesh's \(same count\): the vertices "
                                          r"were reordered"):
        s.deform(V, F, np.array([0]), V[:1])

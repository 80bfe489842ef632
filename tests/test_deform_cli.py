"""``python -m sshade deform`` (sshade/deform_command.py, sshade/mesh/handle_files.py): every handle
format gives what sshade.deform gives on the same handles and targets; unreferenced
vertices, components and --repair; every bad file gets one ``error:`` line and status 2."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from examples.twisted_bar import twist_matrix, write_case
from sshade import deform
from sshade.deform_command import main
from sshade.mesh.handle_files import FIXED, FREE, HANDLE, apply_def, write_def, write_sel
from sshade.mesh.io import read_mesh, write_mesh

from .conftest import ROOT, subprocess_env

# small and fast: SShaDe with 2 samplings in-process
SSHADE = ["--n-low", "150", "--k", "2", "--seed", "3", "--param", "workers=1"]
API = {"n_low": 150, "n_samplings": 2, "seed": 3, "workers": 1}


@pytest.fixture(scope="module")
def bar(tmp_path_factory):
    """A coarse twisted bar (angle 90) in the survey format: bar.off, bar.sel, bar.def."""
    d = tmp_path_factory.mktemp("bar")
    case = write_case(d, angle=90.0, h=0.15)
    V, F = read_mesh(case["paths"]["off"])  # the mesh as the command reads it
    status = np.full(len(V), FREE, np.int8)
    status[case["handles"]] = FIXED
    status[V[:, 0] > 4.0 - 1e-9] = HANDLE
    return dict(dir=d, V=V, F=F, status=status, M=twist_matrix(90.0), **case["paths"])


def _api(b, status=None):
    """sshade.deform on the same handles: fixed vertices at rest, handles moved by M."""
    st = b["status"] if status is None else status
    h = np.flatnonzero(st != FREE)
    t = b["V"][h].copy()
    t[st[h] == HANDLE] = apply_def(b["M"], t[st[h] == HANDLE])
    return h, t, deform(b["V"], b["F"], h, t, **API)


def _cli(args, capsys):
    rc = main(["deform", *map(str, args)])
    out, err = capsys.readouterr()
    return rc, out, err


def _out(path):
    return read_mesh(path, validate=False)[0]


# ------------------------------------------------------------------ formats

def test_sel_def_matches_the_api(bar, tmp_path, capsys):
    out = tmp_path / "d.ply"
    rc, stdout, err = _cli([bar["off"], "--sel", bar["sel"], "--def", bar["def"], "-o", out, *SSHADE], capsys)
    assert rc == 0, err
    h, t, Vd = _api(bar)
    assert np.abs(_out(out) - Vd).max() <= 1e-9
    assert f"{len(h)} handles" in stdout and "deform" in stdout and "total" in stdout
    np.testing.assert_allclose(_out(out)[h], t, atol=1e-12)


def test_dmat_def_matches_the_api(bar, tmp_path, capsys):
    sel = np.where(bar["status"] == FREE, -1, np.where(bar["status"] == FIXED, 0, 1))
    dmat = tmp_path / "sel.dmat"
    dmat.write_text(f"1 {len(sel)}\n" + "\n".join(str(x) for x in sel) + "\n")  # ncols nrows, column-major
    out = tmp_path / "d.off"
    rc, _, err = _cli([bar["off"], "--dmat", dmat, "--def", bar["def"], "-o", out, *SSHADE], capsys)
    assert rc == 0, err
    assert np.abs(_out(out) - _api(bar)[2]).max() <= 1e-9  # OFF keeps 16+ digits


@pytest.mark.parametrize("fmt", ["json", "csv"])
def test_handle_file_matches_the_api(bar, tmp_path, capsys, fmt):
    h, t, Vd = _api(bar)
    f = tmp_path / f"h.{fmt}"
    if fmt == "json":
        f.write_text(json.dumps({"handles": h.tolist(), "targets": t.tolist()}))
    else:
        rows = (f"{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in zip(h.tolist(), t.tolist()))
        f.write_text("index,x,y,z\n" + "".join(rows))
    out = tmp_path / "d.obj"
    rc, _, err = _cli([bar["off"], "--handles", f, "-o", out, *SSHADE], capsys)
    assert rc == 0, err
    assert np.abs(_out(out) - Vd).max() <= 1e-9


def _harness_cli(args, capsys):
    from harness.__main__ import main as harness_main
    rc = harness_main(["deform", *map(str, args)])
    out, err = capsys.readouterr()
    return rc, out, err


def test_harness_deform_runs_other_methods_and_plugins(bar, tmp_path, capsys):
    from baselines import Elastic
    h, t, _ = _api(bar)
    rc, _, err = _harness_cli([bar["off"], "--sel", bar["sel"], "--def", bar["def"], "-o", tmp_path / "e.ply",
                               "--method", "elastic", "--param", "tol=1e-3"], capsys)
    assert rc == 0, err
    assert np.abs(_out(tmp_path / "e.ply") - Elastic(tol=1e-3).deform(bar["V"], bar["F"], h, t)).max() <= 1e-9
    rc, stdout, err = _harness_cli([bar["off"], "--sel", bar["sel"], "--def", bar["def"], "-o", tmp_path / "p.ply",
                                    "--method", "tests.plugin_example.MyMethod", "--param", "iterations=5"], capsys)
    assert rc == 0, err
    from .plugin_example import MyMethod
    assert np.abs(_out(tmp_path / "p.ply") - MyMethod(iterations=5).deform(bar["V"], bar["F"], h, t)).max() <= 1e-9
    assert stdout.startswith("Mine:")
    rc, _, err = _harness_cli([bar["off"], "--sel", bar["sel"], "--def", bar["def"], "-o", tmp_path / "a.ply",
                               "--method", "ARAP", "--n-low", "100"], capsys)
    assert rc == 2 and err.startswith("error: ARAP has no parameter(s) ['n_low']") and err.count("\n") == 1, err


def test_sshade_deform_and_harness_deform_build_the_same_sshade(bar, tmp_path, capsys):
    """The method package's command builds SShaDe and SShaDe+refine without the harness,
    with the parameters the harness's registry gives them (conf/method/*.yaml)."""
    from harness.method_registry import named_or_plugin
    from sshade.deform_command import sshade_method
    for name in ("SShaDe", "SShaDe+refine"):
        ours, theirs = sshade_method(name, {"n_samplings": 2}), named_or_plugin(name, {"n_samplings": 2})
        assert type(ours) is type(theirs) and vars(ours).keys() == vars(theirs).keys()
        assert {k: v for k, v in vars(ours).items() if k != "criterion"} == \
            {k: v for k, v in vars(theirs).items() if k != "criterion"}
    outs = []
    for i, cli in enumerate((_cli, _harness_cli)):
        rc, _, err = cli([bar["off"], "--sel", bar["sel"], "--def", bar["def"], "-o", tmp_path / f"s{i}.ply",
                          *SSHADE], capsys)
        assert rc == 0, err
        outs.append(_out(tmp_path / f"s{i}.ply"))
    assert np.array_equal(outs[0], outs[1])
    rc, _, err = _cli([bar["off"], "--sel", bar["sel"], "--def", bar["def"], "-o", tmp_path / "a.ply",
                       "--method", "ARAP"], capsys)
    assert rc == 2 and "python -m harness deform runs every method" in err and not (tmp_path / "a.ply").exists()


def test_unreferenced_vertices_are_dropped_with_a_warning(bar, tmp_path, capsys):
    V, F = bar["V"], bar["F"]
    V2 = np.vstack([[9.0, 9, 9], V])  # vertex 0 on no face, a fixed vertex in the .sel
    write_mesh(tmp_path / "u.ply", V2, F + 1)
    write_sel(tmp_path / "u.sel", np.r_[FIXED, bar["status"]])
    rc, _, err = _cli([tmp_path / "u.ply", "--sel", tmp_path / "u.sel", "--def", bar["def"], "-o",
                       tmp_path / "o.ply", *SSHADE], capsys)
    assert rc == 0
    assert err.count("warning:") == 1 and "dropped 1 unreferenced vertices" in err and "1 of them handles" in err
    assert np.abs(_out(tmp_path / "o.ply") - _api(bar)[2]).max() <= 1e-9


def test_two_components_from_the_command_line(tmp_path, capsys):
    from scipy.spatial.distance import pdist

    from .test_components import _body_and_sphere
    V, F, h, t, nb = _body_and_sphere()
    write_mesh(tmp_path / "two.ply", V, F)
    (tmp_path / "h.json").write_text(json.dumps({"handles": h.tolist(), "targets": t.tolist()}))
    rc, stdout, err = _cli([tmp_path / "two.ply", "--handles", tmp_path / "h.json", "-o", tmp_path / "o.ply",
                            *SSHADE], capsys)
    assert rc == 0, err
    Vd = _out(tmp_path / "o.ply")
    assert "2 components" in stdout
    assert np.abs(pdist(Vd[nb:]) - pdist(V[nb:])).max() < 1e-9
    assert np.abs(Vd - deform(V, F, h, t, **API)).max() <= 1e-9


def test_repair_fixes_and_reports(bar, tmp_path, capsys):
    V, F = bar["V"], bar["F"]
    n = len(V)
    V2 = np.vstack([V, [2.0, 0.5, 3.0]])
    F2 = np.vstack([F, F[5], [F[0, 0], F[0, 1], n]])  # a duplicate face and a third face on an edge
    write_mesh(tmp_path / "bad.ply", V2, F2)
    write_sel(tmp_path / "bad.sel", np.r_[bar["status"], FREE])
    args = [tmp_path / "bad.ply", "--sel", tmp_path / "bad.sel", "--def", bar["def"], "-o", tmp_path / "o.ply",
            *SSHADE]
    rc, _, err = _cli(args, capsys)
    assert rc == 2 and err.startswith("error:") and "--repair" in err and len(err.strip().splitlines()) == 1
    rc, stdout, err = _cli([*args, "--repair"], capsys)
    assert rc == 0, err
    assert "repair: duplicate faces removed: 1" in stdout and "faces removed on non-manifold edges: 1" in stdout
    Vd, Fd = read_mesh(tmp_path / "o.ply")
    assert len(Fd) == len(F2) - 2 and len(Vd) <= n + 1


def test_repair_removes_a_face_of_rounding_level_area_that_validation_refuses(tmp_path, capsys):
    """A face whose third corner lies on its first edge up to rounding (area ~1e-17, not
    exactly 0): refused without --repair, removed with it (MeshLab's null-face filter,
    an exact test, kept it and the repaired mesh was refused again)."""
    from sshade.mesh.repair import NEAR_ZERO, repair_mesh

    from .conftest import icosphere
    V, F = icosphere()
    a, b, c = F[0]
    V[c] = 0.3 * V[a] + 0.7 * V[b]
    V2, F2, origin, report = repair_mesh(V, F)
    assert report[0] == (NEAR_ZERO, 0, -1) and len(F2) == len(F) - 1 and np.array_equal(V2, V[origin])
    write_mesh(tmp_path / "z.obj", V, F)
    (tmp_path / "h.json").write_text(json.dumps({"handles": [1, 2, 3], "targets": V[[1, 2, 3]].tolist()}))
    args = [tmp_path / "z.obj", "--handles", tmp_path / "h.json", "-o", tmp_path / "o.obj", "--n-low", "20"]
    rc, _, err = _cli(args, capsys)
    assert rc == 2 and "degenerate (zero-area) faces" in err
    rc, stdout, err = _cli([*args, "--repair"], capsys)
    assert rc == 0, err
    assert f"repair: {NEAR_ZERO}: 1" in stdout and len(read_mesh(tmp_path / "o.obj")[1]) == len(F) - 1


# ------------------------------------------------------------------ bad input

def _bad_cases(b, d):
    """name -> (argument list, word in the error)."""
    def w(name, text):
        p = d / name
        p.write_text(text)
        return p

    off, sel, def_, n = b["off"], b["sel"], b["def"], len(b["V"])
    ok = [off, "--sel", sel, "--def", def_, "-o", d / "o.ply"]
    sel_txt = sel.read_text()
    return {
        "missing mesh": ([d / "none.off", *ok[1:]], "not found"),
        "garbage mesh": ([w("g.off", "OFF\n3 x\n"), *ok[1:]], "unreadable"),
        "sel too short": ([off, "--sel", w("s.sel", "\n".join(sel_txt.splitlines()[:-1])), *ok[3:]],
                          f"{n - 1} vertex values but the mesh has {n}"),
        "sel bad value": ([off, "--sel", w("v.sel", sel_txt.replace("\n1\n", "\n3\n", 1)), *ok[3:]], "is '3'"),
        "sel all free": ([off, "--sel", w("f.sel", "1\n" * n), *ok[3:]], "every vertex is free"),
        "def 3 numbers a row": ([*ok[:3], "--def", w("a.def", "1 0 0\n0 1 0\n0 0 1\n"), *ok[5:]], "4x4"),
        "def singular": ([*ok[:3], "--def", w("b.def", "1 0 0 0\n0 1 0 0\n0 0 0 0\n0 0 0 1\n"), *ok[5:]], "singular"),
        "def projective": ([*ok[:3], "--def", w("c.def", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n"), *ok[5:]],
                           "not [0, 0, 0, 1]"),
        "def NaN": ([*ok[:3], "--def", w("e.def", "1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"), *ok[5:]], "NaN"),
        "def words": ([*ok[:3], "--def", w("f.def", "one 0 0 0\n"), *ok[5:]], "not a 4x4 matrix of numbers"),
        "dmat garbage": ([off, "--dmat", w("g.dmat", "hello\n"), *ok[3:]], "unreadable .dmat"),
        "dmat wrong count": ([off, "--dmat", w("c.dmat", "1 3\n0\n1\n-1\n"), *ok[3:]], "one value per vertex"),
        "dmat bad value": ([off, "--dmat", w("v.dmat", f"1 {n}\n-2\n" + "0\n" * (n - 1)), *ok[3:]],
                           "selection value -2"),
        "json missing key": ([off, "--handles", w("k.json", '{"handles": [0]}'), "-o", d / "o.ply"], "\"targets\""),
        "json out of range": ([off, "--handles", w("r.json", json.dumps({"handles": [n], "targets": [[0, 0, 0]]})),
                               "-o", d / "o.ply"], "out of range"),
        "json float index": ([off, "--handles", w("i.json", '{"handles": [1.5], "targets": [[0, 0, 0]]}'),
                              "-o", d / "o.ply"], "integer vertex indices"),
        "json not json": ([off, "--handles", w("n.json", "{handles"), "-o", d / "o.ply"], "unreadable JSON"),
        "csv NaN": ([off, "--handles", w("n.csv", "0,1,nan,2\n"), "-o", d / "o.ply"], "NaN"),
        "csv bad index": ([off, "--handles", w("b.csv", "a,1,2,3\n"), "-o", d / "o.ply"], "is not an integer"),
        "csv 3 fields": ([off, "--handles", w("t.csv", "0,1,2\n"), "-o", d / "o.ply"], "has 3 fields"),
        "handles txt": ([off, "--handles", w("h.txt", "0 1 2 3\n"), "-o", d / "o.ply"], ".json or .csv"),
        "output stl": ([*ok[:5], "-o", d / "o.stl"], "unsupported format '.stl'"),
        "no handles": ([off, "-o", d / "o.ply"], "exactly one of"),
        "sel without def": ([off, "--sel", sel, "-o", d / "o.ply"], "needs --def"),
        "unknown method": ([*ok, "--method", "Nope"], "--method Nope: python -m sshade deform runs SShaDe"),
        "refine param for SShaDe": ([*ok, "--param", "refine_etol=1e-3"], "SShaDe has no parameter 'refine_etol'"),
        "bad n-low": ([*ok, "--n-low", "2"], "n_low must be at least 4"),
        "bad param": ([*ok, "--param", "oops"], "expected KEY=VALUE"),
        "missing -o": ([off, "--sel", sel, "--def", def_], "required: -o/--out"),
    }


def test_every_bad_file_is_one_clear_line(bar, tmp_path, capsys):
    cases = _bad_cases(bar, tmp_path)
    for name, (args, word) in cases.items():
        try:
            rc = main(["deform", *map(str, args)])
        except SystemExit as e:  # argparse's usage errors
            rc = e.code
        out, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert rc == 2, name
        assert len(lines) == 1 and lines[0].startswith("error: "), (name, err)
        assert word in lines[0], (name, lines[0])
        assert not (tmp_path / "o.ply").exists(), name


def test_python_m_sshade_deform_subprocess(bar, tmp_path):
    """The shim: stage times on stdout, status 0; bad input: status 2, one line, no traceback."""
    out = tmp_path / "s.ply"
    r = subprocess.run([sys.executable, "-m", "sshade", "deform", str(bar["off"]), "--sel", str(bar["sel"]),
                        "--def", str(bar["def"]), "-o", str(out), *SSHADE], cwd=tmp_path, env=subprocess_env(),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    for stage in ("read", "handles", "deform", "write", "total"):
        assert f"  {stage}" in r.stdout
    assert np.abs(_out(out) - _api(bar)[2]).max() <= 1e-9
    r = subprocess.run([sys.executable, "-m", "sshade", "deform", str(bar["off"]), "--sel", str(bar["def"]),
                        "--def", str(bar["def"]), "-o", str(out)], cwd=ROOT, env=subprocess_env(),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert r.stderr.startswith("error: ") and "a .sel line is 0" in r.stderr


def test_def_file_round_trip(tmp_path):
    M = twist_matrix(37.0)
    write_def(tmp_path / "m.def", M)
    from sshade.mesh.handle_files import read_def
    assert np.array_equal(read_def(tmp_path / "m.def"), M)

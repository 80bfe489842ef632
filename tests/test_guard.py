"""sshade/guard.py, the guarded run of any method: a plug-in must never corrupt results. Its
output is checked in one place (sshade.mesh.validate.validate_deformed) before anything is
measured or written; it runs through one guard (sshade.guard.run_method) on read-only
copies, its exceptions (SystemExit included) and time-outs become a failed case, a result
whose handles miss their targets is a failed case, names and info values cannot break a
table. The misbehaving plug-ins are in tests/bad_methods.py; each is tried in the evaluator
and in ``python -m sshade deform``."""
from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

from eval.app import CONF_DIR
from eval.config_check import check_config
from examples.twisted_bar import write_case
from harness.__main__ import main as cli_main
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env

MINE = "{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:20}"


def _bad(cls: str, **kw) -> str:
    extra = "".join(f",{k}:{v}" for k, v in kw.items())
    return f"{{_target_:tests.bad_methods.{cls}{extra}}}"


def _compose(overrides):
    from hydra import compose, initialize_config_dir
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=["dataset=faust", *overrides])


def _evaluate(tmp_path, root, methods: list[str], *extra):
    """``run()`` on FAUST's first case with the given ``methods`` items; returns (result,
    cases.csv as strings, table.csv, table.md)."""
    from eval.app import run
    cfg = _compose([f"dataset.root={root}", "dataset.limit=1", "reference.cases=none", f"out_dir={tmp_path}",
                    f"methods=[{','.join(methods)}]", *extra])
    res = run(check_config(cfg))
    cases = pd.read_csv(tmp_path / "cases.csv", keep_default_na=False, dtype=str)
    return res, cases.set_index("method"), pd.read_csv(tmp_path / "table.csv").set_index("method"), \
        (tmp_path / "table.md").read_text()


@pytest.fixture(scope="module")
def bar(tmp_path_factory):
    """A coarse twisted bar in the survey format (bar.off, bar.sel, bar.def)."""
    d = tmp_path_factory.mktemp("bar")
    return write_case(d, angle=90.0, h=0.15)["paths"]


def _cli(bar, out, method, *extra, capsys):
    rc = cli_main(["deform", str(bar["off"]), "-o", str(out), "--sel", str(bar["sel"]), "--def", str(bar["def"]),
                   "--method", method, *extra])
    o, e = capsys.readouterr()
    return rc, o, e


def _one_error_line(rc, err, out, fragment):
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert fragment in lines[0], lines[0]
    assert not out.exists() and not list(out.parent.glob(f"*{out.name}*tmp*"))


# ------------------------------------------------------------------ 1. one output check

@pytest.mark.parametrize("U, fragment", [
    (np.zeros((495, 3)), "shape (495, 3)"),
    (np.zeros(1500), "shape (1500,)"),
    (np.full((500, 3), np.nan), "NaN/inf"),
    (np.zeros((500, 3)) + 0j, "complex"),
    (np.zeros((500, 3)).astype(str), "not numeric"),
    (None, "not numeric"),
    ([[0.0, 1.0], [2.0]], "not numeric"),
    (np.r_[np.zeros((499, 3)), [[1e12, 0, 0]]], "bounding-box diagonals"),
])
def test_validate_deformed_refuses_bad_output(U, fragment):
    from sshade.mesh.validate import validate_deformed
    V = np.random.default_rng(0).random((500, 3))
    with pytest.raises(SShaDeError, match=re.escape(fragment)) as e:
        validate_deformed(U, 500, V=V, name="Mine")
    assert str(e.value).startswith("Mine") and "\n" not in str(e.value)


def test_validate_deformed_converts_good_output():
    from sshade.mesh.validate import validate_deformed
    V = np.random.default_rng(0).random((10, 3))
    src = np.asfortranarray(V.astype(np.float32))
    U = validate_deformed(src, 10, V=V)
    assert U.dtype == np.float64 and U.flags.c_contiguous and U.flags.writeable and U.shape == (10, 3)
    np.testing.assert_array_equal(U, src.astype(np.float64))
    U[0] = 5.0  # a copy: the method's own array is untouched
    assert src[0, 0] != 5.0
    # far, but within 1e6 diagonals: accepted
    assert validate_deformed(V + 1e3, 10, V=V).shape == (10, 3)


def test_evaluator_records_bad_output_and_goes_on(tmp_path, faust_root):
    bad = {"ShortOutput": "shape (6885, 3)", "NaNOutput": "NaN/inf", "InfOutput": "NaN/inf",
           "ComplexOutput": "complex", "TextOutput": "not numeric", "NoneOutput": "not numeric",
           "HugeOutput": "bounding-box diagonals", "FlatOutput": "shape (20670,)"}
    res, cases, table, md = _evaluate(tmp_path, faust_root, [*map(_bad, bad), MINE])
    assert res["n_errors"] == len(bad)
    for name, fragment in bad.items():
        assert cases.loc[name, "error"].startswith(f"{name} returned") and fragment in cases.loc[name, "error"], name
        assert cases.loc[name, "volume_err_pct"] == ""  # nothing measured on a refused output
        assert table.loc[name, "n_cases"] == 0 and table.loc[name, "n_failed"] == 1
    assert cases.loc["Mine", "error"] == "" and table.loc["Mine", "n_cases"] == 1


@pytest.mark.parametrize("cls, fragment", [
    ("ShortOutput", "shape (851, 3)"), ("NaNOutput", "NaN/inf"), ("ComplexOutput", "complex"),
    ("HugeOutput", "bounding-box diagonals"), ("NoneOutput", "not numeric"), ("FlatOutput", "shape (2568,)"),
])
def test_cli_refuses_bad_output(bar, tmp_path, capsys, cls, fragment):
    out = tmp_path / "out.off"
    rc, _, err = _cli(bar, out, f"tests.bad_methods.{cls}", capsys=capsys)
    _one_error_line(rc, err, out, fragment)


# ------------------------------------------------------------------ 2. one guarded runner

def _tet():
    V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return V, F, np.array([0, 1]), np.array([[0., 0, 0], [1.0, 0.1, 0]])


def test_run_method_read_only_copies_and_every_exception():
    import tests.bad_methods as bm
    from sshade.guard import MethodFailure, run_method
    V, F, h, t = _tet()
    keep = [a.copy() for a in (V, F, h, t)]
    with pytest.raises(MethodFailure, match="read-only"):
        run_method(bm.ScalesInput(), V, F, h, t)
    for a, b in zip((V, F, h, t), keep):
        np.testing.assert_array_equal(a, b)  # the caller's arrays are untouched
    with pytest.raises(MethodFailure, match=r"SystemExit: 0"):
        run_method(bm.Exits(), V, F, h, t)
    with pytest.raises(KeyboardInterrupt):  # Ctrl-C stops the run
        run_method(bm.Interrupted(), V, F, h, t)
    r = run_method(bm.RestPose(), V, F, h, t)
    np.testing.assert_array_equal(r.U, V)
    assert r.U is not V and r.seconds >= 0 and r.compile_s == 0.0


def test_run_method_timeout():
    import tests.bad_methods as bm
    from sshade.guard import MethodFailure, run_method
    V, F, h, t = _tet()
    for m in (bm.Sleeper(), bm.SwallowsAll()):
        t0 = time.perf_counter()
        with pytest.raises(MethodFailure, match=r"^timed out after 0.5 s$"):
            run_method(m, V, F, h, t, timeout_s=0.5)
        assert time.perf_counter() - t0 < 5
    assert run_method(bm.RestPose(), V, F, h, t, timeout_s=5).U.shape == (4, 3)
    import signal
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)  # no alarm left behind


def test_a_timeout_that_fires_at_once_leaves_no_alarm_and_the_handler_restored():
    """A time-out of 1 microsecond fires before the method is called: each run is a
    failure that says so, and no alarm is left armed (one left behind killed the process
    with SIGALRM, "Alarm clock", after the run had finished)."""
    code = ("import signal, time, numpy as np\n"
            "from sshade.guard import MethodFailure, run_method\n"
            "import tests.bad_methods as bm\n"
            "V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]); F = np.array([[0, 2, 1], [0, 1, 3], "
            "[0, 3, 2], [1, 2, 3]]); h = np.array([0, 1, 2]); t = V[h] + 0.1\n"
            "before = signal.getsignal(signal.SIGALRM)\n"
            "for _ in range(50):\n"
            "    try:\n"
            "        run_method(bm.RestPose(), V, F, h, t, timeout_s=1e-6)\n"
            "    except MethodFailure as e:\n"
            "        assert str(e) == 'timed out after 1e-06 s', e\n"
            "    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)\n"
            "    assert signal.getsignal(signal.SIGALRM) is before\n"
            "time.sleep(1.2)\n"
            "print('ok')\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=subprocess_env(), capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "ok", (r.returncode, r.stderr[-2000:])


def test_input_modifying_plugin_does_not_harm_later_methods(tmp_path, faust_root):
    _, alone, _, _ = _evaluate(tmp_path / "alone", faust_root, [MINE])
    _, after, _, _ = _evaluate(tmp_path / "after", faust_root, [_bad("ScalesInput"), MINE])
    assert "read-only" in after.loc["ScalesInput", "error"]
    for c in ("volume_err_pct", "area_err_pct", "edge_err_pct", "angle_err_deg", "handle_err_pct"):
        assert after.loc["Mine", c] == alone.loc["Mine", c], c


def test_sys_exit_in_a_plugin_is_a_failed_case(tmp_path, faust_root):
    res, cases, table, md = _evaluate(tmp_path, faust_root, [_bad("Exits"), MINE])
    assert cases.loc["Exits", "error"].startswith("SystemExit: 0")
    assert cases.loc["Mine", "error"] == "" and "| Mine |" in md
    assert json.loads((tmp_path / "run.json").read_text())["status"] == "done"


def test_timeout_in_the_evaluator(tmp_path, faust_root):
    t0 = time.perf_counter()
    res, cases, table, md = _evaluate(tmp_path, faust_root, [_bad("Sleeper"), MINE], "timeout_s=1")
    assert time.perf_counter() - t0 < 50
    assert cases.loc["Sleeper", "error"] == "timed out after 1 s"
    assert cases.loc["Mine", "error"] == ""


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf", "abc", "true", "1e308"])
def test_timeout_config_is_checked(tmp_path, faust_root, value):
    from eval.app import run
    from harness.command import config_error_types
    overrides = [f"dataset.root={faust_root}", "dataset.limit=1", "reference.cases=none", f"out_dir={tmp_path / 'out'}",
                 f"methods=[{MINE}]", f"timeout_s={value}"]
    if value in ("abc", "true"):  # not a number: refused by Hydra as it composes (eval/config_schema.py)
        with pytest.raises(config_error_types(), match=f"timeout_s={value}"):
            _compose(overrides)
        return
    with pytest.raises(SShaDeError, match="timeout_s must be a positive number"):
        run(check_config(_compose(overrides)))
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("cls, extra, fragment", [
    ("Exits", [], "SystemExit: 0"),
    ("ScalesInput", [], "read-only"),
    ("Sleeper", ["--timeout", "1"], "timed out after 1 s"),
])
def test_cli_guarded(bar, tmp_path, capsys, cls, extra, fragment):
    out = tmp_path / "out.off"
    rc, _, err = _cli(bar, out, f"tests.bad_methods.{cls}", *extra, capsys=capsys)
    _one_error_line(rc, err, out, fragment)


def test_cli_sys_exit_subprocess(bar, tmp_path):
    out = tmp_path / "out.ply"
    r = subprocess.run([sys.executable, "-m", "harness", "deform", str(bar["off"]), "-o", str(out), "--sel",
                        str(bar["sel"]), "--def", str(bar["def"]), "--method", "tests.bad_methods.Exits"],
                       cwd=ROOT, env=subprocess_env(), capture_output=True, text=True, timeout=120)
    _one_error_line(r.returncode, r.stderr, out, "SystemExit: 0")


@pytest.mark.parametrize("value", ["0", "-2", "nan", "x", "1e10"])
def test_cli_timeout_is_checked(bar, tmp_path, capsys, value):
    out = tmp_path / "out.off"
    rc, _, err = _cli(bar, out, "tests.plugin_example.MyMethod", "--timeout", value, capsys=capsys)
    _one_error_line(rc, err, out, "--timeout")


# ------------------------------------------------------------------ 3. failed cases in the tables

def test_a_soft_handle_method_above_the_bound_keeps_its_case_with_its_handle_error(tmp_path, faust_root):
    """A penalty method's handle error is a measure of its result: the case is not failed
    (it stays in the means, beside the others), marked handles_missed, and the table's
    note counts it with the largest Handle; the same result from a hard-handle method
    fails the case (test below)."""
    res, cases, table, md = _evaluate(tmp_path, faust_root, [_bad("SoftRestPose"), MINE])
    assert cases.loc["SoftRestPose", "error"] == "" and cases.loc["SoftRestPose", "handles_missed"] == "True"
    err = float(cases.loc["SoftRestPose", "handle_err_pct"])
    assert err > 1.0 and table.loc["SoftRestPose", "n_cases"] == 1 and table.loc["Mine", "n_cases"] == 1
    assert f"1 of 1 runs above the handle bound (handle_error_max_pct), kept in the means with their " \
           f"Handle (largest {err:.2f} %)" in md, md


def test_rest_pose_is_a_failed_case_never_best(tmp_path, faust_root):
    mine2 = MINE.replace("name:Mine,iterations:20", "name:Mine2,iterations:5")
    res, cases, table, md = _evaluate(tmp_path, faust_root, [_bad("RestPose"), MINE, mine2])
    err = cases.loc["RestPose", "error"]
    assert re.fullmatch(r"handles not reached: handle error [0-9.]+% of the diagonal > 1%", err), err
    assert float(cases.loc["RestPose", "volume_err_pct"]) == 0.0  # its metrics stay in cases.csv
    assert float(cases.loc["RestPose", "handle_err_pct"]) > 1.0
    assert table.loc["RestPose", "n_cases"] == 0 and table.loc["RestPose", "n_failed"] == 1
    assert (table.loc[["Mine", "Mine2"], "n_cases"] == 1).all()  # the common set is not emptied
    row = next(ln for ln in md.splitlines() if ln.startswith("| RestPose |"))
    assert "**" not in row and "| 0 |" in row
    assert "**" in next(ln for ln in md.splitlines() if ln.startswith("| Mine |"))  # bold among the others
    assert re.search(r"RestPose: 1 of 1 case failed: handles not reached \(1\)", md), md
    assert "RestPose failed on every case" in md
    tex = (tmp_path / "table.tex").read_text()
    assert not re.search(r"RestPose &[^\n]*textbf", tex)


def test_handle_error_threshold_config(tmp_path, faust_root):
    _, cases, _, _ = _evaluate(tmp_path, faust_root, [_bad("RestPose")], "handle_error_max_pct=1e9")
    assert cases.loc["RestPose", "error"] == ""
    from eval.app import run
    cfg = _compose([f"dataset.root={faust_root}", f"out_dir={tmp_path / 'o2'}", "handle_error_max_pct=-1"])
    with pytest.raises(SShaDeError, match="handle_error_max_pct must be a positive number"):
        run(check_config(cfg))


def test_all_failed_method_keeps_the_common_set():
    from eval.tables import compare, comparison_markdown, failure_lines
    df = pd.DataFrame([
        {"case": c, "method": m, "volume_err_pct": v, "time_s": 1.0 + v, "error": e}
        for c in ("c1", "c2")
        for m, v, e in (("ARAP", 1.0, ""), ("SShaDe", 0.5, ""), ("Bad", 0.0, "timed out after 1 s"))])
    comp = compare(df)
    assert comp.cases == ["c1", "c2"] and comp.same_cases
    md = comparison_markdown(comp, failures=failure_lines(df))
    assert "| Bad | 0 | 2 | -- |" in md and "**0.50**" in md
    assert "Bad: 2 of 2 cases failed: timed out after 1 s (2)" in md


def test_cli_rest_pose_is_refused(bar, tmp_path, capsys):
    out = tmp_path / "out.off"
    rc, _, err = _cli(bar, out, "tests.bad_methods.RestPose", capsys=capsys)
    _one_error_line(rc, err, out, "handles not reached: handle error")


# ------------------------------------------------------------------ 4. method names

@pytest.mark.parametrize("name", ["Bad\nName", "a|b", "x" * 65, "tab\tname", "a&b", "50%", " lead", "$x$"])
def test_bad_method_names_are_refused(name):
    from harness.plugins import build_method
    with pytest.raises(SShaDeError, match="method names are 1-64 characters") as e:
        build_method({"_target_": "tests.plugin_example.MyMethod", "name": name})
    assert "\n" not in str(e.value)


def test_good_method_names_and_case_insensitive_duplicates():
    from eval.method_config import make_methods
    from harness.plugins import build_method
    for name in ("SShaDe+refine", "Mine (v2)", "ARAP-SR", "a/b 1.0", "x" * 64):
        assert build_method({"_target_": "tests.plugin_example.MyMethod", "name": name}).name == name
    with pytest.raises(SShaDeError, match="listed twice"):
        mine = {"_target_": "tests.plugin_example.MyMethod", "name": "sshade"}
        make_methods(check_config({"methods": ["SShaDe", mine]}).methods)


def test_cli_refuses_a_bad_name(bar, tmp_path, capsys):
    out = tmp_path / "out.off"
    rc, _, err = _cli(bar, out, "tests.bad_methods.NewlineName", capsys=capsys)
    _one_error_line(rc, err, out, "method names are 1-64 characters")


# ------------------------------------------------------------------ 5. info values

def test_weird_info_does_not_break_cases_or_tables(tmp_path, faust_root):
    res, cases, table, md = _evaluate(tmp_path, faust_root, [_bad("WeirdInfo"), MINE])
    assert list(cases.index) == ["WeirdInfo", "Mine"] and (cases["error"] == "").all()
    assert all(re.fullmatch(r"[A-Za-z0-9_]+", c) for c in cases.columns), list(cases.columns)
    w = cases.loc["WeirdInfo"]
    assert float(w["info_n_cases"]) == 99 and w["info_error"] == "not an error" and w["info_method"] == "Other"
    assert w["text"] == "line one line two | cell" and w["ok_value"] == "2.5"
    assert w["nan_value"] == "" and w["inf_value"] == "" and w["huge_int"] == ""
    assert float(w["big_int"]) == 2.0 ** 70 and json.loads(w["list_nan"]) == [1.0, None]
    assert w["info_iterations"] == "many" and "nested" not in cases.columns and "obj" not in cases.columns
    # the keys the stop lines read: kept under their name only with the expected type
    assert float(w["info_status"]) == 3 and w["info_handle_pre_pct"] == "small" and float(w["info_handles"]) == 7
    assert (table["n_cases"] == 1).all() and (table["n_failed"] == 0).all()
    rows = [ln for ln in md.splitlines() if ln.startswith("|")]
    assert len({ln.count("|") for ln in rows}) == 1 and len(rows) == 4
    text = (tmp_path / "cases.csv").read_text()
    assert len(text.strip().splitlines()) == 3  # header + one line per row: no newline in any cell
    assert math.isfinite(float(table.loc["WeirdInfo", "volume_err_pct"]))


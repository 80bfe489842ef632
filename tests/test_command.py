"""harness/command.py and sshade/command_errors.py, the command wrappers: bad numbers, Hydra's own
errors, Ctrl-C, OSError and the builder's checks give ONE ``error: ...`` line (or
``interrupted``), the documented exit status, no traceback, and happen before any work (no
folder, no partial build).

Most checks call the wrappers in-process with the inner work replaced; the few that need
a real process (Hydra's argv handling, a real SIGINT) run their commands side by side.
"""
from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from sshade.errors import SShaDeError
from tests.conftest import ROOT, subprocess_env


# ----------------------------------------------------------------------------- helpers
def _run_many(cmds: list[list[str]], cwd, timeout: float = 180) -> list[subprocess.CompletedProcess]:
    """Run ``python -m ...`` commands, three at a time (the machine is shared)."""
    done: list = [None] * len(cmds)
    running: list = []
    todo = list(enumerate(cmds))
    t_end = time.monotonic() + timeout
    while todo or running:
        while todo and len(running) < 3:
            i, c = todo.pop(0)
            p = subprocess.Popen([sys.executable, "-m", *c], cwd=cwd, env=subprocess_env(), text=True,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            running.append((i, c, p))
        i, c, p = running.pop(0)
        out, err = p.communicate(timeout=max(1.0, t_end - time.monotonic()))
        done[i] = subprocess.CompletedProcess(c, p.returncode, out, err)
    return done


def _one_error_line(r, *needles):
    """The process exited 2 after exactly one ``error: ...`` line on stderr."""
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, (r.args, r.returncode, r.stderr[-2000:])
    assert len(lines) == 1 and lines[0].startswith("error: "), (r.args, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "HYDRA_FULL_ERROR" not in r.stderr
    assert "search path" not in lines[0] and "cannot write" not in lines[0], lines[0]  # Hydra's text, one line
    for n in needles:
        assert n in lines[0], (n, lines[0])
    return lines[0]


def _stderr_lines(capsys) -> list[str]:
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


def _compose_eval(overrides):
    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=list(overrides))


def _cases_dir(d: Path) -> Path:
    """A finished-run folder holding only a small cases.csv."""
    import pandas as pd

    from eval.tables import write_cases
    rows = [dict(case=f"c{i}", subject=0, pose=i, method=m, error="", time_s=1.0 + i, volume_err_pct=0.1,
                 edge_err_pct=0.2, angle_err_deg=0.3) for i in range(2) for m in ("ARAP", "SShaDe")]
    write_cases(pd.DataFrame(rows), d)
    return d


def _no_tmp_or_empty(d: Path):
    for p in d.rglob("*"):
        assert not p.name.endswith(".tmp"), p
        assert not (p.is_file() and p.stat().st_size == 0), p


# ----------------------------------------------------------------------------- 1. numbers
CI = ["experiment=ci", "dataset.root=/nonexistent/faust_reg"]
#: refused by Hydra as it composes the config: a value of the wrong type (eval/config_schema.py)
BAD_TYPES = [
    ("arap.max_iter=inf", "arap.max_iter"), ("arap.max_iter=1e300", "arap.max_iter"),
    ("arap_sr.alpha=abc", "arap_sr.alpha"), ("dataset.limit=abc", "dataset.limit"),
    ("dataset.limit=true", "dataset.limit"), ("dataset.seed=abc", "dataset.seed"),
    ("dataset.sample=abc", "dataset.sample"), ("dataset.sample_seed=abc", "dataset.sample_seed"),
    ("dataset.n_per_landmark=inf", "dataset.n_per_landmark"), ("figures.max_cases=abc", "figures.max_cases"),
    ("figures.enabled=maybe", "figures.enabled"), ("figures.rerun_restored=maybe", "figures.rerun_restored"),
    ("reference.max_iter=junk", "reference.max_iter"),
    ("reference.max_iter=inf", "reference.max_iter"), ("sshade.n_samplings=abc", "n_samplings"),
    ("sshade.warm_start=abc", "warm_start"),
]
#: refused by the config check: what a type cannot say (ranges, words, lists of integers)
BAD_VALUES = [
    ("arap.tol=nan", "arap.tol"), ("arap.etol=-1", "arap.etol"), ("dataset.limit=0", "dataset.limit"),
    ("dataset.baseline_cases=abc", "dataset.baseline_cases"), ("dataset.baseline_cases=-1", "dataset.baseline_cases"),
    ("dataset.sample=0", "dataset.sample"), ("dataset.sample_seed=-1", "dataset.sample_seed"),
    ("dataset.static_threshold=nan", "dataset.static_threshold"), ("dataset.subjects=[0,abc]", "dataset.subjects"),
    ("reference.time_budget_s=junk", "reference.time_budget_s"),
    ("reference.time_budget_s=-5", "reference.time_budget_s"),
    ("sshade.n_low=inf", "n_low"), ("sshade.n_low=1e300", "n_low"), ("sshade.seed=-1", "seed"),
    ("sshade.workers=0", "workers"), ("+sshade.max_iter=nan", "max_iter"),
]


def _refusal(overrides) -> tuple[str, str]:
    """Where a config is refused and the one-line message: ``("compose", Hydra's)`` or
    ``("check", eval.config_check's)``; ``("", "")`` when it is accepted."""
    from eval.config_check import check_config
    from harness.command import config_error_types, hydra_message
    try:
        cfg = _compose_eval(overrides)
    except config_error_types() as e:
        return "compose", hydra_message(e)
    try:
        check_config(cfg)
    except SShaDeError as e:
        return "check", str(e)
    return "", ""


@pytest.mark.parametrize("override,key", BAD_TYPES)
def test_composition_rejects_wrong_types(override, key):
    assert _refusal(CI) == ("", "")  # the same config without the bad value is fine
    where, msg = _refusal([*CI, override])
    assert where == "compose" and key in msg, (where, msg)


@pytest.mark.parametrize("override,key", BAD_VALUES)
def test_check_config_rejects_junk_numbers(override, key):
    where, msg = _refusal([*CI, override])
    assert where == "check" and key in msg, (where, msg)


def test_check_config_experiment_sections():
    ok = set()
    for exp, bad, where in [("scaling", "scaling.elastic_budget_s=inf", "check"),
                            ("tosca", "tosca.min_vertices=abc", "compose"),
                            ("tosca", "tosca.min_vertices=-1", "check"),
                            ("tosca", "sshade.n_samplings=abc", "compose"),
                            ("pose_transfer", "sshade.seed=nan", "compose"),
                            ("convergence", "convergence.time_budget_s=abc", "check"),
                            ("shapes", "dataset.vertex_range=[10,abc]", "compose"),
                            ("shapes", "dataset.vertex_range=[10,2]", "check")]:
        if exp not in ok:  # each experiment's own config is accepted (once each)
            ok.add(exp)
            assert _refusal([f"experiment={exp}"]) == ("", "")
        got, msg = _refusal([f"experiment={exp}", bad])
        assert got == where and bad.split("=")[0] in msg, (bad, got, msg)


def test_config_number_helper():
    from omegaconf import OmegaConf

    from harness.checks import check_number, config_value
    cfg = OmegaConf.create({"a": {"n": 5, "x": 2.5, "s": "7", "none": None, "big": 1e300, "b": True}})

    def number(key, default=None, **kw):  # a key read once from the config, then checked
        return check_number(config_value(cfg, key, default), key, **kw)
    assert number("a.n", kind=int, min=1) == 5
    assert number("a.x", kind=float, min=0) == 2.5
    assert number("a.none", kind=int, allow_none=True) is None
    assert number("a.missing", 3, kind=int) == 3
    for key, kw in [("a.x", {"kind": int}), ("a.s", {"kind": int}), ("a.big", {"kind": int}),
                    ("a.b", {"kind": int}), ("a.none", {"kind": int}), ("a.n", {"kind": int, "min": 6}),
                    ("a.n", {"kind": int, "max": 4}), ("a.big", {"kind": float, "max": 1e6})]:
        with pytest.raises(SShaDeError, match=key.replace(".", r"\.")):
            number(key, **kw)


@pytest.mark.slow
def test_eval_bad_numbers_cli_before_any_work(tmp_path, faust_root):
    bad = ["arap.max_iter=inf", "dataset.limit=abc", "reference.time_budget_s=junk", "sshade.n_low=1e300"]
    cmds = [["eval", "experiment=ci", f"dataset.root={faust_root}", f"out_dir={tmp_path / f'run{i}'}", b]
            for i, b in enumerate(bad)]
    for i, (b, r) in enumerate(zip(bad, _run_many(cmds, tmp_path))):
        _one_error_line(r, b.split("=")[0].split(".")[-1])
        assert not (tmp_path / f"run{i}").exists(), b  # refused before Hydra made the run folder


TET_V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


BAD_DEFORM = [
    {"n_low": float("inf")}, {"n_low": float("nan")}, {"n_low": 1e300}, {"n_low": True}, {"n_low": "abc"},
    {"n_low": -5}, {"n_samplings": 0}, {"n_samplings": float("inf")}, {"n_samplings": 2**40}, {"seed": -1},
    {"seed": float("nan")}, {"seed": 2**70}, {"workers": 0}, {"workers": 1.5}, {"tol": float("inf")},
    {"max_iter": float("inf")}, {"max_iter": 1e300}, {"warm_start": "no"}, {"etol": float("nan")},
    {"gtol": "abc"}]


def test_deform_api_rejects_junk_numbers():
    from sshade import deform
    from sshade.pipeline import check_params
    assert check_params(n_low=4.0, seed=2**32 - 1, n_samplings=3, warm_start=np.bool_(False))["n_low"] == 4
    for kw in BAD_DEFORM:
        with pytest.raises(SShaDeError, match=next(iter(kw))):
            deform(TET_V, TET_F, [0], TET_V[:1], **kw)


# ----------------------------------------------------------------------------- 2. builder
GOOD_BUILD = dict(source="synthetic", n_subjects=1, vertex_range=(8000, 12000), remesh_iterations=3,
                  synthetic_vertices=2500, synthetic_voxel=0.02, progress=False)


@pytest.mark.parametrize("bad", [
    {"n_per_landmark": 0}, {"n_per_landmark": 100}, {"neighbourhood": 0}, {"static_threshold": -1.0},
    {"static_threshold": float("nan")}, {"vertex_range": (0, 10)}, {"vertex_range": (20, 10)},
    {"vertex_range": (10,)}, {"vertex_range": (8000, float("inf"))}, {"remesh_iterations": -1},
    {"seed": -1}, {"seed": "abc"}, {"n_subjects": 0}, {"n_poses": 1}, {"synthetic_vertices": 0},
    {"synthetic_voxel": 0.0}, {"synthetic_blend": float("nan")}, {"synthetic_remesh_iterations": 1e300},
    {"subjects": [-1]}, {"progress": "yes"}])
def test_builder_checks_every_parameter_first(tmp_path, bad):
    from defaust.build import BuildConfig, build_defaust
    out = tmp_path / "new"
    t0 = time.perf_counter()
    with pytest.raises(SShaDeError, match=next(iter(bad))):
        build_defaust(BuildConfig(out=out, **{**GOOD_BUILD, **bad}))
    assert time.perf_counter() - t0 < 5.0  # refused before building anything
    assert not out.exists()


def test_builder_failure_leaves_no_empty_folder(tmp_path, monkeypatch):
    """A remesh that cannot reach the vertex range (only known once tried) leaves no
    empty folder behind; a folder the user made is kept."""
    import defaust.build as b

    def unreachable(*a, **k):
        raise SShaDeError("isotropic remesh did not reach [8000, 8001] vertices in 4 attempts")
    monkeypatch.setattr(b, "_build_rest", unreachable)
    out = tmp_path / "new"
    with pytest.raises(SShaDeError, match="did not reach"):
        b.build_defaust(b.BuildConfig(out=out, **GOOD_BUILD))
    assert not out.exists()
    mine = tmp_path / "mine"
    mine.mkdir()
    with pytest.raises(SShaDeError, match="did not reach"):
        b.build_defaust(b.BuildConfig(out=mine, **GOOD_BUILD))
    assert mine.is_dir()


@pytest.mark.slow
def test_defaust_cli_bad_values_and_hydra_errors(tmp_path):
    cases = [(["seed=abc"], "seed"), (["handles.n_per_landmark=0"], "n_per_landmark"),
             (["high_res.vertex_range=[20,10]"], "vertex_range"), (["synthetic.voxel_size=inf"], "voxel"),
             (["foo=1"], "foo"), (["preset=nope"], "nope"), (["subjects=[0"], "subjects")]
    cmds = [["defaust", "source=synthetic", f"out={tmp_path / f'new{i}'}", *ov] for i, (ov, _) in enumerate(cases)]
    for i, ((ov, key), r) in enumerate(zip(cases, _run_many(cmds, tmp_path))):
        _one_error_line(r, key)
        assert not (tmp_path / f"new{i}").exists(), ov


# ----------------------------------------------------------------------------- 3. Hydra's errors
@pytest.mark.slow
def test_hydra_errors_are_one_line(tmp_path):
    cases = [(["eval", "foo=1"], "foo"), (["eval", "dataset=nope"], "dataset/nope"),
             (["eval", "hydra/launcher=nope"], "launcher/nope"), (["eval", "methods=[A"], "[A"),
             (["eval.sweeps", "foo=1"], "foo"), (["eval.sweeps", "-m", "sshade.n_low=1,2", "foo=1"], "foo"),
             (["eval.sweeps", "-m", "dataset=faust,nope"], "dataset/nope"), (["eval", "--cfg", "job", "foo=1"], "foo")]
    res = _run_many([c for c, _ in cases] + [["eval", "--cfg", "job", "experiment=ci"]], tmp_path)
    for (_cmd, key), r in zip(cases, res):
        _one_error_line(r, key)
    ok = res[-1]  # Hydra's own flags still work
    assert ok.returncode == 0 and "experiment:" in ok.stdout and "name: ci" in ok.stdout, ok.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no outputs/ folder made


# ----------------------------------------------------------------------------- 4. Ctrl-C
@pytest.mark.slow
def test_sigint_eval_prints_interrupted(tmp_path, faust_root):
    """Ctrl-C while a method runs (a plug-in that sleeps in its first deform call, so the
    signal always lands mid-run, however loaded the machine): one line, exit 130."""
    out, calls = tmp_path / "run", tmp_path / "calls.txt"
    env = dict(subprocess_env(), SSHADE_TEST_COUNTER=str(calls), SSHADE_TEST_HANG_AFTER="0")
    p = subprocess.Popen([sys.executable, "-m", "eval", "experiment=ci", f"dataset.root={faust_root}",
                          f"out_dir={out}", "dataset.limit=1", "reference.cases=none",
                          "methods=[{_target_:tests.store_methods.Counted,name:Hang}]"], cwd=ROOT, env=env, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        t_end = time.monotonic() + 120
        while not calls.is_file() and p.poll() is None and time.monotonic() < t_end:
            time.sleep(0.1)
        assert p.poll() is None, p.communicate()
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert p.returncode == 130, err[-3000:]
    assert lines[-1] == "interrupted" and "Traceback" not in err, err[-3000:]


def test_swallowed_ctrl_c_still_ends_as_interrupted(capsys):
    """A library that swallows the KeyboardInterrupt (trimesh's optional imports catch
    BaseException) does not turn a Ctrl-C into a successful exit."""
    from harness.command import run_command

    def work():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
        except BaseException:  # noqa: BLE001 -- as trimesh does
            pass
        return 0
    assert run_command(work) == 130
    assert _stderr_lines(capsys) == ["interrupted"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # handler restored


def _raise(exc):
    def f(*a, **k):
        raise exc
    return f


def _wrapper_calls(tmp_path, monkeypatch, exc):
    """(name, callable returning the exit status) for every command, its work raising ``exc``."""
    import defaust.cli
    import eval.app
    import eval.reproduce
    import eval.sweeps.sweep_command
    import eval.tables
    import harness.__main__
    import sshade.deform_command

    def exit_code(fn, argv=None):
        def call():
            if argv is not None:
                monkeypatch.setattr(sys, "argv", argv)
            try:
                return fn()
            except SystemExit as e:
                return e.code
            except BaseException as e:  # noqa: BLE001 -- what escapes the wrapper is the failure
                return f"{type(e).__name__} escaped"
        return call

    monkeypatch.setattr(eval.app, "run_experiment", _raise(exc))
    monkeypatch.setattr(defaust.cli, "run", _raise(exc))
    monkeypatch.setattr(sshade.deform_command, "deform_file", _raise(exc))
    monkeypatch.setattr(eval.tables, "retabulate", _raise(exc))
    monkeypatch.setattr(eval.sweeps.sweep_command, "aggregate_sweep", _raise(exc))
    monkeypatch.setattr(subprocess, "call", _raise(exc))
    run_dir = _cases_dir(tmp_path / "run")
    return [("eval", exit_code(eval.app.main,
                               ["eval", "experiment=ci", "dataset.root=/x", f"out_dir={tmp_path / 'o'}"])),
            ("defaust", exit_code(defaust.cli.main, ["defaust", "source=synthetic", f"out={tmp_path / 'd'}"])),
            ("deform", exit_code(lambda: sshade.deform_command.main(["deform", "m.obj", "-o", "o.obj",
                                                                      "--handles", "h.json"]))),
            ("harness deform", exit_code(lambda: harness.__main__.main(["deform", "m.obj", "-o", "o.obj", "--handles",
                                                                         "h.json", "--method", "ARAP"]))),
            ("tables", exit_code(lambda: eval.tables.main([str(run_dir)]))),
            ("sweep", exit_code(lambda: eval.sweeps.sweep_command.main(["aggregate", str(tmp_path)]))),
            # one step (its plan reads no stored rows): the wrapper is what is tested
            ("reproduce", exit_code(lambda: eval.reproduce.main(["--only", "report"])))]


@pytest.mark.parametrize("name", ["eval", "defaust", "deform", "harness deform", "tables", "sweep", "reproduce"])
def test_wrappers_ctrl_c(tmp_path, monkeypatch, capsys, name):
    call = dict(_wrapper_calls(tmp_path, monkeypatch, KeyboardInterrupt()))[name]
    capsys.readouterr()
    assert call() == 130
    assert _stderr_lines(capsys)[-1:] == ["interrupted"]


# ----------------------------------------------------------------------------- 5. OSError
@pytest.mark.parametrize("name", ["eval", "defaust", "deform", "harness deform", "tables", "sweep", "reproduce"])
def test_wrappers_os_error_one_line(tmp_path, monkeypatch, capsys, name):
    tmp = tmp_path / "out" / ".table.csv.abc123.tmp"  # atomic_write's temporary name
    exc = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp))
    call = dict(_wrapper_calls(tmp_path, monkeypatch, exc))[name]
    capsys.readouterr()
    assert call() == 2
    assert _stderr_lines(capsys) == [f"error: cannot write {tmp_path / 'out' / 'table.csv'}: No space left on device"]


def test_tables_disk_full_leaves_nothing(tmp_path, monkeypatch, capsys):
    """ENOSPC while the tables are written: one line naming the folder, no 0-byte or
    temporary file, cases.csv untouched."""
    from eval.tables import main
    d = _cases_dir(tmp_path / "run")
    before = (d / "cases.csv").read_bytes()

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(os, "fsync", full)
    assert main([str(d)]) == 2
    lines = _stderr_lines(capsys)
    assert len(lines) == 1 and lines[0].startswith(f"error: cannot write {d}") and \
        lines[0].endswith(": No space left on device"), lines
    assert sorted(p.name for p in d.iterdir()) == ["cases.csv"] and (d / "cases.csv").read_bytes() == before
    _no_tmp_or_empty(d)


# ----------------------------------------------------------------------------- 6. eval.tables
def test_tables_cli_usage_and_missing_folders(tmp_path, capsys):
    from eval.tables import main
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0 and "usage:" in capsys.readouterr().out
    assert main([]) == 2
    err = _stderr_lines(capsys)
    assert len(err) == 1 and err[0].startswith(("usage:", "error:")), err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main([str(empty)]) == 2
    err = _stderr_lines(capsys)
    assert len(err) == 1 and err[0].startswith("error: ") and "cases.csv" in err[0], err
    good = _cases_dir(tmp_path / "good")
    assert main([str(good), str(tmp_path / "nope")]) == 2  # checked up front: nothing written anywhere
    err = _stderr_lines(capsys)
    assert len(err) == 1 and err[0].startswith("error: ") and "nope" in err[0], err
    assert sorted(p.name for p in good.iterdir()) == ["cases.csv"]
    with pytest.raises(SystemExit) as e:
        main(["--bogus"])
    assert e.value.code == 2
    err = _stderr_lines(capsys)
    assert len(err) == 1 and err[0].startswith("error: "), err


# ----------------------------------------------------------------------------- 7. one prefix
def test_argparse_errors_and_failures_start_with_error(tmp_path, monkeypatch, capsys):
    import eval.reproduce
    import eval.sweeps.sweep_command
    for call in (lambda: eval.reproduce.main(["--bogus"]), lambda: eval.sweeps.sweep_command.main(["aggregate"])):
        with pytest.raises(SystemExit) as e:
            call()
        assert e.value.code == 2
        err = _stderr_lines(capsys)
        assert len(err) == 1 and err[0].startswith("error: "), err
    monkeypatch.setattr(subprocess, "call", lambda cmd, **kw: 1)
    monkeypatch.setattr(eval.reproduce, "_print_plan", lambda selected: None)  # (its stored rows: not tested here)
    assert eval.reproduce.main([]) == 1
    err = _stderr_lines(capsys)
    assert err[-1].startswith("error: ") and "defaust" in err[-1], err
    monkeypatch.setattr(eval.sweeps.sweep_command, "_hydra_job",
                        lambda: (tmp_path / "job", ["sshade.n_low=2"], 3, None))
    monkeypatch.setattr("eval.app.run_experiment", _raise(SShaDeError("n_low must be at least 4")))
    assert eval.sweeps.sweep_command.sweep_job(_compose_eval(CI))["status"] == "failed"
    assert _stderr_lines(capsys)[-1] == "error: job 3: failed: n_low must be at least 4"

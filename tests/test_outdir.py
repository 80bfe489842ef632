"""eval/run/outdir.py, no data changed or lost: a command writes only into a folder that is
new, empty or its own earlier output of the same kind (eval/run/outdir.py); ``results/``
only under ``python -m eval.reproduce``; two runs never share a folder."""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eval.run import outdir
from eval.run.outdir import MARKER, OutputDirError, claim_output_dir
from eval.run.run_folder import claimed_run
from tests.conftest import ROOT, subprocess_env

EVAL = [sys.executable, "-m", "eval", "experiment=ci", "dataset.root=../shared/data/faust_reg",
        "dataset.limit=1", "methods=[SShaDe]"]


def _snapshot(folder: Path) -> dict:
    """relative path -> (sha256, mtime_ns) of every file below ``folder``."""
    return {str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _run(args, cwd=ROOT, timeout=240):
    return subprocess.run(args, cwd=cwd, env=subprocess_env(), capture_output=True, text=True, timeout=timeout)


def _one_error(r) -> str:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr
    assert lines and lines[-1].startswith("error: "), r.stderr
    return lines[-1]


# ----------------------------------------------------------------------------- end to end
def test_eval_refuses_results_folder_and_changes_nothing():
    res = ROOT / "results" / "faust"
    if not res.is_dir():
        pytest.skip("no committed results/faust")
    before, names = _snapshot(res), sorted(os.listdir(res))
    r = _run([*EVAL, "out_dir=results/faust"])
    msg = _one_error(r)
    assert "python -m eval.reproduce" in msg
    assert _snapshot(res) == before and sorted(os.listdir(res)) == names  # nothing changed, nothing added


def test_eval_refuses_a_users_folder_and_the_current_directory(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "cases.csv").write_text("my own data\n")
    (user / "notes.txt").write_text("keep me\n")
    before = _snapshot(user)
    msg = _one_error(_run([*EVAL, f"out_dir={user}"]))
    assert "overwrite=true" in msg and str(user) in msg
    assert _snapshot(user) == before and sorted(os.listdir(user)) == ["cases.csv", "notes.txt"]
    cwd = tmp_path / "cwd"  # out_dir= (empty) used to write everything into the current directory
    cwd.mkdir()
    (cwd / "keep.txt").write_text("x")
    env = subprocess_env()
    r = subprocess.run([*EVAL[:4], f"dataset.root={ROOT.parent / 'shared/data/faust_reg'}", *EVAL[5:], "out_dir="],
                       cwd=cwd, env=env, capture_output=True, text=True, timeout=240)
    _one_error(r)
    assert sorted(os.listdir(cwd)) == ["keep.txt"]


def test_sweep_refuses_a_users_folder(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "sweep.json").write_text("{\"mine\": true}\n")
    before = _snapshot(user)
    r = _run([sys.executable, "-m", "eval.sweeps", "-m", "dataset=faust", "dataset.root=../shared/data/faust_reg",
              "dataset.limit=1", "methods=[SShaDe]", "sshade.n_low=300,500", f"hydra.sweep.dir={user}"])
    msg = _one_error(r)
    assert "refusing to write into" in msg and str(user) in msg
    assert _snapshot(user) == before and os.listdir(user) == ["sweep.json"]


def test_refused_run_leaves_no_folder(tmp_path):
    new = tmp_path / "new"
    r = _run([*EVAL, "sshade.n_low=2", f"out_dir={new}"])
    assert "n_low" in _one_error(r)
    assert not new.exists()


# ----------------------------------------------------------------------------- the rule itself
def test_new_empty_and_file(tmp_path):
    c = claim_output_dir(tmp_path / "a" / "b", "eval")
    assert c.created and c.path.is_dir() and json.loads((c.path / MARKER).read_text())["status"] == "running"
    c.finish("done")
    (tmp_path / "empty").mkdir()
    c = claim_output_dir(tmp_path / "empty", "eval")
    assert not c.created
    c.finish("done")
    (tmp_path / "f").write_text("x")
    with pytest.raises(OutputDirError, match="is a file"):
        claim_output_dir(tmp_path / "f", "eval")
    assert (tmp_path / "f").read_text() == "x"
    with pytest.raises(OutputDirError, match="empty"):
        claim_output_dir("", "eval")


def test_own_earlier_output_is_replaced_and_named(tmp_path):
    c = claim_output_dir(tmp_path / "run", "eval")
    (c.path / "cases.csv").write_text("old")
    (c.path / "figures").mkdir()
    (c.path / "figures" / "old.png").write_bytes(b"png")
    c.finish("done")
    (c.path / "my_notes.txt").write_text("added by a person")  # not the run's: kept
    c2 = claim_output_dir(tmp_path / "run", "eval")
    assert sorted(c2.replaced) == ["cases.csv", "figures"] and "replacing" in c2.message
    assert "cases.csv" in c2.message and sorted(os.listdir(c2.path)) == sorted([MARKER, outdir.LOCK, "my_notes.txt",
                                                                                  outdir.ASIDE])
    (c2.path / "cases.csv").write_text("new")
    c2.finish("done")  # the new run has its result: the earlier one's files are gone
    assert sorted(os.listdir(c2.path)) == sorted([MARKER, outdir.LOCK, "my_notes.txt", "cases.csv"])
    with pytest.raises(OutputDirError, match="another kind of output"):  # an eval folder is no sweep folder
        claim_output_dir(tmp_path / "run", "sweep")


def test_foreign_folder_needs_overwrite(tmp_path):
    (tmp_path / "data.ply").write_text("mine")
    with pytest.raises(OutputDirError, match="overwrite=true"):
        claim_output_dir(tmp_path, "eval")
    assert os.listdir(tmp_path) == ["data.ply"]
    c = claim_output_dir(tmp_path, "eval", overwrite=True)
    (c.path / "table.md").write_text("t")
    c.finish("done")
    assert json.loads((tmp_path / MARKER).read_text())["files"] == ["table.md"]  # data.ply stays the user's
    c = claim_output_dir(tmp_path, "eval")  # now an earlier eval output: only table.md goes
    assert c.replaced == ["table.md"] and (tmp_path / "data.ply").read_text() == "mine"
    c.finish("done")


def test_two_runs_never_share_a_folder(tmp_path):
    c = claim_output_dir(tmp_path / "run", "eval")
    with pytest.raises(OutputDirError, match="another run is writing"):
        claim_output_dir(tmp_path / "run", "eval")
    c.finish("done")
    claim_output_dir(tmp_path / "run", "eval").finish("done")  # free again once the first run ended


def test_lock_dies_with_its_process(tmp_path):
    """A run killed with SIGKILL leaves a folder 'running' but unlocked: the next run replaces it."""
    code = (f"import time; from eval.run.outdir import claim_output_dir; c = claim_output_dir({str(tmp_path / 'r')!r}, "
            "'eval'); open(c.path / 'cases.csv', 'w').write('x'); print('claimed', flush=True); time.sleep(60)")
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=subprocess_env(), stdout=subprocess.PIPE,
                         text=True)
    try:
        assert p.stdout.readline().strip() == "claimed"
        with pytest.raises(OutputDirError, match="another run is writing"):
            claim_output_dir(tmp_path / "r", "eval")
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait(10)
    claim_output_dir(tmp_path / "r", "eval").finish("done")


def test_default_dated_folder_gets_a_suffix(tmp_path):
    a = claim_output_dir(tmp_path / "2026-01-01_00-00-00", "eval", fresh=True)
    b = claim_output_dir(tmp_path / "2026-01-01_00-00-00", "eval", fresh=True)
    assert a.path.name == "2026-01-01_00-00-00" and b.path.name == "2026-01-01_00-00-00_2"
    a.finish("done")
    b.finish("done")


def test_results_only_under_reproduce(tmp_path, monkeypatch):
    monkeypatch.setattr(outdir, "results_dir", lambda: tmp_path / "results")
    (tmp_path / "results" / "faust").mkdir(parents=True)
    (tmp_path / "results" / "faust" / "table.md").write_text("committed")
    monkeypatch.delenv(outdir.REPRODUCE_ENV, raising=False)
    with pytest.raises(OutputDirError, match="eval.reproduce"):
        claim_output_dir(tmp_path / "results" / "new", "eval")
    assert not (tmp_path / "results" / "new").exists()
    monkeypatch.setenv(outdir.REPRODUCE_ENV, "1")
    c = claim_output_dir(tmp_path / "results" / "faust", "eval")  # committed folder: rewritten in place
    assert c.replaced == [] and (tmp_path / "results" / "faust" / "table.md").read_text() == "committed"
    c.finish("done")


def test_reproduce_marks_its_commands(monkeypatch):
    import eval.reproduce as rep
    seen = []
    monkeypatch.setattr(rep.subprocess, "call", lambda cmd, env=None: seen.append(env) or 0)
    # the plan and the machine check read every committed row (tests/test_reproduce.py covers them)
    monkeypatch.setattr(rep, "_print_plan", lambda selected: None)
    monkeypatch.setattr(rep, "other_machine", lambda *args, **kwargs: None)
    assert rep.main([]) == 0
    assert seen and all(e.get(outdir.REPRODUCE_ENV) == "1" for e in seen)


def test_failed_run_never_stays_running(tmp_path):
    from eval.run.spec import OutputOptions
    with pytest.raises(RuntimeError):
        with claimed_run(OutputOptions(out_dir=str(tmp_path / "run"))):
            (tmp_path / "run" / "run.json").write_text(json.dumps({"status": "running"}))
            raise RuntimeError("a bug in a method")
    info = json.loads((tmp_path / "run" / "run.json").read_text())
    assert info["status"] == "failed" and "a bug in a method" in info["error"]
    with pytest.raises(KeyboardInterrupt):
        with claimed_run(OutputOptions(out_dir=str(tmp_path / "run2"))):
            (tmp_path / "run2" / "run.json").write_text(json.dumps({"status": "running"}))
            raise KeyboardInterrupt
    assert json.loads((tmp_path / "run2" / "run.json").read_text())["status"] == "interrupted"
    assert json.loads((tmp_path / "run2" / MARKER).read_text())["status"] == "interrupted"


def test_a_claim_as_a_with_block_ends_done_or_failed_and_releases_its_lock(tmp_path):
    with claim_output_dir(tmp_path / "ok", "bench", option="") as claim:
        (claim.path / "table.md").write_text("x")
    m = json.loads((tmp_path / "ok" / MARKER).read_text())
    assert m["status"] == "done" and m["files"] == ["table.md"] and claim.fd is None
    with pytest.raises(KeyboardInterrupt), claim_output_dir(tmp_path / "bad", "bench", option="") as claim:
        raise KeyboardInterrupt
    assert json.loads((tmp_path / "bad" / MARKER).read_text())["status"] == "failed" and claim.fd is None
    claim_output_dir(tmp_path / "ok", "bench", option="").finish("done")  # its own earlier output: reusable


def test_anny_figures_refuses_results(capsys):
    from eval.present.anny_figures import main
    t = time.time()
    assert main([str(ROOT / "results" / "defaust" / "figures")]) == 2
    assert "eval.reproduce" in capsys.readouterr().err and time.time() - t < 5


def test_tables_and_sweep_aggregate_refuse_results(capsys):
    from eval.sweeps.sweep_command import main as sweep_main
    from eval.tables import main as tables_main
    res = ROOT / "results"
    targets = [(tables_main, [str(res / "faust")]), (sweep_main, ["aggregate", str(res / "sweeps" / "defaust")])]
    for fn, argv in targets:
        if not Path(argv[-1]).is_dir():
            continue
        before = _snapshot(Path(argv[-1]))
        try:
            rc = fn(argv)
        except SystemExit as e:
            rc = e.code
        assert rc == 2 and "eval.reproduce" in capsys.readouterr().err
        assert _snapshot(Path(argv[-1])) == before


@pytest.mark.slow
def test_sweep_default_folder_taken_gets_a_suffix_and_jobs_follow(tmp_path):
    """Two sweeps started in the same second: the second's default dated folder exists
    (here: every name of the next minute holds a user's file); the sweep goes to
    ``<name>_2`` and so do its jobs; the user's folders are untouched."""
    import datetime
    now = datetime.datetime.now()
    taken = []
    for s in range(90):
        d = tmp_path / "outputs" / "multirun" / (now + datetime.timedelta(seconds=s)).strftime("%Y-%m-%d_%H-%M-%S")
        d.mkdir(parents=True)
        (d / "mine.txt").write_text("x")
        taken.append(d)
    r = subprocess.run([sys.executable, "-m", "eval.sweeps", "-m", "dataset=faust",
                        f"dataset.root={ROOT.parent / 'shared/data/faust_reg'}", "dataset.limit=1", "methods=[SShaDe]",
                        "sshade.n_low=300", "sshade.n_samplings=1"], cwd=tmp_path, env=subprocess_env(),
                       capture_output=True, text=True, timeout=240)
    if not (ROOT.parent / "shared/data/faust_reg").is_dir():
        pytest.skip("no FAUST registrations")
    assert r.returncode == 0, r.stderr[-2000:]
    assert all(os.listdir(d) == ["mine.txt"] for d in taken)
    new = [d for d in (tmp_path / "outputs" / "multirun").iterdir() if d.name.endswith("_2")]
    assert len(new) == 1 and (new[0] / "0" / "status.json").is_file() and (new[0] / "sweep_table.md").is_file()


@pytest.mark.parametrize("where", ["report", "figures/old.png", "runs/s0_p1"])
def test_an_earlier_output_holding_a_link_is_refused_and_nothing_outside_changes(tmp_path, where):
    """A link anywhere in an earlier output (a folder or a file) would take the next run's
    writes or removals outside it: the claim is refused, naming the link, before any work."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.txt").write_text("mine")
    c = claim_output_dir(tmp_path / "run", "eval")
    (c.path / "figures").mkdir()
    (c.path / "runs").mkdir()
    (c.path / "cases.csv").write_text("old")
    c.finish("done")
    target = outside / "keep.txt" if where.endswith(".png") else outside
    os.symlink(target, c.path / where)
    before = sorted(os.listdir(c.path))
    for kw in ({}, {"keep": True}, {"overwrite": True}):
        with pytest.raises(OutputDirError, match=f"{where} is a symbolic link"):
            claim_output_dir(tmp_path / "run", "eval", **kw)
    assert (outside / "keep.txt").read_text() == "mine" and sorted(os.listdir(outside)) == ["keep.txt"]
    assert sorted(os.listdir(c.path)) == before


def test_a_link_that_stays_inside_an_earlier_output_is_accepted(tmp_path):
    """submitit's ``.submitit/`` keeps links to its own files: a link resolving inside the
    folder cannot take a write or a removal out of it, so a resumed sweep may go on."""
    c = claim_output_dir(tmp_path / "sweep", "sweep")
    (c.path / ".submitit" / "1").mkdir(parents=True)
    (c.path / ".submitit" / "1" / "1_submission.sh").write_text("#!/bin/sh\n")
    os.symlink(c.path / ".submitit" / "1" / "1_submission.sh", c.path / ".submitit" / ".submission_file_x.sh")
    os.symlink("1", c.path / ".submitit" / "relative")  # relative, inside
    c.finish("done")
    again = claim_output_dir(tmp_path / "sweep", "sweep", keep=True)
    assert again.path == c.path and (c.path / ".submitit" / ".submission_file_x.sh").is_symlink()
    again.finish("done")
    os.symlink("../..", c.path / ".submitit" / "up")  # relative, but out of the folder
    with pytest.raises(OutputDirError, match=r"\.submitit/up is a symbolic link out of it"):
        claim_output_dir(tmp_path / "sweep", "sweep", keep=True)

"""An earlier output replaced without loss (eval/run/earlier_output.py through
eval.run.outdir's claims): a run that fails before its first result leaves the earlier output
byte for byte; files someone added inside it survive a rerun and are named; a run killed
with the earlier output set aside is recovered by the next claim."""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from eval.run import outdir
from eval.run.earlier_output import ASIDE, files_under, ours
from eval.run.outdir import LOCK, MARKER, claim_output_dir
from tests.conftest import ROOT, subprocess_env


def _bytes(folder: Path) -> dict:
    """relative path -> sha256 of every file below ``folder`` (marker and lock included)."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _earlier(tmp_path: Path) -> Path:
    """An earlier eval output with files added by a person: at the top, in ``runs/s0``, in ``report``."""
    c = claim_output_dir(tmp_path / "run", "eval", first_result="run.json")
    p = c.path
    (p / "run.json").write_text('{"status": "done"}')
    (p / "runs" / "s0").mkdir(parents=True)
    (p / "runs" / "s0" / "A.json").write_text("old record")
    (p / "report").mkdir()
    (p / "report" / "index.html").write_text("<p>old</p>")
    c.finish("done")
    (p / "my_top.txt").write_text("mine, top")
    (p / "runs" / "s0" / "notes.txt").write_text("mine, in runs")
    (p / "report" / "my.txt").write_text("mine, in report")
    return p


def test_a_claim_that_fails_before_its_first_result_leaves_the_earlier_output_byte_identical(tmp_path):
    p = _earlier(tmp_path)
    before = _bytes(p)
    c = claim_output_dir(p, "eval", first_result="run.json")
    assert sorted(c.replaced) == ["report", "run.json", "runs"] and (p / ASIDE).is_dir()
    (p / ".hydra").mkdir()
    (p / ".hydra" / "config.yaml").write_text("new run")
    (p / "eval.log").write_text("new log")
    c.finish("failed", drop_if_unused="run.json")
    assert _bytes(p) == before and not (p / ASIDE).exists()


def test_files_added_inside_an_earlier_output_survive_a_rerun_and_are_not_recorded_as_its_own(tmp_path, caplog):
    p = _earlier(tmp_path)
    c = claim_output_dir(p, "eval", first_result="run.json")
    (p / "run.json").write_text('{"status": "done", "new": 1}')
    (p / "runs" / "s0").mkdir(parents=True)
    (p / "runs" / "s0" / "A.json").write_text("new record")
    with caplog.at_level("INFO", logger="eval"):
        c.finish("done")
    assert (p / "runs" / "s0" / "notes.txt").read_text() == "mine, in runs"
    assert (p / "report" / "my.txt").read_text() == "mine, in report"
    assert (p / "my_top.txt").read_text() == "mine, top"
    assert not (p / "report" / "index.html").exists()  # the earlier run's own file, not written again
    assert (p / "runs" / "s0" / "A.json").read_text() == "new record" and not (p / ASIDE).exists()
    assert "kept 2 file(s) you added" in caplog.text and "runs/s0/notes.txt" in caplog.text
    m = json.loads((p / MARKER).read_text())
    assert sorted(m["paths"]) == ["run.json", "runs/s0/A.json"]
    assert sorted(m["user_paths"]) == ["report/my.txt", "runs/s0/notes.txt"]
    c = claim_output_dir(p, "eval", first_result="run.json")  # a third run: still theirs
    (p / "run.json").write_text("{}")
    c.finish("done")
    assert (p / "runs" / "s0" / "notes.txt").is_file() and (p / "report" / "my.txt").is_file()
    assert not (p / "runs" / "s0" / "A.json").exists()


def test_a_file_added_where_the_new_run_writes_is_kept_beside_it(tmp_path):
    p = _earlier(tmp_path)
    c = claim_output_dir(p, "eval", first_result="run.json")
    (p / "run.json").write_text("{}")
    (p / "report").mkdir()
    (p / "report" / "my.txt").write_text("the new run's file of that name")
    c.finish("done")
    assert (p / "report" / "my.txt").read_text() == "the new run's file of that name"
    assert (p / "report" / "my.txt.kept").read_text() == "mine, in report"


@pytest.mark.parametrize("had_result", [False, True])
def test_a_run_killed_with_the_earlier_output_aside_is_recovered_by_the_next_claim(tmp_path, had_result):
    p = _earlier(tmp_path)
    before = _bytes(p)
    c = claim_output_dir(p, "eval", first_result="run.json")
    (p / "partial.csv").write_text("half")
    if had_result:
        (p / "run.json").write_text('{"status": "running"}')
    outdir.alive(p)  # as after a stored record
    c.release()  # the process dies here: no finish
    c2 = claim_output_dir(p, "eval", first_result="run.json", keep=True)
    assert not (p / ASIDE).exists()
    if had_result:  # the killed run had results: its files stay, the earlier one's go, the person's come back
        assert (p / "partial.csv").is_file() and not (p / "report" / "index.html").exists()
        assert (p / "runs" / "s0" / "notes.txt").is_file() and (p / "report" / "my.txt").is_file()
        c2.finish("done")
        m = json.loads((p / MARKER).read_text())
        assert "partial.csv" in m["paths"] and "runs/s0/notes.txt" not in m["paths"]
    else:  # died before its first result: the earlier output as it was; what the dead run
        # (or someone after it) added beside stays, named in the claim's message
        assert "kept 1 that a killed run left or someone added: partial.csv" in c2.message
        c2.release()
        now = _bytes(p)
        now.pop(MARKER), before.pop(MARKER)
        now.pop(LOCK), before.pop(LOCK)
        assert now.pop("partial.csv") and now == before


def test_a_killed_claim_whose_continued_entries_hold_old_results_gets_the_earlier_output_back(tmp_path):
    """A sweep-like claim continuing job ``0`` (an old record on disk) and replacing the
    rest, killed before any job stored a new record: the old record is not its result, so
    the next claim puts the earlier output back byte for byte; killed after a job stored
    one, its own files stand as the earlier output of the claim after it."""
    first = "**/runs/*/*.json"
    c = claim_output_dir(tmp_path / "sweep", "sweep", first_result=first)
    p = c.path
    (p / "0" / "runs" / "s0").mkdir(parents=True)
    (p / "0" / "runs" / "s0" / "A.json").write_text("old row")
    (p / "sweep_table.md").write_text("old table")
    c.finish("done")
    before = _bytes(p)
    time.sleep(0.05)  # file times are coarse: the next claim a clock tick later at least
    c = claim_output_dir(p, "sweep", keep={"0"}, first_result=first)
    assert c.replaced == ["sweep_table.md"] and c.continued == ["0"]
    (p / "sweep_table.md").write_text("half a table")
    c.release()  # SIGKILL in the first job, before its first record
    claim_output_dir(p, "sweep", keep={"0"}, first_result=first).finish("failed")
    now = _bytes(p)
    assert now.pop(LOCK) and before.pop(LOCK)  # the lock names the last process that held it
    assert now == before
    c = claim_output_dir(p, "sweep", keep={"0"}, first_result=first)
    (p / "1" / "runs" / "s0").mkdir(parents=True)
    (p / "1" / "runs" / "s0" / "A.json").write_text("new row")
    (p / "sweep_table.md").write_text("half a table")
    c.release()  # SIGKILL after the first record of job 1
    claim_output_dir(p, "sweep", keep={"0"}, first_result=first).finish("failed")
    assert (p / "1" / "runs" / "s0" / "A.json").read_text() == "new row"
    assert (p / "sweep_table.md").read_text() == "half a table" and not (p / ASIDE).exists()


def test_files_added_after_a_run_was_killed_before_its_first_result_survive_the_next_commands(tmp_path):
    """Killed with the earlier output aside; a person then adds a file and a folder: the
    next command into the folder, even one refused (failed before its first result), puts
    the earlier output back and keeps both, naming them; so does the run after it."""
    p = _earlier(tmp_path)
    c = claim_output_dir(p, "eval", first_result="run.json")
    c.release()  # killed
    (p / "analysis.txt").write_text("mine, after the kill")
    (p / "myplots").mkdir()
    (p / "myplots" / "a.png").write_bytes(b"png")
    refused = claim_output_dir(p, "eval", first_result="run.json")
    assert "analysis.txt, myplots" in refused.message
    refused.finish("failed", drop_if_unused="run.json")
    assert (p / "analysis.txt").read_text() == "mine, after the kill" and (p / "myplots" / "a.png").is_file()
    assert (p / "run.json").is_file() and (p / "runs" / "s0" / "A.json").read_text() == "old record"
    c = claim_output_dir(p, "eval", first_result="run.json")
    (p / "run.json").write_text("{}")
    c.finish("done")
    assert (p / "analysis.txt").is_file() and (p / "myplots" / "a.png").is_file()


def test_files_added_after_a_run_was_killed_past_its_first_result_survive_the_next_run_and_are_named(
        tmp_path, caplog):
    """Killed after its first result and a stored record (its last sign of life); a person
    then adds a file and a folder, one inside the run's store: the next run replaces the
    killed one, keeps both and names them, and its marker does not count them as its own.
    What the killed run wrote before its last sign of life goes."""
    p = _earlier(tmp_path)
    c = claim_output_dir(p, "eval", first_result="run.json", own=("eval.log", ".hydra"))
    (p / "run.json").write_text('{"status": "running"}')
    (p / "runs" / "s0").mkdir(parents=True)
    (p / "runs" / "s0" / "A.json").write_text("killed run's record")
    (p / "eval.log").write_text("its log")
    outdir.alive(p)
    (p / "eval.log").write_text("its log, a line after its last record")  # its own, changed later
    c.release()  # SIGKILL
    time.sleep(0.05)  # a person, after the kill (file times are coarse: a clock tick at least)
    (p / "analysis.txt").write_text("mine")
    (p / "myplots").mkdir()
    (p / "myplots" / "a.png").write_bytes(b"png")
    (p / "runs" / "s0" / "mine.txt").write_text("mine too")
    c2 = claim_output_dir(p, "eval", first_result="run.json")
    assert "analysis.txt, myplots/a.png, runs/s0/mine.txt" in c2.message
    (p / "run.json").write_text("{}")
    with caplog.at_level("INFO", logger="eval"):
        c2.finish("done")
    assert (p / "analysis.txt").read_text() == "mine" and (p / "myplots" / "a.png").read_bytes() == b"png"
    assert (p / "runs" / "s0" / "mine.txt").read_text() == "mine too"
    assert not (p / "eval.log").exists() and not (p / "runs" / "s0" / "A.json").exists()  # the killed run's
    assert "kept 5 file(s)" in caplog.text and "analysis.txt" in caplog.text  # with the earlier output's two
    m = json.loads((p / MARKER).read_text())
    assert m["paths"] == ["run.json"] and {"analysis.txt", "myplots/a.png"} <= set(m["user_paths"])


@pytest.mark.parametrize("field, value", [
    ("aside.names", ["../../victim"]), ("aside.names", ["/abs"]), ("foreign", ["../sibling.txt"]),
    ("files", ["a/b"]), ("aside.user_paths", ["x/../../victim/f"]), ("user_paths", ["/etc/passwd"]),
    ("aside.first_result", "../run.json"), ("files", "run.json"), ("aside.names", [None])])
def test_a_marker_naming_anything_but_a_plain_path_inside_its_folder_is_refused_and_nothing_is_touched(
        tmp_path, field, value):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "f").write_text("not yours")
    (tmp_path / "sibling.txt").write_text("not yours either")
    p = _earlier(tmp_path / "deep")
    m = json.loads((p / MARKER).read_text())
    m["status"] = "running"
    top, _, key = field.rpartition(".")
    (m.setdefault(top, {"names": [], "user_paths": [], "first_result": "run.json"}) if top else m)[key] = value
    (p / MARKER).write_text(json.dumps(m))
    (p / ASIDE).mkdir()
    before = _bytes(tmp_path)
    with pytest.raises(outdir.OutputDirError, match=f"{MARKER}: {field} names"):
        claim_output_dir(p, "eval", first_result="run.json")
    assert _bytes(tmp_path) == before and (victim / "f").read_text() == "not yours"


def test_files_under_lists_files_and_links_and_ours_reads_both_records(tmp_path):
    (tmp_path / "d" / "e").mkdir(parents=True)
    (tmp_path / "d" / "e" / "f.txt").write_text("x")
    (tmp_path / "g").write_text("y")
    os.symlink("e", tmp_path / "d" / "link")
    assert files_under(tmp_path, ["d", "g", "absent"]) == ["d/e/f.txt", "d/link", "g"]
    assert ours({"paths": ["g"]})("g") and not ours({"paths": ["g"]})("d/e/f.txt")
    assert ours({"user_paths": ["g"]})("d/e/f.txt") and not ours({"user_paths": ["g"]})("g")
    assert ours(None)("anything")


# ----------------------------------------------------------------------------- end to end
EVAL = [sys.executable, "-m", "eval", "experiment=ci", "dataset.root=../shared/data/faust_reg", "dataset.limit=1",
        "methods=[SShaDe]"]


def _run(args):
    return subprocess.run(args, cwd=ROOT, env=subprocess_env(), capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_a_bad_input_into_an_earlier_eval_output_is_refused_and_leaves_it_byte_identical(tmp_path):
    if not (ROOT.parent / "shared" / "data" / "faust_reg").is_dir():
        pytest.skip("needs ../shared/data/faust_reg")
    p = tmp_path / "P"
    r = _run([*EVAL, f"out_dir={p}"])
    assert r.returncode == 0, r.stderr[-2000:]
    (p / "runs").mkdir(exist_ok=True)
    (p / "my_notes.txt").write_text("mine")
    before = _bytes(p)
    notrun = tmp_path / "not_a_run"
    notrun.mkdir()
    score = ["experiment=score", "score.name=Theirs"]
    for bad in (["dataset.root=/nonexistent"], [f"compare_with=[{notrun}]"], [f"compare_with=[{p}]"],
                ["sshade.n_low=2"], [*score, "score.results=/nonexistent"], [*score, f"score.results={notrun}",
                                                                              "score.times=/dev/zero"]):
        r = _run([*EVAL, f"out_dir={p}", *bad])
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 2 and lines[-1].startswith("error: ") and "Traceback" not in r.stderr, (bad, r.stderr)
        assert _bytes(p) == before, bad
        assert not (p / outdir.ASIDE).exists()


def test_an_unrecorded_set_aside_folder_is_refused_naming_it_and_what_to_do(tmp_path):
    """A .sshade-earlier that no run recorded (made by hand, or copied with the folder):
    the claim names it and what to do, moves nothing and leaves the lock free."""
    p = _earlier(tmp_path)
    (p / ASIDE).mkdir()
    (p / ASIDE / "x.txt").write_text("someone's")
    before = _bytes(p)
    with pytest.raises(outdir.OutputDirError, match=f"holds {ASIDE}, which no run recorded.*move it out"):
        claim_output_dir(p, "eval", first_result="run.json")
    assert _bytes(p) == before
    (p / ASIDE / "x.txt").unlink()
    (p / ASIDE).rmdir()
    claim_output_dir(p, "eval", first_result="run.json").release()  # the lock was released

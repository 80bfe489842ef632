"""eval/run/pending_rows.py: how a table marks its rows made by older code and how
``--check`` reads the marks back; the evaluator's early stop read from the environment."""
from __future__ import annotations

import os
import time

import pytest

from eval.present.meshview import OTHER_DATA_KIND, case_view_path, read_view
from eval.run.pending_rows import (
    STOP_AFTER_ENV,
    STOP_BY_ENV,
    marked_pending,
    pending_markdown,
    pending_on_other_data,
    pending_title,
    share_stop,
    short_commit,
    stop_after_s,
    strip_pending,
)
from eval.run.stale_rows import RowState
from sshade.errors import SShaDeError


def _states(tmp_path):
    return [RowState(tmp_path, "s0_p1", "ARAP", False, commit="a" * 40),
            RowState(tmp_path, "s0_p2", "ARAP", True, "sshade.guard changed since 3e79476",
                     commit="3e79476" + "0" * 33),
            RowState(tmp_path, "s0_p2", "Implicit-ARAP", True, "invalid: not a record", commit=None)]


def test_what_a_table_writes_of_its_pending_rows_is_read_back_exactly(tmp_path):
    states = _states(tmp_path)
    title = pending_title("faust: 2 cases", states)
    assert title == "faust: 2 cases (1 of 3 rows made by this commit's code; 2 pending from 3e79476, unknown)"
    assert strip_pending(title) == "faust: 2 cases" and pending_title(title, states[:1]) == "faust: 2 cases"
    (tmp_path / "table.md").write_text(f"### {title}\n\n| table |\n\n{pending_markdown(states)}")
    assert marked_pending(tmp_path) == {("s0_p2", "ARAP", "3e79476"): "sshade.guard changed since 3e79476",
                                        ("s0_p2", "Implicit-ARAP", "unknown"): "invalid: not a record"}
    assert pending_markdown(states[:1]) == "" and short_commit(12) == "unknown"


def test_a_linked_or_missing_table_marks_nothing(tmp_path):
    (tmp_path / "elsewhere.md").write_text(pending_markdown(_states(tmp_path)))
    assert marked_pending(tmp_path) == {}
    os.symlink(tmp_path / "elsewhere.md", tmp_path / "table.md")
    assert marked_pending(tmp_path) == {}  # a link is not read: no mark comes from outside the folder


@pytest.mark.parametrize("text, want", [("", None), ("  ", None), ("20", 20.0), ("0.5", 0.5)])
def test_the_early_stop_is_a_number_of_seconds_or_nothing(text, want):
    assert stop_after_s({STOP_AFTER_ENV: text}) == want


@pytest.mark.parametrize("text", ["0", "-3", "abc", "nan", "inf"])
def test_a_bad_early_stop_is_refused_naming_the_variable(text):
    with pytest.raises(SShaDeError, match=STOP_AFTER_ENV):
        stop_after_s({STOP_AFTER_ENV: text})


def test_a_shared_stop_is_fixed_once_and_counts_down_to_one_moment():
    env = {STOP_AFTER_ENV: "100"}
    assert share_stop(env) == 100.0 and abs(float(env[STOP_BY_ENV]) - (time.time() + 100)) < 5
    by = env[STOP_BY_ENV]
    env[STOP_AFTER_ENV] = "5000"  # a later command of the same sweep: the moment stays
    assert share_stop(env) < 101 and env[STOP_BY_ENV] == by
    assert 0 < stop_after_s(env) <= 100  # a job started later gets what is left, not the whole stop
    assert share_stop({}) is None


def test_a_run_started_past_the_shared_moment_starts_no_pair():
    assert stop_after_s({STOP_AFTER_ENV: "100", STOP_BY_ENV: repr(time.time() - 10)}) == pytest.approx(1e-3)


@pytest.mark.parametrize("text", ["0", "-3", "abc", "nan", "inf"])
def test_a_bad_shared_moment_is_refused_naming_the_variable(text):
    with pytest.raises(SShaDeError, match=STOP_BY_ENV):
        stop_after_s({STOP_AFTER_ENV: "100", STOP_BY_ENV: text})


@pytest.mark.slow  # about 35 s: a sweep of two evaluator runs on FAUST, the first taking 25 s
def test_the_jobs_of_a_sweep_share_one_stop(tmp_path, faust_root):
    """``python -m eval.sweeps`` under :data:`STOP_AFTER_ENV` (as ``--budget`` runs a sweep
    step): job 0's one pair starts before the 20 s stop and takes 25 s; job 1 starts past the
    sweep's stop, so it starts no pair (given the whole stop again, it would have run its
    two), and the sweep ends cleanly."""
    import subprocess
    import sys

    from .conftest import ROOT, subprocess_env

    counter, d = tmp_path / "calls.txt", tmp_path / "sweep"
    cmd = [sys.executable, "-m", "eval.sweeps", "-m", "dataset=faust", f"dataset.root={faust_root}",
           "dataset.limit=1,2", "methods=[{_target_:tests.store_methods.Counted,name:A}]", "reference.cases=none",
           "figures.enabled=false", "report.enabled=false", "jobs=1", "resume=true", f"hydra.sweep.dir={d}"]
    env = dict(subprocess_env(), SSHADE_TEST_COUNTER=str(counter), SSHADE_TEST_SLEEP_S="25", **{STOP_AFTER_ENV: "20"})
    env.pop(STOP_BY_ENV, None)
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert counter.read_text().count(" A\n") == 1
    assert "not run and never stored: no row" in (d / "1" / "eval.log").read_text()


@pytest.mark.slow  # about 8 s: an evaluator run on FAUST stopped after its first pairs
def test_a_pair_left_at_the_stop_and_never_stored_has_no_row_and_the_run_ends_cleanly(tmp_path, faust_root):
    """The evaluator's early stop past its first pair: a stored current row (A) stands, a
    pair never stored (B) has no row and no mesh in the first case's figure, and the run
    exits 0 (it once failed on the missing mesh of the pair left)."""
    import subprocess
    import sys

    import pandas as pd

    from .conftest import ROOT, subprocess_env

    (tmp_path / "faust").symlink_to(faust_root)
    out, counter = tmp_path / "out", tmp_path / "calls.txt"
    A, B = ("{_target_:tests.store_methods.Counted,name:%s}" % n for n in "AB")

    def run(methods, environ=None):
        cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path / 'faust'}",
               "dataset.limit=1", "reference.cases=none", f"methods=[{methods}]", f"out_dir={out}", "resume=true",
               "jobs=1"]
        env = dict(subprocess_env(), SSHADE_TEST_COUNTER=str(counter), **(environ or {}))
        return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)

    assert run(A).returncode == 0
    calls = counter.read_text()
    r = run(f"{A},{B}", {STOP_AFTER_ENV: "0.001"})
    assert r.returncode == 0, r.stderr[-3000:]
    assert counter.read_text() == calls  # nothing ran after the stop
    assert list(pd.read_csv(out / "cases.csv")["method"]) == ["A"]
    assert "not run and never stored: no row" in (out / "eval.log").read_text()


@pytest.mark.slow  # about 10 s: evaluator runs on FAUST, stopped and resumed
def test_a_row_left_pending_from_other_case_data_is_counted_in_the_title_and_run_json(faust_root, tmp_path):
    """A resumed run stopped at once (:data:`STOP_AFTER_ENV`) whose case now has other
    targets (another dataset seed) leaves its stored row, made on the earlier data,
    pending: the row says it stands on other case data, the table's title counts it, so
    a run does not vouch for data it did not read; a row of the same data says nothing."""
    import json
    import subprocess
    import sys

    from .conftest import ROOT, subprocess_env

    (tmp_path / "faust").symlink_to(faust_root)
    out = tmp_path / "out"
    A = "{_target_:tests.store_methods.Counted,name:A}"

    def run(seed, environ=None):
        cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path / 'faust'}",
               "dataset.limit=1", f"dataset.seed={seed}", "reference.cases=none", f"methods=[{A}]",
               f"out_dir={out}", "resume=true", "jobs=1"]
        env = dict(subprocess_env(), SSHADE_TEST_COUNTER=str(tmp_path / "calls.txt"), **(environ or {}))
        return subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)

    assert run(0).returncode == 0
    r = run(1, {STOP_AFTER_ENV: "0.001"})
    assert r.returncode == 0, r.stderr[-3000:]
    table = (out / "table.md").read_text()
    assert "1 pending row(s) made on other case data than this run's" in table.splitlines()[0]
    assert "on other case data than this run's" in table.split("#### ")[-1]
    assert json.loads((out / "run.json").read_text()).get("dataset_build") is None  # FAUST: no canonical build
    (case,) = {c for c, _ in pending_on_other_data(out)}
    assert pending_on_other_data(out) == {(case, "A")}
    panels = {m["label"]: m for m in read_view(case_view_path(out, case))["meshes"]}
    assert panels["A"]["kind"] == OTHER_DATA_KIND and not panels["A"]["pos"]  # said, not drawn on this mesh


def test_a_row_left_pending_for_other_settings_stays_marked_until_made_again(tmp_path):
    """A row whose code is current but that its run left pending for other settings (the
    run's stop, :data:`STOP_AFTER_ENV`) stays marked when its tables are rebuilt, and counts
    as pending for ``--check``, the leaderboard and the index, until a run makes it again."""

    from eval.run.stale_rows import CommitTrees, check_folders
    from eval.tables import retabulate

    from .conftest import ROOT
    from .current_rows import current_copy
    run = current_copy(ROOT / "results" / "faust", tmp_path / "faust")  # current, whatever the committed state
    with CommitTrees() as trees:
        assert check_folders([run], trees, marked=marked_pending)[str(run)]["ARAP"]["stale"] == 0
    rec = __import__("json").loads((run / "runs" / "s0_p1" / "ARAP.json").read_text())
    c7 = short_commit(rec["git"]["commit"])
    table = run / "table.md"
    why = "other settings: guard or reference options"
    table.write_text(table.read_text() + f"\n#### Rows pending regeneration (made by older code)\n\n"
                                         f"- `s0_p1` `ARAP`: made at {c7}; {why}\n")
    code_only = table.read_text().replace(why, "sshade.guard changed since " + c7)
    retabulate(run)
    assert marked_pending(run) == {("s0_p1", "ARAP", c7): why}
    assert "(39 of 40 rows made by this commit's code; 1 pending from " in table.read_text().splitlines()[0]
    with CommitTrees() as trees:
        arap = check_folders([run], trees, marked=marked_pending)[str(run)]["ARAP"]
    assert (arap["stale"], arap["marked"], list(arap["why"])) == (1, 1, [why])
    table.write_text(code_only)  # a mark for code that is current again goes
    retabulate(run)
    assert marked_pending(run) == {}


def test_a_folder_run_whole_is_marked_pending_in_its_table_and_unmarked_byte_for_byte(tmp_path):
    from eval.run.pending_rows import RUN_PENDING_HEADING, mark_run_pending, marked_run
    table = tmp_path / "table.md"
    text = "### convergence\n\n| a | b |\n"
    table.write_text(text)
    assert marked_run(tmp_path) is None and not mark_run_pending(tmp_path, "c" * 40, None)
    assert mark_run_pending(tmp_path, "c449109" + "0" * 33, "sshade.mesh.io changed since c449109")
    assert marked_run(tmp_path) == "c449109" and RUN_PENDING_HEADING in table.read_text()
    assert not mark_run_pending(tmp_path, "c449109" + "0" * 33, "sshade.mesh.io changed since c449109")  # idempotent
    assert mark_run_pending(tmp_path, "c449109" + "0" * 33, None) and table.read_text() == text
    os.symlink(table, tmp_path / "other")
    (tmp_path / "linked").mkdir()
    os.symlink(table, tmp_path / "linked" / "table.md")
    assert not mark_run_pending(tmp_path / "linked", "c" * 40, "why") and table.read_text() == text  # no link written

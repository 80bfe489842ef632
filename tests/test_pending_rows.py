"""eval/run/pending_rows.py: how a table marks its rows made by older code and how
``--check`` reads the marks back; the evaluator's early stop read from the environment."""
from __future__ import annotations

import os

import pytest

from eval.run.pending_rows import (
    STOP_AFTER_ENV,
    marked_pending,
    pending_markdown,
    pending_title,
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
    assert marked_pending(tmp_path) == {("s0_p2", "ARAP", "3e79476"), ("s0_p2", "Implicit-ARAP", "unknown")}
    assert pending_markdown(states[:1]) == "" and short_commit(12) == "unknown"


def test_a_linked_or_missing_table_marks_nothing(tmp_path):
    (tmp_path / "elsewhere.md").write_text(pending_markdown(_states(tmp_path)))
    assert marked_pending(tmp_path) == set()
    os.symlink(tmp_path / "elsewhere.md", tmp_path / "table.md")
    assert marked_pending(tmp_path) == set()  # a link is not read: no mark comes from outside the folder


@pytest.mark.parametrize("text, want", [("", None), ("  ", None), ("20", 20.0), ("0.5", 0.5)])
def test_the_early_stop_is_a_number_of_seconds_or_nothing(text, want):
    assert stop_after_s({STOP_AFTER_ENV: text}) == want


@pytest.mark.parametrize("text", ["0", "-3", "abc", "nan", "inf"])
def test_a_bad_early_stop_is_refused_naming_the_variable(text):
    with pytest.raises(SShaDeError, match=STOP_AFTER_ENV):
        stop_after_s({STOP_AFTER_ENV: text})

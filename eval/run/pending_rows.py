"""A table's rows made by older code, marked pending: what ``table.md`` says of them and
how ``python -m eval.reproduce --check`` reads it back.

A stored row whose code changed since it was computed (:mod:`eval.run.stale_rows`) stays
in its tables until it is regenerated, marked: the title gives the count (``38 of 40
rows made by this commit's code; 2 pending from 3e79476``) and a list under the table
names each pending row with the commit that made it and the modules changed since
(:func:`pending_markdown`). ``--check`` counts a stale row as marked when its folder's
``table.md`` lists it with that commit (:func:`marked_pending`). :data:`STOP_AFTER_ENV` stops
an evaluator run early, its pairs left marked so (``python -m eval.reproduce --budget``);
a sweep's jobs share one stop (:func:`share_stop`).
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.
"""
from __future__ import annotations

import os
import re
import time
from pathlib import Path

from harness.checks import env_positive
from sshade.files import atomic_write
from sshade.json_file import read_bounded

__all__ = ["STOP_AFTER_ENV", "STOP_BY_ENV", "PENDING_HEADING", "RUN_PENDING_HEADING", "stop_after_s", "share_stop",
           "short_commit", "pending_title", "strip_pending", "pending_markdown", "marked_pending", "mark_run_pending",
           "marked_run", "OTHER_CASE_DATA", "pending_on_other_data"]

#: The environment variable that stops an evaluator run early (``python -m eval.reproduce
#: --budget`` sets it for each table step): seconds after the run's start when no (case,
#: method) run starts any more; each pair left keeps its stored row, marked pending. An
#: operating limit of the command, not a setting of any row: no part of the config or a key.
STOP_AFTER_ENV = "SSHADE_STOP_AFTER_S"
#: Set by :func:`share_stop` in a command that runs several evaluator runs one after the
#: other (a sweep): the moment, in seconds since the epoch, after which none of them starts
#: a pair, so that :data:`STOP_AFTER_ENV` bounds the whole command, not each run.
STOP_BY_ENV = "SSHADE_STOP_BY"
#: The stop of a run that starts past the shared moment: no pair starts.
_PAST = 1e-3

#: The heading of the list of a table's pending rows in ``table.md``.
PENDING_HEADING = "Rows pending regeneration (made by older code)"
#: A listed pending row: ``- `case` `method`: made at abc1234; why``.
_ROW = re.compile(r"^- `(?P<case>[^`]+)` `(?P<method>[^`]+)`: made at (?P<commit>[0-9a-f]{7}|unknown)\b"
                  r"(?:; (?P<why>.*))?$")
#: The heading a folder run whole gets at the end of its ``table.md`` while it is pending,
#: over one line ``made at abc1234; why`` (:func:`mark_run_pending`).
RUN_PENDING_HEADING = "This run is pending regeneration (made by older code)"
#: The words a pending row's reason carries when its stored record ran on other case data
#: than the run that left it (another build of the dataset: its vertices do not fit this
#: one's meshes), as the tables and a run's title write them.
OTHER_CASE_DATA = "on other case data"
#: The count a title ends with when some rows are pending.
_TITLE = re.compile(r" \(\d+ of \d+ rows made by this commit's code; \d+ pending from [^()]*\)$")
#: The most of a ``table.md`` read back (bytes): a table is a few kB.
MAX_TABLE_BYTES = 8 * 2**20


def short_commit(commit) -> str:
    """How a table names the commit that made a row: its first 7 hex digits, ``"unknown"``
    when the record names none (or not as a text)."""
    return commit[:7] if isinstance(commit, str) and commit else "unknown"


def pending_title(title: str | None, states) -> str | None:
    """``title`` with the count of pending rows among ``states`` (the
    :class:`eval.run.stale_rows.RowState` of every stored row of the table) appended, or
    as it is when none is pending (any count appended before is taken off first)."""
    states = list(states)
    stale = [s for s in states if s.stale]
    if title is None or not stale:
        return strip_pending(title)
    commits = ", ".join(sorted({short_commit(s.commit) for s in stale}))
    n = len(states)
    return (f"{strip_pending(title)} ({n - len(stale)} of {n} rows made by this commit's code; "
            f"{len(stale)} pending from {commits})")


def strip_pending(title: str | None) -> str | None:
    """``title`` without the count :func:`pending_title` appended."""
    return None if title is None else _TITLE.sub("", title)


def pending_markdown(states) -> str:
    """The list of the pending rows among ``states`` (``""`` when none is), for ``table.md``:
    each row's case, method, the commit that made it and why it is stale."""
    stale = [s for s in states if s.stale]
    if not stale:
        return ""
    rows = "\n".join(f"- `{s.case}` `{s.method}`: made at {short_commit(s.commit)}; {' '.join(str(s.why).split())}"
                     for s in stale)
    return (f"#### {PENDING_HEADING}\n\nTheir numbers are in the table as that code made them; "
            f"`python -m eval.reproduce` regenerates them (`--check` lists them).\n\n{rows}\n")


def _table_text(folder, errors: str = "replace") -> str | None:
    """The text of ``folder``'s ``table.md`` read as untrusted input, None when it is
    missing, a link, no regular file, above :data:`MAX_TABLE_BYTES` or (``errors="strict"``)
    no UTF-8."""
    path = Path(folder) / "table.md"
    try:
        return None if path.is_symlink() else read_bounded(path, MAX_TABLE_BYTES).decode("utf-8", errors)
    except (OSError, UnicodeDecodeError):
        return None


def marked_pending(folder) -> dict[tuple[str, str, str], str]:
    """``{(case, method, commit[:7]): why}`` of the rows ``folder``'s ``table.md`` lists as
    pending (:func:`pending_markdown`); empty when it has none, or no readable ``table.md``
    (a link, a FIFO or a file above :data:`MAX_TABLE_BYTES` is not read)."""
    _, found, rest = (_table_text(folder) or "").partition(f"#### {PENDING_HEADING}\n")
    if not found:
        return {}
    return {(m["case"], m["method"], m["commit"]): m["why"] or "" for m in map(_ROW.match, rest.splitlines()) if m}


def pending_on_other_data(folder) -> set[tuple[str, str]]:
    """``{(case, method)}`` of the rows ``folder``'s ``table.md`` lists as pending and made
    on other case data than the run's (:data:`OTHER_CASE_DATA`; :func:`marked_pending`)."""
    return {(case, method) for (case, method, _), why in marked_pending(folder).items() if OTHER_CASE_DATA in why}


def _unmarked(text: str) -> str:
    """``text`` of a ``table.md`` without the section :func:`mark_run_pending` adds."""
    return text.partition(f"\n#### {RUN_PENDING_HEADING}\n")[0].rstrip("\n") + "\n"


def mark_run_pending(folder, commit, why: str | None) -> bool:
    """Mark the folder run whole ``folder`` pending in its ``table.md`` (a section at its
    end: the commit that made it and ``why`` it is stale), or, with ``why`` None, remove
    that mark; the rest of the file kept byte for byte. Returns whether the file changed;
    a ``table.md`` that is missing, a link or no regular file is left alone (False)."""
    text = _table_text(folder, "strict")  # rewritten whole: never from replaced characters
    if text is None:
        return False
    new = _unmarked(text)
    if why is not None:
        new += f"\n#### {RUN_PENDING_HEADING}\n\nmade at {short_commit(commit)}; {' '.join(str(why).split())}\n"
    if new == text:
        return False
    with atomic_write(Path(folder) / "table.md", "w") as fh:
        fh.write(new)
    return True


def marked_run(folder) -> str | None:
    """The commit (7 hex digits, or ``"unknown"``) with which :func:`mark_run_pending`
    marked the folder run whole ``folder`` pending, None when it is not marked (or its
    ``table.md`` cannot be read as a regular file)."""
    _, found, rest = (_table_text(folder) or "").partition(f"\n#### {RUN_PENDING_HEADING}\n")
    m = re.search(r"^made at ([0-9a-f]{7}|unknown)\b", rest, re.M) if found else None
    return m[1] if m else None


def stop_after_s(environ=None) -> float | None:
    """The seconds from now after which an evaluator run starts no pair: what
    :data:`STOP_AFTER_ENV` gives in ``environ`` (default ``os.environ``), or, where
    :func:`share_stop` set :data:`STOP_BY_ENV`, the seconds left until that moment (at
    least 1 ms: a run started past it starts no pair); None when neither is set.
    Raises SShaDeError naming the variable when it holds no number > 0."""
    after = env_positive(STOP_AFTER_ENV, "a number of seconds > 0", environ)
    by = env_positive(STOP_BY_ENV, "a number of seconds since the epoch > 0", environ)
    return after if by is None else max(by - time.time(), _PAST)


def share_stop(environ=None) -> float | None:
    """In a command that runs several evaluator runs one after the other (a sweep, whose
    jobs may run in other processes): fix the moment :data:`STOP_AFTER_ENV` points to, once,
    in ``environ`` (default ``os.environ``) as :data:`STOP_BY_ENV`, so that every run it
    starts later stops at that one moment. Returns the seconds left (None without a stop);
    a moment already set (an outer command's) is kept. Raises SShaDeError as
    :func:`stop_after_s`."""
    environ = os.environ if environ is None else environ
    left = stop_after_s(environ)
    if left is not None and not environ.get(STOP_BY_ENV, "").strip():
        environ[STOP_BY_ENV] = repr(time.time() + left)
    return left

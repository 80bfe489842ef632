"""docs/experiments.md's table of commands and their times: every time with a number names
the measured run it comes from, and says what that run took. A run is a results folder's
``run.json`` (its ``wall_s``: the evaluator's wall seconds of that run) or a row of
benchmarks/records/command_times.md (the same command timed as a whole, with its date and
commit). A figure ``N s``, ``N min`` or ``N h`` matches a run of S seconds when N is S in
that unit to the figure's precision (rounded)."""
from __future__ import annotations

import json
import re

import pytest

from tests.conftest import ROOT

DOC = ROOT / "docs" / "experiments.md"
RECORD = ROOT / "benchmarks" / "records" / "command_times.md"
FIGURE = re.compile(r"(\d+(?:\.\d+)?)\s?(s|min|h)\b")
RUN_JSON = re.compile(r"`?(results/[\w./-]+/run\.json)`?")
UNIT_S = {"s": 1.0, "min": 60.0, "h": 3600.0}


def _cells(line: str) -> list[str]:
    """A Markdown table row's cells; an escaped ``\\|`` (GitHub's way within a cell, code
    spans included) or a ``|`` inside backticks is part of a cell, read as ``|``."""
    cells, cur, code = [], "", False
    text = line.strip().strip("|").replace("\\|", "\0")
    for ch in text:
        if ch == "`":
            code = not code
        if ch == "|" and not code:
            cells.append(cur.strip())
            cur = ""
        else:
            cur += ch
    return [c.replace("\0", "|") for c in cells + [cur.strip()]]


def _table(lines: list[str], header: str) -> list[list[str]]:
    """The rows of the first table whose header row starts with ``header``."""
    start = next(i for i, ln in enumerate(lines) if ln.startswith(header))
    rows = []
    for ln in lines[start + 2:]:
        if not ln.startswith("|"):
            break
        rows.append(_cells(ln))
    return rows


def _matches(figure: re.Match, seconds: float) -> bool:
    value, unit = figure.group(1), figure.group(2)
    decimals = len(value.partition(".")[2])
    return round(seconds / UNIT_S[unit], decimals) == float(value)


def _recorded() -> dict[str, float]:
    """benchmarks/records/command_times.md's runs: command -> wall seconds."""
    rows = _table(RECORD.read_text().splitlines(), "| Command |")
    return {r[0]: float(r[-1]) for r in rows}


def _checks() -> list[tuple[str, str]]:
    """(command, time cell) of every docs row whose time has a number."""
    rows = _table(DOC.read_text().splitlines(), "| command | what | time |")
    return [(r[0], r[-1]) for r in rows if FIGURE.search(r[-1])]


@pytest.mark.parametrize("command,cell", _checks(), ids=lambda x: x[:40])
def test_a_documented_time_is_that_of_the_run_it_names(command, cell):
    figure = FIGURE.search(cell)
    m = RUN_JSON.search(cell)
    if m:
        seconds = json.loads((ROOT / m.group(1)).read_text())["wall_s"]
    else:
        assert "command_times.md" in cell, f"{command}: the time {cell[:60]!r} names no run it comes from"
        recorded = _recorded()
        assert command in recorded, f"{command}: not in {RECORD.name}"
        seconds = recorded[command]
    assert _matches(figure, seconds), f"{command}: the docs say {figure.group(0)}, the run took {seconds:.1f} s"


def test_an_edited_time_fails():
    assert _matches(FIGURE.search("10 min"), 618.0) and not _matches(FIGURE.search("11 min"), 618.0)
    assert _matches(FIGURE.search("2.4 min"), 144.0) and not _matches(FIGURE.search("2.5 min"), 144.0)


def test_the_readmes_main_job_is_the_documented_and_measured_one_within_10_minutes():
    """The evaluator command ending the README's set-up line is the docs' main-job row and a
    record of command_times.md, whose measured wall time (the whole set-up line from a fresh
    clone on 2 cores) is at most 10 minutes."""
    line = next(ln for ln in (ROOT / "README.md").read_text().splitlines() if ln.startswith("pip install -e . &&"))
    main_job = line.split("&&")[-1].strip()
    assert main_job.startswith("python -m eval")
    rows = {c: cell for c, cell in _checks()}
    assert f"`{main_job}`" in rows, f"docs/experiments.md has no row for the README's {main_job!r}"
    assert "the main job" in next(ln for ln in DOC.read_text().splitlines() if ln.startswith(f"| `{main_job}` |"))
    assert _recorded()[f"`{main_job}`"] <= 600.0

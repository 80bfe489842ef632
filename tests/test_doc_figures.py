"""Every percentage that docs/reproduction.md, docs/methods.md, docs/deform.md,
docs/implementation.md and docs/protocols.md attach to a committed results folder (or a
benchmark's record under benchmarks/records/) is in that folder's tables, in the row and
column it names.

A paragraph attaches its percentages to the folders it names (``results/...``), or, naming
none and not opening with the script it quotes, to the folders named earlier in its
section (a ``#`` heading starts a section). A percentage must round-match a cell of
those folders' tables (their ``*.md``, ``table*.csv``, ``sweep_table*.csv``, the per-case
``cases*.csv``; a named file:
that file); where its sentence names a method before it (ARAP, Elastic, ARAP-SR,
Implicit-ARAP, SShaDe), a cell of that method's rows; where it names a measure (volume,
area, EL, GT mean, handle) just before the number, a cell of that measure's column. A doc
table's row is checked cell by cell the same way, in its method's rows where it starts
with one (columns without ``%`` and those headed ``Paper`` aside). The paper's own
figures (``paper`` within the 40 characters before the number) are exempt, and so is a
sentence that gives its own source. An edited number fails (tested)."""
from __future__ import annotations

import csv
import functools
import io
import re
from pathlib import Path

import pytest

from tests.conftest import ROOT

DOCS = ("reproduction.md", "methods.md", "deform.md", "implementation.md", "protocols.md")
PERCENT = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?%")
RESULTS = re.compile(r"((?:results|benchmarks/records)/[\w./-]*[\w/])")
SENTENCE = re.compile(r"(?<=[.!?])\s+(?=[A-Z`(*])|\n(?=\|)")  #: a sentence, or a table row
SCRIPT = re.compile(r"\btests/\w+\.py|\bbenchmarks/\w+\.py")
OWN_SOURCE = re.compile(SCRIPT.pattern + "|not kept in a results file")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE]-?\d+)?")
METHOD = re.compile(r"(?<![\w-])(Implicit-ARAP|ARAP-SR|ARAP|Elastic|SShaDe)(?![\w-])")
#: a measure as the docs name it -> the column names that hold it in the results' tables
MEASURES = {"volume": ("Volume (%)", "volume_err_pct"), "area": ("Area (%)", "area_err_pct"),
            "EL": ("EL (%)", "edge_err_pct"), "GT mean": ("GT mean (%)", "gt_vertex_mean_pct"),
            "handle": ("Handle (%)", "handle_err_pct")}
MEASURE = re.compile(r"\b(?:(?i:volume|area|handle)|EL|GT mean)\b")
NEAR = 25  #: a measure names the number's column when named at most this many characters before it


@functools.lru_cache(maxsize=None)
def _files(target: Path) -> tuple[Path, ...]:
    if target.is_file():
        return (target,)
    tables = ("table", "sweep_table", "cases")
    return tuple(sorted(p for p in target.rglob("*") if p.is_file() and "runs" not in p.relative_to(target).parts
                        and (p.suffix == ".md" or p.name.startswith(tables) and p.suffix == ".csv")))


@functools.lru_cache(maxsize=None)
def _rows(p: Path) -> tuple:
    """``(header, row)`` pairs of the tables in ``p`` (markdown pipe tables or a CSV file);
    a line of a markdown file outside any table is one row of one cell, with no header."""
    text = p.read_text(errors="replace")
    if p.suffix == ".csv":
        rows = list(csv.reader(io.StringIO(text)))
        return tuple((rows[0], r) for r in rows[1:]) if rows else ()
    out, header = [], None
    for line in text.splitlines():
        if not line.startswith("|"):
            header = None
            out.append(([""], [line]))
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = cells
        elif not all(set(c) <= set("-: ") for c in cells):
            out.append((header, cells))
    return tuple(out)


@functools.lru_cache(maxsize=None)
def _cells(targets: frozenset, method: str | None, measure: str | None) -> tuple[float, ...]:
    """The numbers of the targets' table cells in ``method``'s rows (a row with a cell
    equal to it, or a column headed with it) and ``measure``'s column; ``None``: any."""
    cols = MEASURES.get(measure, MEASURES.get(measure.lower(), ())) if measure else ()
    out = []
    for t in targets:
        for p in _files(t):
            for header, row in _rows(p):
                in_row = method is None or method in row
                for h, cell in zip(header, row):
                    if method is not None and not (in_row or method in METHOD.findall(h)):
                        continue
                    if measure is not None and not any(h == c or h.endswith(" " + c) for c in cols):
                        continue
                    out += [float(m.group(0)) for m in NUMBER.finditer(cell)]
    return tuple(out)


def _backed(s: str, targets, method, measure) -> bool:
    """``s`` (a number as written) rounds from a cell of the targets, in the named row and
    column where the tables have them (each restriction dropped where it leaves no cell)."""
    dec = len(s.split(".")[1]) if "." in s else 0
    for key in ((method, measure), (method, None), (None, measure), (None, None)):
        values = _cells(frozenset(targets), *key)
        if values:
            return any(abs(v - float(s)) <= 0.5 * 10 ** -dec + 1e-12 for v in values)
    return False


def _last(pattern: re.Pattern, text: str) -> str | None:
    found = pattern.findall(text)
    return found[-1] if found else None


def _table_row(sentence: str, header: list[str] | None, targets) -> list[str]:
    """The unbacked cells of one doc table row (held to the row's method where it starts
    with one)."""
    cells = [c.strip() for c in sentence.strip().strip("|").split("|")]
    if header is None or not cells:
        return []
    method = cells[0] if METHOD.fullmatch(cells[0]) else None
    bad = []
    for h, cell in zip(header[1:], cells[1:]):
        if "%" in h and not h.lower().startswith("paper") and NUMBER.fullmatch(cell):
            if not _backed(cell, targets, method, _last(MEASURE, h)):
                bad.append(f"{cell}% in: {sentence.strip()[:90]!r}")
    return bad


def _sentences(sentence: str, targets) -> list[str]:
    bad = []
    for m in PERCENT.finditer(sentence):
        before = sentence[:m.start()]
        if "paper" in before[-40:]:
            continue
        if not _backed(m.group(1), targets, _last(METHOD, before), _last(MEASURE, before[-NEAR:])):
            bad.append(f"{m.group(1)}% in: {sentence[:90]!r}")
    return bad


def unbacked(text: str) -> list[str]:
    """The percentages of ``text`` (a document) attached to a results folder and not in
    the named row and column of its tables."""
    bad, section = [], set()
    for para in re.split(r"\n\s*\n", text):
        if para.lstrip().startswith("#"):
            section = set()
        named = {ROOT / m.group(1).rstrip("/.") for m in RESULTS.finditer(para)}
        section |= {t for t in named if t.exists()}
        own = SCRIPT.search(SENTENCE.split(para)[0]) is not None  # opens naming the script it quotes
        targets = {t for t in named if t.exists()} or (set() if own else set(section))
        if not targets:
            continue
        header = None
        for sentence in SENTENCE.split(para):
            if OWN_SOURCE.search(sentence):
                continue
            if sentence.lstrip().startswith("|"):
                cells = [c.strip() for c in sentence.strip().strip("|").split("|")]
                if header is None or set("".join(cells)) <= set("-: "):
                    header = header or cells
                    continue
                bad += _table_row(sentence, header, targets)
            else:
                header = None
            bad += _sentences(sentence, targets)
    return bad


@pytest.mark.parametrize("doc", DOCS)
def test_every_percentage_attached_to_a_results_folder_is_in_its_row_and_column(doc):
    if not (ROOT / "results").is_dir():
        pytest.skip("no committed results/")
    assert unbacked((ROOT / "docs" / doc).read_text()) == []


@pytest.mark.parametrize("quote, edited, doc", [
    # benchmarks/records/arap_sr_faust_s0_p1.md: Ref mean 1.208
    ("1.2% of the diagonal from the minimiser", "9.7% of the diagonal from the minimiser", "reproduction.md"),
    # a paragraph that names no folder, under the section naming results/defaust_faust: 1.47
    # is a number of that folder's tables, but not SShaDe's GT mean
    ("(GT mean 1.46 % converged", "(GT mean 1.47 % converged", "reproduction.md"),
    # a doc table's cell: Elastic's volume in results/defaust_faust/table.md
    ("| Elastic | 12.25 | 5.34 |", "| Elastic | 12.25 | 5.65 |", "reproduction.md"),
    # a per-case figure, in the handle column of the named sweep's cases.csv (2.006)
    ("s03_p04 at a handle error of 2.01 %", "s03_p04 at a handle error of 2.02 %", "methods.md"),
])
def test_an_edited_number_is_caught(quote, edited, doc):
    text = (ROOT / "docs" / doc).read_text()
    assert quote in text, f"{doc} no longer quotes {quote!r}"
    assert unbacked(text) == [] and unbacked(text.replace(quote, edited))

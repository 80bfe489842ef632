"""Every percentage that docs/reproduction.md, docs/methods.md and docs/protocols.md attach
to a committed results folder (or a benchmark's record under benchmarks/records/) is in
that folder's tables: a sentence (or table row) that
names ``results/...`` may quote a percentage only when one of the named folder's tables (its
``*.md``, ``table*.csv``, ``sweep_table*.csv``; a named file: that file) holds a number
that rounds to it. The paper's own figures (``paper`` within the 40 characters before
the number) are exempt. An edited number fails (tested)."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.conftest import ROOT

DOCS = ("reproduction.md", "methods.md", "protocols.md")
PERCENT = re.compile(r"(?<![\w.])(\d+(?:\.\d+)?)\s?%")
RESULTS = re.compile(r"((?:results|benchmarks/records)/[\w./-]*[\w/])")
SENTENCE = re.compile(r"(?<=[.!?])\s+(?=[A-Z`(*])|\n(?=\|)")  #: a sentence, or a table row
OWN_SOURCE = re.compile(r"\btests/\w+\.py|\bbenchmarks/\w+\.py|not kept in a results file")
NUMBER = re.compile(r"-?\d+(?:\.\d+)?(?:[eE]-?\d+)?")


def _tables(target: Path) -> list[Path]:
    if target.is_file():
        return [target]
    return sorted(p for p in target.rglob("*") if p.is_file() and "runs" not in p.relative_to(target).parts
                  and (p.suffix == ".md" or p.name.startswith(("table", "sweep_table")) and p.suffix == ".csv"))


def _numbers(targets) -> list[float]:
    out = []
    for t in targets:
        for p in _tables(t):
            out += [float(m.group(0)) for m in NUMBER.finditer(p.read_text(errors="replace"))]
    return out


def unbacked(text: str) -> list[str]:
    """The percentages of ``text`` (a document) attached to a results folder and not in
    its tables: a paragraph naming ``results/...`` attaches its percentages to the named
    folders, except in a sentence that gives its own source (a test or benchmark file, a
    measurement "not kept in a results file") and the paper's figures."""
    bad = []
    for para in re.split(r"\n\s*\n", text):
        targets = {ROOT / m.group(1).rstrip("/.") for m in RESULTS.finditer(para)}
        targets = {t for t in targets if t.exists()}
        if not targets:
            continue
        values = _numbers(targets)
        for sentence in SENTENCE.split(para):
            if OWN_SOURCE.search(sentence):
                continue
            for m in PERCENT.finditer(sentence):
                if "paper" in sentence[max(0, m.start() - 40):m.start()]:
                    continue
                s = m.group(1)
                dec = len(s.split(".")[1]) if "." in s else 0
                if not any(abs(v - float(s)) <= 0.5 * 10 ** -dec + 1e-12 for v in values):
                    bad.append(f"{s}% in: {sentence[:90]!r}")
    return bad


@pytest.mark.parametrize("doc", DOCS)
def test_every_percentage_attached_to_a_results_folder_is_in_it(doc):
    if not (ROOT / "results").is_dir():
        pytest.skip("no committed results/")
    assert unbacked((ROOT / "docs" / doc).read_text()) == []


def test_an_edited_number_is_caught():
    text = (ROOT / "docs" / "reproduction.md").read_text()
    quote = "1.2% of the diagonal from the minimiser"  # benchmarks/records/arap_sr_faust_s0_p1.md: Ref mean 1.208
    assert quote in text, "reproduction.md no longer quotes the move rule's distance beside its results file"
    assert unbacked(text) == [] and unbacked(text.replace(quote, "9.7% of the diagonal from the minimiser"))

"""The module docstrings of ``baselines/``, ``defaust/`` and ``harness/`` are references, not
lab notes: each module has one, of at most 12 lines (what the module holds, where it sits,
its source); rationale and measurements live in docs/ ("Implementation notes: ...")."""
from __future__ import annotations

import ast

from .conftest import ROOT

PACKAGES = ("baselines", "defaust", "harness")
MAX_LINES = 12


def test_module_docstrings_of_baselines_defaust_harness_are_at_most_12_lines():
    files = sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))
    assert files, "no module found under " + ", ".join(PACKAGES)
    offenders = []
    for p in files:
        doc = ast.get_docstring(ast.parse(p.read_text(encoding="utf-8"), filename=str(p)))
        where = p.relative_to(ROOT)
        if not doc:
            offenders.append(f"{where}: no module docstring")
        elif len(doc.splitlines()) > MAX_LINES:
            offenders.append(f"{where}: {len(doc.splitlines())} lines")
    assert not offenders, f"module docstrings over {MAX_LINES} lines or missing:\n" + "\n".join(offenders)

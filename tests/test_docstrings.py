"""Module docstrings are references, not lab notes: every module of the packages in
:data:`PACKAGES` has one, of at most :data:`MAX_LINES` lines (what the module holds, where
it sits, the paper section it implements); rationale and measurements live in
docs/implementation.md ("Implementation notes: ...", eval/ included).
Read with ``ast``, nothing imported."""
from __future__ import annotations

import ast
from pathlib import Path

from .conftest import ROOT

#: The packages whose modules are checked (a package added here is checked the same way).
PACKAGES = ("sshade", "eval")
MAX_LINES = 12


def module_docstring_problem(path: Path) -> str | None:
    """Why the module docstring of ``path`` breaks the rule (missing, too long), or None."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    doc = ast.get_docstring(tree)
    if not doc:
        return "no module docstring"
    n_lines = len(doc.splitlines())
    return f"{n_lines} lines (at most {MAX_LINES})" if n_lines > MAX_LINES else None


def test_module_docstrings_are_at_most_12_lines():
    paths = sorted(path for package in PACKAGES for path in (ROOT / package).rglob("*.py"))
    assert paths, f"no Python module under {PACKAGES}"
    problems = {path.relative_to(ROOT).as_posix(): module_docstring_problem(path) for path in paths}
    offending = [f"{where}: {why}" for where, why in problems.items() if why]
    assert not offending, "module docstrings to shorten (move the rest to the docs):\n" + "\n".join(offending)

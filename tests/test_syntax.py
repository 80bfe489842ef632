"""eval/run/syntax.py: its walks give what a whole :func:`ast.walk` gives (the statements
in the same order, the same attribute chains), on every fourth module of the project and
on a function holding every kind of block."""
from __future__ import annotations

import ast

import pytest

from eval.run.code_identity import project_modules
from eval.run.syntax import attribute_chains, statements

_BLOCKS = (ast.stmt, ast.excepthandler, ast.match_case)
TRY_MATCH = """
def f(x):
    try:
        import a.b as c
    except (ValueError, c.E) as e:
        import d
    else:
        match x:
            case 1:
                import e.f
            case _:
                y = lambda: g.h.i
    finally:
        class K:
            import j
"""


def _walked_chains(tree: ast.AST) -> set:
    out = set()
    for node in ast.walk(tree):
        chain = []
        while isinstance(node, ast.Attribute):
            chain.append(node.attr)
            node = node.value
        if chain and isinstance(node, ast.Name):
            out.add((node.id, tuple(reversed(chain))))
    return out


@pytest.mark.parametrize("source", ["project modules", "try, match and a class in a function"])
def test_statements_and_chains_are_those_of_a_whole_walk(source):
    files = sorted(project_modules().values())[::4]
    trees = [ast.parse(p.read_bytes()) for p in files] if source == "project modules" else [ast.parse(TRY_MATCH)]
    assert len(trees) > (40 if source == "project modules" else 0)
    for tree in trees:
        walked = [n for n in ast.walk(tree) if n is tree or isinstance(n, _BLOCKS)]
        assert [id(n) for n in statements(tree)] == [id(n) for n in walked]
        assert attribute_chains(tree) == _walked_chains(tree)

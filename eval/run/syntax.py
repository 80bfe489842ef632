"""Walks of a Python syntax tree (:mod:`ast`) for the readers of the project's sources
(:mod:`eval.run.code_identity`, :mod:`eval.run.library_versions`): the statements alone,
in :func:`ast.walk`'s order, and the attribute chains on plain names. Both give what a
whole :func:`ast.walk` would and cost a fraction of it: imports, definitions and
docstrings are statements (never inside an expression), so the expressions are skipped;
the chains are gathered in one pass without ``ast.walk``'s nested generators.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py)."""
from __future__ import annotations

import ast
from collections import deque

__all__ = ["statements", "attribute_chains"]

#: The nodes that hold statements: a statement, an ``except`` clause, a ``case`` of a match.
_BLOCKS = (ast.stmt, ast.excepthandler, ast.match_case)


def statements(tree: ast.AST) -> list[ast.AST]:
    """``tree`` and every statement, ``except`` clause and ``case`` under it, in the order
    :func:`ast.walk` visits them (breadth first, each node's fields in order): a
    statement's parents are all statements, so their relative order is that of the whole walk.

    >>> tree = ast.parse("import a\\ndef f():\\n    import b.c as d\\n    return d.e.f(a.x)")
    >>> [type(n).__name__ for n in statements(tree)]
    ['Module', 'Import', 'FunctionDef', 'Import', 'Return']
    """
    out, todo = [], deque([tree])
    while todo:
        node = todo.popleft()
        out.append(node)
        for field in node._fields:
            value = getattr(node, field, None)
            if isinstance(value, list):
                todo.extend(v for v in value if isinstance(v, _BLOCKS))
    return out


def attribute_chains(tree: ast.AST) -> set[tuple[str, tuple[str, ...]]]:
    """``(name, attributes)`` of every attribute chain on a plain name anywhere in ``tree``,
    each prefix its own chain: ``a.b.c`` gives ``("a", ("b", "c"))`` and ``("a", ("b",))``.

    >>> sorted(attribute_chains(ast.parse("d.e.f(a.x)")))
    [('a', ('x',)), ('d', ('e',)), ('d', ('e', 'f'))]
    """
    out, todo = set(), [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.Attribute):
            chain, base = [], node
            while isinstance(base, ast.Attribute):
                chain.append(base.attr)
                base = base.value
            if isinstance(base, ast.Name):
                out.add((base.id, tuple(reversed(chain))))
        for field in node._fields:
            value = getattr(node, field, None)
            if isinstance(value, ast.AST):
                todo.append(value)
            elif isinstance(value, list):
                todo.extend(v for v in value if isinstance(v, ast.AST))
    return out

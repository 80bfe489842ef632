"""The modules a method's protocol runs in, as its class's module names them: a
module-level literal :data:`PROTOCOL_TABLE` (``{protocol: dotted module}``) that the
module imports by name (``importlib``) when the method is built under a protocol, so
that its own import closure holds no protocol's code. A row's code identity
(:mod:`eval.run.code_identity`) adds the entry of its ``protocol`` (:func:`protocol_roots`);
the same literal decides what runs and what the identity holds. Used by ARAP and Elastic
(``baselines.fullres_arap.PROTOCOL_MODULES``). Floor 0 of eval/; notes: docs/implementation.md.
"""
from __future__ import annotations

import ast
from collections.abc import Mapping
from pathlib import Path

__all__ = ["PROTOCOL_TABLE", "protocol_roots"]

#: the name of the module-level literal ``{protocol: dotted module}`` in a method's module
PROTOCOL_TABLE = "PROTOCOL_MODULES"


def protocol_roots(spec: Mapping, mods: Mapping[str, Path]) -> tuple[str, ...]:
    """The modules a method's protocol runs in (sorted dotted names): for a definition
    ``spec`` (a record's ``key_fields.method``) whose ``class`` is defined in a module of
    ``mods`` (``{dotted name: file}``, :func:`eval.run.code_identity.project_modules`)
    binding :data:`PROTOCOL_TABLE` once, at module level, to a dict literal: the entry for
    ``spec["protocol"]``, or every entry when the spec names none of the table's
    protocols (whichever ran is held); ``()`` otherwise.

    >>> from eval.run.code_identity import project_modules
    >>> protocol_roots({"class": "baselines.fullres_arap.ARAP", "protocol": "paper"}, project_modules())
    ('baselines.fullres_paper',)
    """
    cls, protocol = spec.get("class"), spec.get("protocol")
    parts = cls.split(".") if isinstance(cls, str) else []
    module = next((m for m in (".".join(parts[:i]) for i in range(len(parts) - 1, 0, -1)) if m in mods), None)
    if module is None:
        return ()
    try:
        body = ast.parse(Path(mods[module]).read_bytes()).body
    except (OSError, SyntaxError, ValueError, RecursionError, MemoryError):
        return ()
    values = [n.value for n in body if isinstance(n, ast.Assign) and len(n.targets) == 1
              and isinstance(n.targets[0], ast.Name) and n.targets[0].id == PROTOCOL_TABLE]
    try:
        table = ast.literal_eval(values[0]) if len(values) == 1 else None
    except (ValueError, TypeError, SyntaxError, RecursionError, MemoryError):
        return ()
    if not isinstance(table, dict):
        return ()
    chosen = [table[protocol]] if isinstance(protocol, str) and protocol in table else list(table.values())
    return tuple(sorted(m for m in chosen if isinstance(m, str)))

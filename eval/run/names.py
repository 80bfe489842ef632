"""File names for the evaluator's case and method names.

:func:`safe_name` turns a case or method name into a file name that stays inside its
folder: the result store's ``runs/<case>/<method>.json`` (:mod:`eval.run.result_store`), the
figures, the report's views and scope, the datasets' names compared as file names.
On the evaluator's ground floor (:mod:`eval.run`), so that every floor above may use it.
"""
from __future__ import annotations

import re

__all__ = ["safe_name"]


def safe_name(name) -> str:
    """A file name for a case or method name: characters outside ``[A-Za-z0-9._+-]``
    become ``_``; a leading dot too (never a hidden file), at most 120 characters.

    >>> safe_name("SShaDe+refine"), safe_name("a/b c"), safe_name(".x")
    ('SShaDe+refine', 'a_b_c', '_x')
    """
    s = re.sub(r"[^A-Za-z0-9._+-]", "_", str(name))[:120]
    return "_" + s[1:] if s.startswith(".") else (s or "_")

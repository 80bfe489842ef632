"""griffe extensions of the documentation site (mkdocs.yml, mkdocstrings' python handler).

* :class:`SiteDocstrings`: a docstring finished at import time (``{sshade_params}``,
  :func:`sshade.params.document_params`) is read from the imported function, and a
  literal ``Example::`` block (the packages' form of an example that does not run as a
  doctest) becomes an ``Examples`` section with a fenced Python block.
"""
from __future__ import annotations

import importlib
import inspect
import re

import griffe

_LITERAL = re.compile(r"^(?P<indent>[ \t]*)Examples?::[ \t]*\n(?P<body>(?:(?:(?P=indent)[ \t]+.*)?\n)+)", re.M)


def fenced_examples(text: str) -> str:
    """``text`` with each ``Example::`` literal block made a numpy ``Examples`` section
    holding a fenced Python block (the block's common indentation removed)."""
    def fence(m: re.Match) -> str:
        body = inspect.cleandoc(m.group("body"))
        return f"Examples\n--------\n```python\n{body}\n```\n"
    return _LITERAL.sub(fence, text if text.endswith("\n") else text + "\n").rstrip("\n")


class SiteDocstrings(griffe.Extension):
    """Docstrings as the site shows them (module docstring)."""

    def _fix(self, obj) -> None:
        if obj.docstring is None:
            return
        text = obj.docstring.value
        if "{sshade_params}" in text:
            live = getattr(importlib.import_module(obj.module.path), obj.name, None)
            text = inspect.cleandoc(getattr(live, "__doc__", None) or text)
        obj.docstring.value = fenced_examples(text)

    def on_function_instance(self, *, func, **kwargs) -> None:
        self._fix(func)

    def on_class_instance(self, *, cls, **kwargs) -> None:
        self._fix(cls)

    def on_module_instance(self, *, mod, **kwargs) -> None:
        self._fix(mod)

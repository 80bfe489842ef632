"""The numerical libraries beneath the project's code and their installed versions: part
of a row's identity only for the libraries its code imports and those they compute with
(:func:`used_libraries`), so an upgrade of PyTorch stales Implicit-ARAP's rows and not
ARAP's. Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes:
docs/implementation.md ("eval/run/code_identity.py")."""
from __future__ import annotations

import ast
import functools
from importlib import metadata
from pathlib import Path

from eval.run.syntax import statements

__all__ = ["NUMERICAL", "IMPORT_NAMES", "BUILDS_ON", "numerical_versions", "used_libraries"]

#: Distributions whose version can change a row's numbers: the solvers and mesh
#: processing beneath the methods, and PyTorch (Implicit-ARAP, plug-ins).
NUMERICAL = ("numpy", "scipy", "libigl", "pymeshlab", "numba", "cholespy", "trimesh", "torch")

#: The module a distribution of :data:`NUMERICAL` is imported as, where the names differ.
IMPORT_NAMES = {"libigl": "igl"}

#: The distributions of :data:`NUMERICAL` each one computes with: its results can change
#: with theirs.
BUILDS_ON = {"scipy": ("numpy",), "libigl": ("numpy", "scipy"), "trimesh": ("numpy", "scipy"),
             "pymeshlab": ("numpy",), "numba": ("numpy",), "cholespy": ("numpy",), "torch": ("numpy",)}


@functools.lru_cache(maxsize=1)
def numerical_versions() -> dict:
    """``{distribution: version or None}`` for :data:`NUMERICAL` (installed metadata)."""
    out = {}
    for dist in NUMERICAL:
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    return out


def _top_names(tree: ast.AST) -> frozenset:
    """The top-level names of the absolute imports anywhere in ``tree``."""
    out = set()
    for node in statements(tree):  # an import is a statement
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            out.add(node.module.split(".")[0])
    return frozenset(out)


def _names_of(tree) -> frozenset:
    """:func:`_top_names` of ``tree()``; every library of :data:`NUMERICAL` when it raises
    SyntaxError or ValueError (a file that does not parse: every library counts)."""
    try:
        return _top_names(tree())
    except (SyntaxError, ValueError):
        return frozenset(NUMERICAL)


@functools.lru_cache(maxsize=2048)
def _imported(path: str, mtime_ns: int, size: int) -> frozenset:
    """:func:`_names_of` the file ``path``, parsed here."""
    return _names_of(lambda: ast.parse(Path(path).read_bytes(), path))


def used_libraries(files, parse=None) -> tuple[str, ...]:
    """The distributions of :data:`NUMERICAL` (in that order) that the Python ``files``
    import (module level or in a function; by :data:`IMPORT_NAMES`), with those they
    compute with (:data:`BUILDS_ON`). ``parse``: a function from a file's
    :class:`~pathlib.Path` to its syntax tree (a caller's cache of them; raising
    SyntaxError or ValueError for a file that does not parse), or None to parse here.
    Raises OSError when a file cannot be read."""
    names = set()
    for f in files:
        if parse is not None:
            names |= _names_of(functools.partial(parse, Path(f)))
        else:
            st = Path(f).stat()
            names |= _imported(str(f), st.st_mtime_ns, st.st_size)
    used = {d for d in NUMERICAL if IMPORT_NAMES.get(d, d) in names}
    used |= {b for d in list(used) for b in BUILDS_ON.get(d, ())}
    return tuple(d for d in NUMERICAL if d in used)

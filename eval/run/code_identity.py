"""The identity of the code that produces a result: part of every result-store key
(:mod:`eval.run.result_store`), so that a stored row is reused only by the code that computed it.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/experiments.md.

Example::

    >>> ident = code_identity(None)
    >>> sorted(ident), len(ident["sources"]), "eval.metrics.measures" in ident["modules"]
    (['modules', 'plugin', 'sources', 'versions'], 64, True)"""
from __future__ import annotations

import ast
import functools
import hashlib
import inspect
from collections.abc import Mapping
from importlib import metadata
from pathlib import Path

from eval.run.runinfo import REPO_ROOT

__all__ = ["PACKAGES", "NUMERICAL", "ROW_HARNESS", "code_text", "sources_digest", "project_modules", "import_closure",
           "modules_digest", "numerical_versions", "code_identity", "describe_change"]

#: The project's packages whose source makes a row (every floor of the house: the method,
#: the harness's shared tools, the baselines and the builder, the evaluator).
PACKAGES = ("sshade", "harness", "baselines", "defaust", "eval")

#: The modules that make a stored row besides the method: the pair runner (the guarded
#: call, the metrics, the info columns), the reference columns, the record format and the
#: runner of pairs in worker processes (their threads, the ``cores`` column).
ROW_HARNESS = ("eval.experiments.cases.pair", "eval.experiments.cases.case_references", "eval.run.result_store",
               "eval.experiments.cases.case_jobs")

#: Distributions whose version can change a row's numbers: the solvers and mesh
#: processing beneath the methods, and PyTorch (Implicit-ARAP, plug-ins).
NUMERICAL = ("numpy", "scipy", "libigl", "pymeshlab", "numba", "cholespy", "trimesh", "torch")


def _strip_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` with the docstring of every module, class and function removed."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return tree


@functools.lru_cache(maxsize=4096)
def _code_text(path: str, mtime_ns: int, size: int) -> bytes:
    """What of a module's source decides what it computes: its syntax tree without
    comments, docstrings, formatting or line numbers (``ast.dump``), as bytes; the raw
    bytes when the file does not parse. Cached by file, modification time and size."""
    data = Path(path).read_bytes()
    try:
        return ast.dump(_strip_docstrings(ast.parse(data)), include_attributes=False).encode()
    except (SyntaxError, ValueError):
        return data


def code_text(path) -> bytes:
    """:func:`_code_text` of the file ``path``: a comment, docstring or layout edit leaves
    it unchanged, any change to a statement or expression changes it."""
    st = Path(path).stat()
    return _code_text(str(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4)
def sources_digest(packages: tuple = PACKAGES, root: str | None = None) -> str:
    """SHA-256 (hex, 64 characters) of every ``.py`` file under the ``packages`` folders
    of ``root`` (default: this checkout or installed tree), each as its path relative to
    ``root`` and its :func:`code_text`, in sorted order; cached per process (the code of a
    running process does not change under it)."""
    base = Path(root) if root is not None else REPO_ROOT
    h = hashlib.sha256()
    for pkg in packages:
        for p in sorted((base / pkg).rglob("*.py")):
            if "__pycache__" in p.parts:
                continue
            h.update(str(p.relative_to(base)).encode() + b"\0")
            h.update(code_text(p) + b"\0")
    return h.hexdigest()


@functools.lru_cache(maxsize=4)
def project_modules(root: str | None = None) -> dict[str, Path]:
    """``{dotted name: file}`` of every module of :data:`PACKAGES` under ``root``
    (default: this checkout or installed tree); a package by its ``__init__.py``."""
    base = Path(root) if root is not None else REPO_ROOT
    mods = {}
    for pkg in PACKAGES:
        for p in sorted((base / pkg).rglob("*.py")):
            if "__pycache__" in p.parts:
                continue
            parts = p.relative_to(base).with_suffix("").parts
            mods[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return mods


def _resolve(name: str, mods: Mapping) -> str | None:
    """The project module ``name`` refers to: itself, or the nearest enclosing one
    (``pkg.mod.attr`` -> ``pkg.mod``); None outside the project."""
    while name and name not in mods:
        name = name.rpartition(".")[0]
    return name or None


def _imports(name: str, path: Path, mods: Mapping) -> set[str]:
    """The project modules that module ``name`` (file ``path``) imports, anywhere in it."""
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_bytes(), str(path))):
        if isinstance(node, ast.Import):
            out.update(r for a in node.names if (r := _resolve(a.name, mods)))
        elif isinstance(node, ast.ImportFrom):
            base = pkg
            for _ in range(max(node.level - 1, 0)):
                base = base.rpartition(".")[0]
            mod = (f"{base}.{node.module}" if node.module else base) if node.level else (node.module or "")
            out.update(r for r in [_resolve(mod, mods)] + [_resolve(f"{mod}.{a.name}", mods) for a in node.names]
                       if r)
    return out


@functools.lru_cache(maxsize=64)
def import_closure(roots: tuple, root: str | None = None) -> tuple[str, ...]:
    """The project modules (sorted dotted names) that the modules ``roots`` can import:
    each root, every module an ``import`` statement of a reached module names (module
    level or in a function), and the parent packages of each (run on import). Names
    outside :data:`PACKAGES` are left out; ``root`` as in :func:`project_modules`.

    >>> arap = import_closure(("baselines.fullres_arap",))
    >>> "eval.tables" in arap, "sshade.arap.solver" in arap
    (False, True)
    """
    mods = project_modules(root)
    seen: set[str] = set()
    todo = [r for r in (_resolve(str(x), mods) for x in roots) if r]
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        parts = m.split(".")
        todo += [p for p in (".".join(parts[:i]) for i in range(1, len(parts))) if p in mods]
        todo += _imports(m, mods[m], mods)
    return tuple(sorted(seen))


def modules_digest(modules, root: str | None = None) -> str:
    """SHA-256 (hex) of the files of the project ``modules`` (dotted names), each as its
    path relative to ``root`` and its :func:`code_text`, in sorted order."""
    base = Path(root) if root is not None else REPO_ROOT
    mods, h = project_modules(root), hashlib.sha256()
    for m in sorted(modules):
        h.update(str(mods[m].relative_to(base)).encode() + b"\0")
        h.update(code_text(mods[m]) + b"\0")
    return h.hexdigest()


def _targets(spec) -> list[str]:
    """Every ``_target_`` string in a method definition (nested mappings and lists too)."""
    if isinstance(spec, Mapping):
        out = [str(spec["_target_"])] if isinstance(spec.get("_target_"), str) else []
        return out + [t for v in spec.values() for t in _targets(v)]
    if isinstance(spec, (list, tuple)):
        return [t for v in spec for t in _targets(v)]
    return []


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


def _plugin_digest(method) -> str | None:
    """SHA-256 of the file defining ``type(method)`` when it lies outside :data:`PACKAGES`
    (a plug-in), None for the project's own methods; ``"unknown"`` when the file cannot
    be found or read (such a plug-in's rows are still keyed, by that word)."""
    cls = type(method)
    if cls.__module__.split(".")[0] in PACKAGES:
        return None
    try:
        f = inspect.getsourcefile(cls) or inspect.getfile(cls)
        return hashlib.sha256(Path(f).read_bytes()).hexdigest()
    except (TypeError, OSError):
        return "unknown"


def code_identity(method, spec=None, *, root: str | None = None) -> dict:
    """The code identity of ``method``'s rows (module docstring): ``{"sources": hex,
    "modules": [dotted names], "versions": {dist: version}, "plugin": hex or None}``.
    ``method``: the built method object, or None for the harness alone (``plugin``
    None); ``spec``: its resolved definition, whose ``_target_`` strings (nested ones
    too) add their modules; ``root`` as in :func:`project_modules`."""
    roots = list(ROW_HARNESS)
    if method is not None:
        roots.append(type(method).__module__)
    roots += [t.rpartition(".")[0] for t in _targets(spec)]
    mods = import_closure(tuple(sorted(set(roots))), root)
    return {"sources": modules_digest(mods, root), "modules": list(mods), "versions": dict(numerical_versions()),
            "plugin": None if method is None else _plugin_digest(method)}


def describe_change(old, new: dict) -> str:
    """In words, what differs between a stored record's code identity ``old`` (any JSON
    value: records written before code identities were keyed have none) and ``new``:
    e.g. ``"the project's sources changed"``, ``"numpy 1.26.4 -> 2.1.0"``, ``"the
    plug-in's source changed"``; ``""`` when they agree.

    >>> describe_change({"sources": "a", "versions": {"numpy": "1"}, "plugin": None},
    ...                 {"sources": "b", "versions": {"numpy": "2"}, "plugin": None})
    "the project's sources changed; numpy 1 -> 2"
    """
    if not isinstance(old, dict):
        return "a record without the identity of its code (written by an older version)"
    parts = []
    if old.get("sources") != new.get("sources"):
        parts.append("the project's sources changed")  # of the modules the row's code imports
    ov, nv = old.get("versions") if isinstance(old.get("versions"), dict) else {}, new.get("versions") or {}
    parts += [f"{d} {ov.get(d)} -> {nv.get(d)}" for d in sorted(set(ov) | set(nv)) if ov.get(d) != nv.get(d)]
    if old.get("plugin") != new.get("plugin"):
        parts.append("the plug-in's source changed")
    return "; ".join(parts)

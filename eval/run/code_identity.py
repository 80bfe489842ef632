"""The identity of the code that produces a result: part of every result-store key
(:mod:`eval.run.result_store`), so that a stored row is reused only by the code that computed it:
the method's modules and what they import (solvers, metrics, references, data loading),
through lazy packages (SPEC 1) and re-exports; literal constants by value; not the
modules that only store, run or present records (:data:`RECORD_ONLY`).
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

Example::

    >>> ident = code_identity(None)
    >>> sorted(ident), "eval.metrics.measures" in ident["modules"], "sshade.pipeline" in ident["modules"]
    (['constants', 'modules', 'plugin', 'reference', 'sources', 'versions'], True, False)"""
from __future__ import annotations

import ast
import functools
import hashlib
import inspect
from collections.abc import Mapping
from pathlib import Path

from eval.run.library_versions import NUMERICAL, numerical_versions, used_libraries
from eval.run.protocol_table import protocol_roots
from eval.run.runinfo import REPO_ROOT
from eval.run.syntax import attribute_chains, statements

__all__ = ["PACKAGES", "ROW_HARNESS", "ROW_REFERENCES", "ARTIFACTS", "RECORD_ONLY", "code_text", "sources_digest",
           "sources_snapshot", "project_modules", "import_closure", "closure_constants", "file_imports",
           "modules_digest", "same_code", "modules_digest_at", "identity_roots", "code_identity", "row_libraries",
           "artifact_identity"]

#: The project's packages whose source makes a row (every floor of the house: the method,
#: the harness's shared tools, the baselines and the builder, the evaluator).
PACKAGES = ("sshade", "harness", "baselines", "defaust", "eval")

#: The modules that make every stored row besides the method: the pair runner (the
#: guarded call, the metrics, the info columns).
ROW_HARNESS = ("eval.experiments.cases.pair",)

#: The modules that make a row's reference columns, part of the identity of the rows
#: that have them only (``key_fields.extra.reference.on``).
ROW_REFERENCES = ("eval.experiments.cases.case_references",)

#: The modules that make an artifact a row reads by its content: the reference solutions
#: (:mod:`eval.metrics.reference`, keyed by their own code and case). A row's closure stops
#: there; a row with reference columns holds the artifact's own identity beside its code
#: (:func:`artifact_identity`, ``code["reference"]``) and its record the digest of the
#: reference it was scored against, so that a reference solved again by other code, bit
#: for bit the same, leaves the row current (early cutoff; docs/reproduction.md).
ARTIFACTS = ("eval.metrics.reference",)

#: The modules (and packages, with everything under them) that only store, run or present
#: records: the ground floor (record format, options, paths, progress, run records), the
#: presentation and the runner of pairs in worker processes. Their source is no part of a
#: row's identity and the closure does not enter them: what they decide reaches a row's
#: key as values (its options, the case's data) or as the store's record version
#: (:data:`eval.run.result_store.STORE_VERSION`, bumped when the record changes).
RECORD_ONLY = ("eval.run", "eval.present", "eval.experiments.cases.case_jobs")

def _strip_docstrings(tree: ast.AST) -> ast.AST:
    """``tree`` with the docstring of every module, class and function removed."""
    for node in statements(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return tree


@functools.lru_cache(maxsize=4096)
def _code_text(path: str, mtime_ns: int, size: int) -> bytes:
    """What of a module's source decides what it computes: its syntax tree without
    comments, docstrings, formatting or line numbers (``ast.dump`` of :func:`_parse`), as
    bytes; the raw bytes when the file does not parse. Cached by file, modification time and size."""
    try:
        return ast.dump(_parse(path, mtime_ns, size), include_attributes=False).encode()
    except (SyntaxError, ValueError):
        return Path(path).read_bytes()


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


@functools.lru_cache(maxsize=32)
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


def _record_only(name: str) -> bool:
    """Whether the module ``name`` is (under) one of :data:`RECORD_ONLY`."""
    return any(name == r or name.startswith(r + ".") for r in RECORD_ONLY)


@functools.lru_cache(maxsize=512)  # the bound it had: trees of other commits share it (eval/run/stale_rows.py)
def _parse(path: str, mtime_ns: int, size: int) -> ast.Module:
    """The syntax tree of the file ``path`` without docstrings (:func:`_strip_docstrings`),
    parsed once per file, modification time and size and shared by every reader here:
    read, never changed. Raises SyntaxError or ValueError when the file does not parse."""
    return _strip_docstrings(ast.parse(Path(path).read_bytes(), path))


def _tree(path: Path) -> ast.Module:
    st = path.stat()
    return _parse(str(path), st.st_mtime_ns, st.st_size)


def _lazy_exports(path: Path) -> dict[str, str]:
    """``{name: submodule}`` that a package ``__init__`` binds lazily through a module-level
    ``lazy_loader.attach(__name__, submodules, submod_attrs)`` (literal arguments); ``{}``
    for any other ``__init__``."""
    out: dict[str, str] = {}
    for node in _tree(path).body:
        call = node.value if isinstance(node, (ast.Assign, ast.Expr)) else None
        f = getattr(call, "func", None)
        if not isinstance(call, ast.Call) or getattr(f, "attr", getattr(f, "id", None)) != "attach":
            continue
        args = {**dict(zip(("package_name", "submodules", "submod_attrs"), call.args)),
                **{k.arg: k.value for k in call.keywords}}
        try:
            subs = ast.literal_eval(args["submodules"]) if "submodules" in args else ()
            attrs = ast.literal_eval(args["submod_attrs"]) if "submod_attrs" in args else {}
        except ValueError:
            continue
        out.update({str(m): str(m) for m in subs or ()})
        out.update({str(a): str(m) for m, names in (attrs or {}).items() for a in names})
    return out


def _locate(name: str, mods: Mapping) -> tuple[str, list[str]] | None:
    """``(module, rest)``: the project module the dotted ``name`` refers to and the names
    left after it. Follows a lazy package's names (``sshade.deform`` -> ``sshade.pipeline``)
    and a name a module only re-exports (``from .params import MAX_SEED`` in
    ``sshade.pipeline`` -> ``sshade.params``); None outside the project."""
    parts = name.split(".")
    cur = next((".".join(parts[:i]) for i in range(len(parts), 0, -1) if ".".join(parts[:i]) in mods), None)
    if cur is None:
        return None
    rest = parts[cur.count(".") + 1:]
    for _ in range(32):  # a chain of re-exports, bounded (an import cycle of names stops here)
        if not rest:
            break
        nxt = _lazy_exports(mods[cur]).get(rest[0]) if mods[cur].name == "__init__.py" else None
        if nxt is not None and f"{cur}.{nxt}" in mods:
            cur, rest = f"{cur}.{nxt}", rest[1:]
            continue
        source = _reexport(cur, rest[0], mods)
        if source is None:
            break
        return _locate(".".join([source, *rest[1:]]), mods) or (cur, rest)
    return cur, rest


def _resolve(name: str, mods: Mapping) -> str | None:
    """The project module the dotted ``name`` refers to (:func:`_locate`), None outside the project."""
    found = _locate(name, mods)
    return found[0] if found else None


_LITERAL_NODES = (ast.Constant, ast.Tuple, ast.List, ast.Set, ast.Dict, ast.UnaryOp, ast.BinOp, ast.operator,
                  ast.unaryop, ast.expr_context)


def _literal(module: str, attr: str, mods: Mapping) -> str | None:
    """``ast.dump`` of the value of ``attr`` when module ``module`` binds it once, at module
    level, to a literal (numbers, strings, and tuples, lists, sets, dicts and arithmetic of
    them: ``MAX_SEED = 2**63 - 1``); None otherwise. Such a name counts by its value, not
    by its module's whole source."""
    value, n = None, 0
    for node in _tree(mods[module]).body:
        if isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(attr in {x.id for x in ast.walk(t) if isinstance(x, ast.Name)} for t in targets):
                n += 1
                ok = (len(targets) == 1 and isinstance(targets[0], ast.Name) and node.value is not None
                      and not isinstance(node, ast.AugAssign))
                value = node.value if ok else None
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Import, ast.ImportFrom)):
            if attr in {getattr(node, "name", None)} | {a.asname or a.name for a in getattr(node, "names", [])}:
                n += 2
    if n != 1 or value is None or not all(isinstance(x, _LITERAL_NODES) for x in ast.walk(value)):
        return None
    return ast.dump(value, include_attributes=False)


def _from_module(pkg: str, node: ast.ImportFrom) -> str:
    """The absolute dotted module a ``from ... import`` statement ``node`` of a module in
    package ``pkg`` imports from (its relative level resolved)."""
    if not node.level:
        return node.module or ""
    base = pkg
    for _ in range(node.level - 1):
        base = base.rpartition(".")[0]
    return f"{base}.{node.module}" if node.module else base


def _reexport(name: str, attr: str, mods: Mapping) -> str | None:
    """Where module ``name`` takes ``attr`` from when it only re-exports it (a module-level
    ``from X import attr``, and no definition or assignment of its own): the dotted name
    ``X.attr``, absolute; None when the module defines it (or does not bind it)."""
    pkg = name if mods[name].name == "__init__.py" else name.rpartition(".")[0]
    source = None
    for node in _tree(mods[name]).body:
        if isinstance(node, ast.ImportFrom):
            for a in node.names:
                if (a.asname or a.name) == attr:
                    source = f"{_from_module(pkg, node)}.{a.name}"
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.name == attr:
            return None
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(attr in {n.id for n in ast.walk(t) if isinstance(n, ast.Name)} for t in targets):
                return None
    return source


def _attribute_names(tree: ast.AST, bound: Mapping[str, str]) -> set[str]:
    """Dotted names used as attribute chains on the names ``bound`` (local name -> module
    name bound by ``import``): ``sshade.deform(...)`` after ``import sshade`` gives ``sshade.deform``."""
    return {".".join([bound[name], *chain]) for name, chain in attribute_chains(tree) if name in bound}


def _imports(name: str, path: Path, mods: Mapping) -> tuple[set[str], set[str]]:
    """``(modules, constants)``: the project modules that module ``name`` (file ``path``)
    imports, anywhere in it, each resolved through lazy packages and re-exports
    (:func:`_locate`), and the literal constants it imports (``"module.NAME"``,
    :func:`_literal`), which count by their value instead of their module."""
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = _tree(path)
    found, bound = set(), {}
    for node in statements(tree):  # in ast.walk's order: a name bound twice keeps the last binding
        if isinstance(node, ast.Import):
            for a in node.names:
                found.add(a.name)  # the module itself runs (a lazy package: only the names used, below)
                bound[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            mod = _from_module(pkg, node)
            found.update(f"{mod}.{a.name}" for a in node.names)
            # a module bound by name (``from eval import datasets``): its attributes are followed too
            bound.update({a.asname or a.name: f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in mods})
    found |= _attribute_names(tree, bound)
    modules, constants = set(), set()
    for x in found:
        loc = _locate(x, mods)
        if loc is None:
            continue
        m, rest = loc
        if rest and _literal(m, rest[0], mods) is not None:
            constants.add(f"{m}.{rest[0]}")
        elif not (x == m and _binds_lazily(m, mods)):
            modules.add(m)
    return modules, constants


def _binds_lazily(name: str, mods: Mapping) -> bool:
    """Whether ``name`` is a package whose ``__init__`` only binds names lazily: importing
    it runs no project code; the names used from it are followed instead."""
    return mods[name].name == "__init__.py" and bool(_lazy_exports(mods[name])) and not _eager(name, mods)


def _eager(name: str, mods: Mapping) -> bool:
    """Whether the package ``__init__`` of ``name`` imports a project module when it runs
    (a module-level import, not one inside a function): only then does importing one of
    its submodules run project code of its own."""
    body = [n for n in _tree(mods[name]).body if not isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                                      ast.ClassDef))]
    for node in body:
        for sub in ast.walk(node):
            if isinstance(sub, ast.Import) and any(_resolve(a.name, mods) for a in sub.names):
                return True
            if isinstance(sub, ast.ImportFrom) and (sub.level or _resolve(sub.module or "", mods)):
                return True
    return False


def sources_snapshot(root: str | None = None) -> tuple:
    """Each project file under ``root`` (default: this checkout) as ``(path, mtime in ns,
    size in bytes)``: what results computed from the sources are cached by until a file changes."""
    return tuple((str(p), (st := p.stat()).st_mtime_ns, st.st_size) for p in project_modules(root).values())


def _closure(roots: tuple, root: str | None, stop: tuple = ()) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(modules, constants)`` of :func:`import_closure` and :func:`closure_constants`."""
    return _closure_of(tuple(roots), root, sources_snapshot(root), tuple(stop))


@functools.lru_cache(maxsize=256)
def _closure_of(roots: tuple, root: str | None, snapshot: tuple, stop: tuple = ()
                ) -> tuple[tuple[str, ...], tuple[str, ...]]:
    mods = project_modules(root)
    known = _imports_of(root, snapshot)  # one snapshot's modules' imports, shared by every closure of it
    seen, consts = set(), set()
    todo = [r for r in (_resolve(str(x), mods) for x in roots) if r]
    stop = tuple(m for m in stop if m not in todo)  # a root is entered
    while todo:
        m = todo.pop()
        if m in seen or _record_only(m) or m in stop:
            continue
        seen.add(m)
        parts = m.split(".")
        todo += [p for p in (".".join(parts[:i]) for i in range(1, len(parts))) if p in mods and _eager(p, mods)]
        found, c = known[m] if m in known else known.setdefault(m, _imports(m, mods[m], mods))
        todo += found
        consts |= {x for x in c if not _record_only(x.rpartition(".")[0])}
    return tuple(sorted(seen)), tuple(sorted(consts))


@functools.lru_cache(maxsize=8)
def _imports_of(root: str | None, snapshot: tuple) -> dict:  # {module: _imports(...)} of one snapshot
    return {}


def import_closure(roots: tuple, root: str | None = None, stop: tuple = ()) -> tuple[str, ...]:
    """The project modules (sorted dotted names) whose code the modules ``roots`` can run:
    each root, every module an ``import`` statement of a reached module names (module
    level or in a function; through a lazy package or a re-export, the module that
    defines the name used; a literal constant counts by its value instead,
    :func:`closure_constants`), and the parent packages whose ``__init__`` imports
    project code when it runs. Names outside :data:`PACKAGES` and the modules under
    :data:`RECORD_ONLY` are left out, and the modules ``stop`` (unless a root; e.g.
    :data:`ARTIFACTS` for a row) with all they alone import; ``root`` as in :func:`project_modules`.

    >>> arap = import_closure(("baselines.fullres_converged",))
    >>> "eval.tables" in arap, "sshade.arap.solver" in arap, "sshade.pipeline" in arap
    (False, True, False)
    """
    return _closure(tuple(roots), root, stop)[0]


def file_imports(path, root: str | None = None) -> tuple[str, ...]:
    """The project modules (sorted dotted names) a Python file outside the packages (a
    script such as ``benchmarks/frames.py``) imports, anywhere in it, resolved as
    :func:`import_closure` resolves a module's imports: roots for :func:`import_closure`.
    Raises OSError when ``path`` cannot be read, SyntaxError when it does not parse."""
    mods = project_modules(root)
    return tuple(sorted(m for m in _imports("__main__", Path(path), mods)[0] if not _record_only(m)))


def closure_constants(roots: tuple, root: str | None = None, stop: tuple = ()) -> tuple[str, ...]:
    """The literal constants (sorted ``"module.NAME"``, :func:`_literal`) that the modules
    of :func:`import_closure` (``stop`` as there) import from modules outside it: part of
    the identity by value.

    >>> "sshade.params.MAX_SEED" in closure_constants(("harness.checks",))
    True
    """
    mods, consts = _closure(tuple(roots), root, stop)
    return tuple(c for c in consts if c.rpartition(".")[0] not in set(mods))


def modules_digest(modules, root: str | None = None, constants=()) -> str:
    """SHA-256 (hex) of the files of the project ``modules`` (dotted names), each as its
    path relative to ``root`` and its :func:`code_text`, in sorted order, then of each
    literal constant of ``constants`` (``"module.NAME"``) as its name and value
    (:func:`_literal`; a module or name missing under ``root`` counts as such).
    Raises KeyError when a module is missing under ``root``."""
    base = Path(root) if root is not None else REPO_ROOT
    mods = project_modules(root)
    return _digest(((mods[m], base) for m in sorted(modules)), constants, mods)


def _digest(files, constants, mods: Mapping) -> str:
    """SHA-256 (hex) of ``files`` (``(path, base)`` pairs, in order: each as its path
    relative to ``base`` and its :func:`code_text`), then of each of ``constants``
    (``"module.NAME"``, sorted) as its name and value in the project ``mods``
    (:func:`_literal`; a module or name missing there counts as such)."""
    h = hashlib.sha256()
    for path, base in files:
        h.update(str(path.relative_to(base)).encode() + b"\0")
        h.update(code_text(path) + b"\0")
    for c in sorted(constants):
        m, _, attr = c.rpartition(".")
        value = _literal(m, attr, mods) if m in mods else None
        h.update(f"{c}={value}".encode() + b"\0")
    return h.hexdigest()


def _bound_names(node: ast.stmt) -> tuple[str, ...]:
    """The names a top-level statement binds when it is a definition (a function, a class,
    an assignment to plain names), else ``()``."""
    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
        return (node.name,)
    if isinstance(node, (ast.Assign, ast.AnnAssign)) and getattr(node, "value", None) is not None:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        if all(isinstance(t, ast.Name) for t in targets):
            return tuple(t.id for t in targets)
    return ()


@functools.lru_cache(maxsize=1024)
def _parts(path: str, mtime_ns: int, size: int, pkg: str) -> tuple[tuple, tuple, frozenset]:
    """``(statements, bindings, used)`` of the module file ``path`` in package ``pkg``:
    each top-level statement but its imports and ``__all__`` as ``(names it defines,
    ast.dump)`` (docstrings left out, as :func:`code_text`), in order; ``(name, absolute
    dotted source)`` of each name its top-level imports bind; every name it reads or
    writes. Cached by file, modification time and size."""
    tree = _parse(path, mtime_ns, size)
    stmts, binds = [], []
    for node in tree.body:
        if isinstance(node, ast.Import):
            binds += [(a.asname or a.name.split(".")[0], a.name if a.asname else a.name.split(".")[0])
                      for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            binds += [(a.asname or a.name, f"{_from_module(pkg, node)}.{a.name}") for a in node.names]
        elif (names := _bound_names(node)) != ("__all__",):  # __all__ lists names, it runs nothing
            stmts.append((names, ast.dump(node, include_attributes=False)))
    used = frozenset(n.id for n in ast.walk(tree) if isinstance(n, ast.Name))
    return tuple(stmts), tuple(binds), used


def _module_parts(name: str, mods: Mapping) -> tuple[list, dict[str, str], frozenset]:
    """:func:`_parts` of project module ``name`` of ``mods``, its bindings as a dict."""
    path = mods[name]
    st = path.stat()
    pkg = name if path.name == "__init__.py" else name.rpartition(".")[0]
    stmts, binds, used = _parts(str(path), st.st_mtime_ns, st.st_size, pkg)
    return list(stmts), dict(binds), used


def _definition(dotted: str, mods: Mapping) -> tuple[str, str]:
    """What an imported dotted name means in the project ``mods``: ``("module", name)``
    for a project module, ``("def", ast.dump)`` of the top-level statement of the
    defining module that binds it (:func:`_locate`; docstrings left out), or
    ``("name", dotted)`` outside the project (or where no such statement is found)."""
    found = _locate(dotted, mods)
    if found is None:
        return "name", dotted
    module, rest = found
    if not rest and module.rpartition(".")[2] != dotted.rpartition(".")[2]:
        rest = [dotted.rpartition(".")[2]]  # a name a lazy package binds (_locate gives its module)
    if not rest:
        return "module", module
    for names, dump in _module_parts(module, mods)[0]:
        if rest[0] in names:
            return "def", dump
    return "name", f"{module}.{'.'.join(rest)}"


def _moved(stmts, binds: dict, mods: Mapping) -> list:
    """The definitions of ``stmts`` that the other side binds by import instead
    (``binds``, resolved in ``mods``) to the very same statement: moved to another module."""
    return [s for s in stmts if s[0] and all(n in binds and _definition(binds[n], mods) == ("def", s[1])
                                             for n in s[0])]


def same_code(name: str, tree, root: str | None = None) -> bool:
    """Whether project module ``name`` of the checkout ``root`` runs the same code as the
    sources under ``tree`` (a commit's, :mod:`eval.run.stale_rows`): its :func:`code_text`
    is the same there; or its statements are those there, in order, but for
    definitions that moved between it and another module (one side defines a name, the
    other imports the very same definition: :func:`_definition`), definitions it now
    imports from a record-only module (:data:`RECORD_ONLY`: no part of any identity) and
    definitions it dropped and no longer uses (:func:`_dropped`), each name its imports
    bind means the same there, and an import it no longer has binds a name it does not
    use; or, a new module, each of its definitions is word for word one of the code
    there, and each name it imports is bound to the same definition there. A move is not
    a change; anything else is."""
    now, then = project_modules(root), project_modules(str(tree))
    if name not in now:
        return False
    if name in then and code_text(then[name]) == code_text(now[name]):
        return True
    stmts, binds, used = _module_parts(name, now)
    if name not in then:
        return _new_module_moved(stmts, binds, now, then)
    old, old_binds, _ = _module_parts(name, then)
    out_, in_ = _moved(old, binds, now), _moved(stmts, old_binds, then)
    out_ += [s for s in old if s not in out_ and s[0] and all(n in binds and _record_only(binds[n]) for n in s[0])]
    out_ += _dropped([s for s in old if s not in out_ and s not in stmts], used, then[name])
    if [s for s in old if s not in out_] != [s for s in stmts if s not in in_]:
        return False
    moved_names = {n for s in out_ + in_ for n in s[0]}
    if any(n not in moved_names and not _record_only(b)  # a record-only module's names are no part of a row
           and (n not in old_binds or _definition(b, now) != _definition(old_binds[n], then))
           for n, b in binds.items()):
        return False
    return all(n in binds or n in moved_names or n not in used for n in old_binds)


def _dropped(stmts, used: frozenset, path: Path) -> list:
    """The statements of ``stmts``, gone from the module whose earlier file is ``path``,
    that defined what the module no longer uses (none of their names in ``used``) and ran
    nothing when defined: a function without decorators, or a name bound to a literal. A
    module that imported one from it now binds something else: a change found there."""
    st = path.stat()
    inert = _inert(str(path), st.st_mtime_ns, st.st_size)
    return [s for s in stmts if s[0] and not set(s[0]) & used and s[1] in inert]


@functools.lru_cache(maxsize=512)
def _inert(path: str, mtime_ns: int, size: int) -> frozenset:
    """The top-level statements of the module file ``path`` that run nothing when
    defined (:func:`_dropped`), each as its ``ast.dump``; cached by file, modification
    time and size."""
    inert = set()
    for node in _parse(path, mtime_ns, size).body:
        if (isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not node.decorator_list) or (
                isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None
                and all(isinstance(x, _LITERAL_NODES) for x in ast.walk(node.value))):
            inert.add(ast.dump(node, include_attributes=False))
    return frozenset(inert)


def _new_module_moved(stmts, binds: dict, now: Mapping, then: Mapping) -> bool:
    """Whether a module new since the sources ``then`` only holds definitions moved there
    from them (:func:`same_code`): each statement a definition found word for word in
    one of ``then``'s modules, each import binding what such a module binds by that name."""
    if not stmts or any(not s[0] for s in stmts):
        return False
    names, plain = [n.encode() for s in stmts for n in s[0]], all(n.isascii() for s in stmts for n in s[0])
    sources = {m for m in then if (not plain or any(map(then[m].read_bytes().__contains__, names)))  # spells one?
               and set(stmts) & set(_module_parts(m, then)[0])}  # (a text read once per module; NFKC: parse all)
    if not set(stmts) <= {s for m in sources for s in _module_parts(m, then)[0]}:
        return False
    meanings = {}
    for m in sources:
        old, old_binds, _ = _module_parts(m, then)
        meanings.update({n: _definition(b, then) for n, b in old_binds.items()})
        meanings.update({n: ("def", d) for names, d in old for n in names})
    return all(_record_only(b) or meanings.get(n) == _definition(b, now) for n, b in binds.items())


def modules_digest_at(modules, tree, root: str | None = None, constants=()) -> str:
    """:func:`modules_digest` of the ``modules`` and ``constants`` of the checkout ``root``
    with their code as under ``tree`` (a commit's sources): each module that runs the
    same code there (:func:`same_code`, a move included) counts as it is in ``root``,
    any other as it is under ``tree``; equal to ``modules_digest(modules, root,
    constants)`` exactly when no module and no constant differs. Raises KeyError naming
    a module missing under ``tree`` (and not moved there)."""
    base = Path(root) if root is not None else REPO_ROOT
    now, then = project_modules(root), project_modules(str(tree))
    return _digest(((now[m], base) if same_code(m, tree, root) else (then[m], Path(tree)) for m in sorted(modules)),
                   constants, then)


def _targets(spec) -> list[str]:
    """Every ``_target_`` string in a method definition (nested mappings and lists too)."""
    if isinstance(spec, Mapping):
        out = [str(spec["_target_"])] if isinstance(spec.get("_target_"), str) else []
        return out + [t for v in spec.values() for t in _targets(v)]
    if isinstance(spec, (list, tuple)):
        return [t for v in spec for t in _targets(v)]
    return []


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


def identity_roots(spec: Mapping | None, references: bool = True, root: str | None = None) -> tuple[str, ...]:
    """The modules a row's identity starts from (sorted): :data:`ROW_HARNESS`, with
    ``references`` (the row has reference columns) :data:`ROW_REFERENCES`, and for a
    method's resolved definition ``spec`` (as stored in a record's key, :mod:`eval.run.result_store`)
    the dotted names of its ``class`` and of every ``_target_`` in it (nested ones too),
    which :func:`import_closure` resolves to the modules defining them, and those its
    ``protocol`` runs in (:func:`eval.run.protocol_table.protocol_roots`; ``root`` as in :func:`project_modules`).

    >>> identity_roots({"class": "baselines.fullres_arap.ARAP", "_target_": "baselines.ARAP",
    ...                 "protocol": "paper"}, False)
    ('baselines.ARAP', 'baselines.fullres_arap.ARAP', 'baselines.fullres_paper', 'eval.experiments.cases.pair')
    """
    roots = list(ROW_HARNESS) + (list(ROW_REFERENCES) if references else [])
    if isinstance(spec, Mapping):
        roots += [spec["class"]] if isinstance(spec.get("class"), str) else []
        roots += _targets(spec)  # resolved through lazy packages: "baselines.ARAPSR" -> baselines.arap_sr
        roots += protocol_roots(spec, project_modules(root))
    return tuple(sorted({r for r in roots if r}))


def code_identity(method, spec=None, *, references: bool = True, root: str | None = None) -> dict:
    """The code identity of ``method``'s rows (module docstring): ``{"sources": hex,
    "modules": [dotted names], "constants": ["module.NAME"], "versions": {dist: version},
    "plugin": hex or None}`` (``sources``: :func:`modules_digest` of the modules and constants).
    ``method``: the built method object, or None for the harness alone (``plugin``
    None); ``spec``: its resolved definition (:func:`identity_roots`; without a ``class``
    the method's own module is taken); ``references``: of the rows with reference
    columns (:data:`ROW_REFERENCES`; their closure stops at :data:`ARTIFACTS`, whose own
    identity is then ``"reference"``, :func:`artifact_identity`); ``root`` as in
    :func:`project_modules`."""
    spec = dict(spec or {})
    if method is not None and "class" not in spec:
        spec["class"] = f"{type(method).__module__}.{type(method).__qualname__}"
    roots = identity_roots(spec, references, root)
    mods, consts = import_closure(roots, root, ARTIFACTS), closure_constants(roots, root, ARTIFACTS)
    plugin = None if method is None else _plugin_digest(method)
    used = set(row_libraries(mods, root)) if plugin is None else set(NUMERICAL)  # a plug-in's imports are unseen
    out = {"sources": modules_digest(mods, root, consts), "modules": list(mods), "constants": list(consts),
           "versions": {d: v for d, v in numerical_versions().items() if d in used}, "plugin": plugin}
    if references:
        out["reference"] = artifact_identity(root)
    return out


def row_libraries(modules, root: str | None = None) -> tuple[str, ...]:
    """The numerical libraries whose version is part of the identity of a row made of the
    project ``modules`` (:func:`eval.run.library_versions.used_libraries` of their files
    under ``root``)."""
    mods = project_modules(root)
    return used_libraries((mods[m] for m in modules if m in mods), parse=_tree)


def artifact_identity(root: str | None = None) -> dict:
    """The identity of the code that solves the references (:data:`ARTIFACTS` and their
    closure): ``{"sources": hex, "modules": [...], "constants": [...]}`` as in
    :func:`code_identity`, at the checkout ``root`` (default: this one)."""
    mods, consts = import_closure(ARTIFACTS, root), closure_constants(ARTIFACTS, root)
    return {"sources": modules_digest(mods, root, consts), "modules": list(mods), "constants": list(consts)}


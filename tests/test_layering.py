"""The house rules, checked on the source (AST, nothing imported):
sshade/ (the method) at the bottom, harness/ (the shared tools) above it, baselines/ and
defaust/ above that, eval/ on top, and inside eval/ its own floors (:data:`EVAL_FLOORS`);
imports only go down, never in a cycle, never a private name across modules, and a
project module is imported at the top of a module, not hidden inside a function."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

from .conftest import ROOT

#: package -> floor; a module may import from its own floor's package or a lower floor.
FLOORS = {"sshade": 0, "harness": 1, "baselines": 2, "defaust": 2, "eval": 3}


def _modules() -> dict[str, Path]:
    mods = {}
    for pkg in FLOORS:
        for p in sorted((ROOT / pkg).rglob("*.py")):
            parts = p.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            mods[name] = p
    return mods


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The project module ``name`` refers to (itself, or its parent for ``pkg.mod.attr``)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(mod: str, path: Path):
    """(line, target module, imported names, at module level?) of every project import."""
    tree = ast.parse(path.read_text(), str(path))
    top = set(map(id, tree.body))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] in FLOORS:
                    yield node.lineno, a.name, [], id(node) in top
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = mod.split(".") if path.name == "__init__.py" else mod.split(".")[:-1]
                base = base[:len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] in FLOORS:
                names = [a.name for a in node.names]
                yield node.lineno, target, names, id(node) in top or _guarded_top(tree, node)


def _guarded_top(tree, node) -> bool:
    """An import inside a module-level ``try:`` / ``if TYPE_CHECKING:`` counts as top level."""
    for stmt in tree.body:
        if isinstance(stmt, (ast.Try, ast.If)) and any(n is node for n in ast.walk(stmt)):
            return True
    return False


EDGES = [(m, ln, t, names, top) for m, p in MODULES.items() for ln, t, names, top in _imports(m, p)]


def test_imports_only_go_down():
    up = [f"{m}:{ln} imports {t}" for m, ln, t, _, _ in EDGES
          if FLOORS[t.split(".")[0]] > FLOORS[m.split(".")[0]]
          or (FLOORS[t.split(".")[0]] == FLOORS[m.split(".")[0]] and t.split(".")[0] != m.split(".")[0])]
    assert not up, "imports that climb or cross a floor:\n" + "\n".join(up)


#: eval/'s floors, bottom up: subpackage (or top module) -> floor. A module of eval/ belongs
#: to the longest name here that is it or its package (``eval``: the commands on top, i.e.
#: app, config_check, report, leaderboard, reproduce, __main__; above them the sweep
#: command eval.sweeps.sweep_command, run by eval.sweeps.__main__); it may import its own
#: part of eval/ or a lower floor, never a part on its own floor or above.
EVAL_FLOORS = {
    "eval.run": 0,  # the ground: run folder, store, names, run.json, plan, progress, subsets, code identity
    "eval.registry_base": 0,  # the plug-in registries' common part
    "eval.config_schema": 1,  # the config's types, registered with Hydra's ConfigStore (some are eval.run.spec's)
    "eval.metrics": 1,  # what a result is scored by
    "eval.method_config": 1,  # the methods from the config
    "eval.datasets": 2,  # the cases, each dataset with its options (registered as its section's config type)
    "eval.present": 2,  # presentation: figures, table text, stops, rows, views
    "eval.exchange": 2,  # results computed outside the harness
    "eval.tables": 3,  # the comparison tables, written by the experiments and the sweeps
    "eval.experiments": 4,  # the experiment kinds
    "eval.sweeps": 4,  # a sweep's files, table and launcher
    "eval": 5,  # the commands
    "eval.sweeps.sweep_command": 6,  # the sweep command, each job a run of eval.app
    "eval.sweeps.__main__": 7,  # runs it: python -m eval.sweeps
}


def _eval_part(mod: str) -> str:
    """The entry of :data:`EVAL_FLOORS` module ``mod`` of eval/ belongs to."""
    return max((k for k in EVAL_FLOORS if mod == k or mod.startswith(k + ".")), key=len)


def test_eval_floors_name_every_subpackage():
    subs = {f"eval.{p.parent.name}" for p in (ROOT / "eval").glob("*/__init__.py")}
    missing = sorted(subs - set(EVAL_FLOORS))
    assert not missing, f"eval subpackages without a floor in EVAL_FLOORS: {missing}"
    assert not set(EVAL_FLOORS) - set(MODULES), "EVAL_FLOORS names a module that is not there"


def test_eval_subpackages_import_only_their_own_floor_or_below():
    bad = []
    for m, ln, t, names, _ in EDGES:
        if not (m + ".").startswith("eval.") or not (t + ".").startswith("eval."):
            continue
        own = _eval_part(m)
        for target in {_resolve(f"{t}.{n}") or _resolve(t) for n in names} if names else {_resolve(t)}:
            part = _eval_part(target)
            if part != own and EVAL_FLOORS[part] >= EVAL_FLOORS[own]:
                bad.append(f"{m}:{ln} imports {target} ({part}, floor {EVAL_FLOORS[part]}; "
                           f"{own} is on floor {EVAL_FLOORS[own]})")
    assert not bad, "eval imports that climb or cross a floor:\n" + "\n".join(bad)


#: What the method package never imports, not even inside a function: the harness's config
#: and table libraries.
HARNESS_LIBRARIES = ("hydra", "omegaconf", "pandas", "matplotlib")


def test_the_method_package_imports_no_config_or_table_library():
    bad = []
    for m, p in MODULES.items():
        if not m.startswith("sshade"):
            continue
        for node in ast.walk(ast.parse(p.read_text(), str(p))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
            bad += [f"{m}:{node.lineno} imports {n}" for n in names if n.split(".")[0] in HARNESS_LIBRARIES]
    assert not bad, "\n".join(bad)


def test_importing_every_module_of_the_method_package_loads_nothing_above_it():
    code = ("import importlib, pkgutil, sys, sshade\n"
            "for m in pkgutil.walk_packages(sshade.__path__, 'sshade.'):\n"
            "    importlib.import_module(m.name)\n"
            "print(' '.join(sorted({m.split('.')[0] for m in sys.modules})))")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    loaded = set(r.stdout.split()) & {*HARNESS_LIBRARIES, *(p for p in FLOORS if p != "sshade")}
    assert not loaded, loaded


def test_no_private_name_across_modules():
    bad = []
    for m, ln, t, names, _ in EDGES:
        target = _resolve(t)
        for n in names:
            private = n.startswith("_") and not n.startswith("__")
            sub = _resolve(f"{t}.{n}")  # `from pkg import _mod` is a module, still private
            if private and (sub or target) != m:
                bad.append(f"{m}:{ln} imports {n} from {t}")
    assert not bad, "private names imported across modules:\n" + "\n".join(bad)


def test_project_imports_at_module_top():
    hidden = [f"{m}:{ln} imports {t} inside a function" for m, ln, t, _, top in EDGES if not top]
    assert not hidden, "\n".join(hidden)


def test_no_import_cycles():
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for m, _, t, names, _ in EDGES:
        for target in {_resolve(f"{t}.{n}") or _resolve(t) for n in names} if names else {_resolve(t)}:
            if target and target != m and not m.startswith(target + "."):  # a package's own __init__
                graph[m].add(target)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles = []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


@pytest.mark.parametrize("pkg", list(FLOORS))
def test_modules_and_functions_stay_small(pkg):
    """Modules under ~600 lines, functions under ~80, with the numba
    kernels that must stay one function named here."""
    big_modules, big_functions = [], []
    for m, p in MODULES.items():
        if not m.startswith(pkg):
            continue
        text = p.read_text()
        if len(text.splitlines()) > 650:
            big_modules.append(f"{m}: {len(text.splitlines())} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > 100:
                    big_functions.append(f"{m}.{node.name}: {n} lines")
    assert not big_modules and not big_functions, "\n".join(big_modules + big_functions)


#: Where the prose lives that the tracker rule covers: source, tests, configs, docs.
_PROSE_GLOBS = ("sshade/**/*.py", "harness/**/*.py", "baselines/**/*.py", "defaust/**/*.py", "eval/**/*.py",
                "tests/**/*.py", "benchmarks/**/*.py", "conf/**/*.yaml", "docs/**/*.md", "*.md", "pyproject.toml")


def test_no_issue_numbers_in_code_or_docs():
    """The tracker is not part of the repository: code, tests, configs and
    docs say what a thing does, never which issue made it; history lives in git log."""
    pattern = re.compile(r"\bissues?\s+#?\d+", re.I)
    hits = []
    for glob in _PROSE_GLOBS:
        for p in sorted(ROOT.glob(glob)):
            for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
                if pattern.search(line):
                    hits.append(f"{p.relative_to(ROOT)}:{n}: {line.strip()[:100]}")
    assert not hits, "\n".join(hits)


def _docstrings(tree) -> set[int]:
    """ids of the docstring constants of a module, its classes and functions."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                out.add(id(first.value))
    return out


def test_no_builtin_method_name_is_a_string_literal_in_eval():
    """A method's facts live in its conf/method/<name>.yaml and its module: no string of a
    module of eval/ is a built-in method's name (docstrings aside; prose that mentions
    one, such as a message or a column title, is not a name), so adding or renaming a
    method edits no harness code."""
    from harness.method_registry import builtin_methods
    names = set(builtin_methods())
    found = []
    for mod, path in MODULES.items():
        if not mod.startswith("eval"):
            continue
        tree = ast.parse(path.read_text(), str(path))
        skip = _docstrings(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip:
                if node.value.strip() in names:
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {node.value!r}")
    assert not found, found

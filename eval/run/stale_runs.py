"""Which committed folders run whole (no stored rows) are stale, and why.

A folder run whole (an experiment such as ``convergence`` or ``scaling``, or a benchmark
script such as ``benchmarks/frames.py``) keeps no per-row code identity: it names the
commit that made it (``run.json``'s ``git``, or its ``table.md``'s "Made by ... at git
commit" line). It is current when every module its run can execute (the import closure
of its experiment's module, or of the script's imports and its ``CODE_ROOTS``) and the
script itself have the same code (:func:`eval.run.code_identity.code_text`) at that
commit as in this checkout; git must hold the commit (:class:`eval.run.stale_rows.CommitTrees`).
Only code is held, not the config: a run's effective settings are in its ``run.json``.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.
"""
from __future__ import annotations

import ast
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from eval.run.code_identity import closure_constants, code_text, file_imports, import_closure
from eval.run.result_store import STORE_DIR
from eval.run.runinfo import REPO_ROOT
from eval.run.stale_rows import CommitTrees, changed_since
from sshade.json_file import read_json

__all__ = ["MADE_BY", "RunOrigin", "RunState", "is_whole_run", "whole_run_folders", "run_origin", "whole_run_state"]

#: A benchmark script's provenance line in the ``table.md`` it writes: its path, commit, dirty flag.
MADE_BY = re.compile(r"Made by `python (benchmarks/[\w]+\.py)[^`]*` at git commit ([0-9a-f]{40}) \(dirty: (\w+)\)")


@dataclass(frozen=True)
class RunOrigin:
    """What made a folder run whole: the ``commit`` (40 hex digits or None), whether the
    checkout was ``dirty``, and either the experiment ``kind`` (``run.json``) or the
    ``script`` (a path relative to the repository, from ``table.md``)."""

    commit: str | None
    dirty: bool | None
    kind: str | None = None
    script: str | None = None


@dataclass
class RunState:
    """A folder run whole: its ``origin``, whether it is ``stale`` and ``why`` (``""`` when current)."""

    folder: Path
    origin: RunOrigin | None
    stale: bool
    why: str = ""


def run_origin(folder) -> RunOrigin | None:
    """The :class:`RunOrigin` of ``folder`` (untrusted files: a missing, unreadable or
    malformed record gives None): its ``run.json`` (``git``, ``config.experiment.kind``)
    when it has one, else the "Made by" line of its ``table.md`` (:data:`MADE_BY`)."""
    folder = Path(folder)
    run = folder / "run.json"
    if run.is_file() and not run.is_symlink():
        try:
            rec = read_json(run)
        except (OSError, ValueError, RecursionError):
            return None
        git = rec.get("git") if isinstance(rec, dict) else None
        exp = (rec.get("config") or {}).get("experiment") if isinstance(rec.get("config"), dict) else None
        if not isinstance(git, dict) or not isinstance(exp, dict):
            return None
        commit, dirty, kind = git.get("commit"), git.get("dirty"), exp.get("kind")
        return RunOrigin(commit if isinstance(commit, str) else None, dirty if isinstance(dirty, bool) else None,
                         kind=kind if isinstance(kind, str) else None)
    table = folder / "table.md"
    if table.is_file() and not table.is_symlink():
        try:
            found = MADE_BY.search(table.read_text(errors="replace"))
        except OSError:
            return None
        if found:
            return RunOrigin(found[2], {"True": True, "False": False}.get(found[3]), script=found[1])
    return None


def is_whole_run(folder) -> bool:
    """Whether ``folder`` is a folder run whole: a directory (not a link) with a
    ``run.json`` or a benchmark's ``table.md`` and no result store (``runs/``: those are
    held row by row)."""
    d = Path(folder)
    return (d.is_dir() and not d.is_symlink() and not (d / STORE_DIR).exists()
            and ((d / "run.json").is_file() or (d / "table.md").is_file()))


def whole_run_folders(top) -> list[Path]:
    """The folders directly under ``top`` run whole (:func:`is_whole_run`), sorted."""
    top = Path(top)
    return [d for d in sorted(top.iterdir()) if is_whole_run(d)] if top.is_dir() else []


def _script_roots(path: Path, root: str | None) -> tuple[str, ...]:
    """A script's imports and the dotted names of its literal ``CODE_ROOTS`` (the code it
    runs in other processes, which no import statement names)."""
    extra: list[str] = []
    for node in ast.parse(path.read_bytes()).body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "CODE_ROOTS" for t in node.targets):
            extra += [x for x in ast.literal_eval(node.value) if isinstance(x, str)]
    return (*file_imports(path, root), *extra)


def whole_run_state(folder, trees: CommitTrees, find_run: Callable[[str], Callable | None],
                    root: str | None = None) -> RunState:
    """The :class:`RunState` of the folder run whole ``folder``: stale when its origin is
    unknown, dirty or not in git, or when a module its run can execute (or its script)
    differs between its commit and the checkout ``root`` (default: this one);
    ``find_run(kind)``: experiment ``kind``'s run function, None for no such kind
    (:func:`eval.experiments.find_experiment`); its module is where the run's code starts."""
    origin = run_origin(folder)
    st = RunState(Path(folder), origin, True)
    base = Path(root) if root is not None else REPO_ROOT
    if origin is None:
        st.why = "no run.json with its commit and experiment, nor a benchmark's 'Made by' line"
        return st
    if origin.dirty is not False:
        st.why = "made by a checkout with uncommitted changes (or of unknown state)"
        return st
    tree = trees.tree(origin.commit)
    if tree is None:
        st.why = f"its commit {str(origin.commit)[:7]} is not in this clone: its code cannot be compared"
        return st
    try:
        if origin.script is not None:
            roots, files = _script_roots(base / origin.script, root), [origin.script]
        else:
            module = getattr(find_run(origin.kind), "__module__", None) if origin.kind else None
            if module is None:
                st.why = f"experiment kind {origin.kind!r} is not one of this checkout"
                return st
            roots, files = (module,), []
    except (OSError, SyntaxError, ValueError) as e:
        st.why = f"its script cannot be read: {e}"
        return st
    changed = changed_since(import_closure(roots, root), closure_constants(roots, root), tree, root)
    changed += [f for f in files if not (tree / f).is_file() or code_text(tree / f) != code_text(base / f)]
    st.stale = bool(changed)
    st.why = f"{', '.join(sorted(changed))} changed since {origin.commit[:7]}" if changed else ""
    return st


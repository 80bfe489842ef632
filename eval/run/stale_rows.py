"""Which stored rows are stale, and why; re-keying records whose code git still has.

A stored row (:mod:`eval.run.result_store`) is current when its record is of this store
version and its code identity's ``sources`` equal what
:func:`eval.run.code_identity.code_identity` gives for its method at this checkout (the
numerical libraries' versions are this machine's, not the code's: they are reported, not
judged here). A record keyed under earlier identity rules (store version 4, or this one)
is re-keyed, never recomputed, when git has the commit its ``git`` names and that commit's
sources give its recorded identity: its new identity is computed from that commit's
sources, for the modules its method's identity is made of now.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.
"""
from __future__ import annotations

import functools
import io
import os
import subprocess
import tarfile
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from eval.run.code_identity import (
    ARTIFACTS,
    PACKAGES,
    artifact_identity,
    closure_constants,
    identity_roots,
    import_closure,
    modules_digest,
    modules_digest_at,
    row_libraries,
    same_code,
    sources_snapshot,
)
from eval.run.pending_rows import short_commit
from eval.run.result_store import (
    OTHER_SETTINGS,
    STORE_DIR,
    STORE_VERSION,
    ResultStore,
    check_row,
    fields_digest,
    pair_key,
    record_digest,
)
from eval.run.row_check import check_rows, read_cases
from eval.run.runinfo import REPO_ROOT, machine_words
from sshade.errors import SShaDeError
from sshade.json_file import read_json

__all__ = ["REKEY_FROM", "CommitTrees", "RowState", "record_paths", "run_folders", "changed_since", "row_state",
           "check_folders", "settings_marks", "table_problems", "rekey_record", "references_on",
           "folder_states", "current_code", "row_machines"]

#: The folders of scripts whose runs are held to their code besides the packages
#: (:mod:`eval.run.stale_runs`): extracted with them.
SCRIPTS = ("benchmarks",)

#: The store versions whose records :func:`rekey_record` converts besides this one's: 4 (a
#: row's identity held the reference columns' code where it has none, and the loaders,
#: through the lazy dataset and experiment packages) and 5 (it held the reference solver's
#: code, now an artifact of its own: ``code["reference"]``).
REKEY_FROM = (4, 5)


class CommitTrees:
    """The project's sources (:data:`eval.run.code_identity.PACKAGES`, :data:`SCRIPTS`) at git commits,
    extracted once each per process (``git archive``) into a temporary folder removed when
    the process exits: a commit's sources never change, so every check of a process reads
    the same files, and what was computed from them stays cached (:func:`changed_since`).
    A context manager, as it was when each instance held its own folder."""

    def __init__(self, repo=REPO_ROOT):
        self.repo = Path(repo)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        """Nothing: the extracted trees are the process's (removed at its exit)."""

    def tree(self, commit) -> Path | None:
        """The folder holding the sources of ``commit`` (40 hex digits), None when it is
        no commit of this repository (or git is missing)."""
        if not isinstance(commit, str) or len(commit) != 40 or any(c not in "0123456789abcdef" for c in commit):
            return None
        key = (str(self.repo.resolve()), commit)
        with _EXTRACTING:
            if key not in _EXTRACTED:
                _EXTRACTED[key] = self._extract(commit, Path(_extracted_dir().name) / str(len(_EXTRACTED)))
            return _EXTRACTED[key]

    def _extract(self, commit: str, dest: Path) -> Path | None:
        """``git archive`` of the packages and scripts at ``commit`` (only the packages
        where that commit had no scripts' folder), extracted into ``dest``; None when git cannot."""
        here = [p for p in (*PACKAGES, *SCRIPTS) if (self.repo / p).is_dir()]
        for paths in (here, [p for p in here if p not in SCRIPTS]):
            try:
                r = subprocess.run(["git", "-C", str(self.repo), "archive", "--format=tar", commit, "--", *paths],
                                   capture_output=True, timeout=120, check=False)
            except (OSError, subprocess.TimeoutExpired):
                return None
            if r.returncode == 0:
                with tarfile.open(fileobj=io.BytesIO(r.stdout)) as tf:
                    tf.extractall(dest, filter="data")  # refuses links out and absolute names
                return dest
        return None


#: ``(repository, commit) -> its extracted sources`` (None: git could not), per process.
_EXTRACTED: dict[tuple[str, str], Path | None] = {}
_EXTRACTING = threading.Lock()


@functools.lru_cache(maxsize=1)
def _extracted_dir() -> tempfile.TemporaryDirectory:
    """The process's folder of extracted commits (removed when the process exits)."""
    return tempfile.TemporaryDirectory(prefix="sshade-commits-")


@dataclass
class RowState:
    """One stored record: its folder (the run's ``out_dir``), case, method, whether it is
    stale and why (``""`` when current), the commit that computed it and its ``time_s``."""
    folder: Path
    case: str
    method: str
    stale: bool
    why: str = ""
    commit: str | None = None
    time_s: float | None = None
    extra: dict = field(default_factory=dict)


def run_folders(top) -> list[Path]:
    """Every run folder under ``top`` (``top`` itself included) that holds a result store
    (``runs/``), sorted; symbolic links are not followed."""
    top = Path(top)
    found = [p.parent for p in top.rglob(STORE_DIR) if p.is_dir() and not p.is_symlink()]  # rglob enters no link
    return sorted(p for p in found if STORE_DIR not in p.relative_to(top).parts)


def record_paths(folder) -> Iterator[tuple[str, Path]]:
    """``(case folder name, record path)`` of every ``runs/<case>/<method>.json`` of
    ``folder``, sorted; an entry of ``runs/`` that is no folder (a file, a link) comes as
    its own path, and a record that is a link as its path, for the caller to refuse."""
    root = Path(folder) / STORE_DIR
    for d in sorted(root.iterdir()) if root.is_dir() else []:
        if d.is_symlink() or not d.is_dir():
            yield d.name, d
            continue
        for p in sorted(d.glob("*.json")):
            yield d.name, p


def row_machines(folders, pairs=None) -> dict[str, int]:
    """How many records under ``folders`` (run folders) each machine made, by
    :func:`eval.run.runinfo.machine_words`; records without a machine (older ones), links
    and unreadable ones are not counted. ``pairs``: a set of ``(case, method)`` to count
    alone (None: every record)."""
    counts: dict[str, int] = {}
    for folder in folders:
        for case, p in record_paths(folder):
            if pairs is not None and (case, p.stem) not in pairs:
                continue
            rec = None if p.is_symlink() or not p.is_file() else _read_json(p)
            words = machine_words(rec.get("machine")) if isinstance(rec, dict) else None
            if words is not None:
                counts[words] = counts.get(words, 0) + 1
    return counts


def _read_json(p: Path):
    try:
        return read_json(p)
    except (OSError, ValueError, RecursionError):
        return None


def references_on(fields) -> bool:
    """Whether a record's key fields ``fields`` say its row has reference columns
    (``extra.reference.on``; a record of unknown shape counts as having them)."""
    extra = fields.get("extra") if isinstance(fields, dict) else None
    ref = extra.get("reference") if isinstance(extra, dict) else None
    return not isinstance(ref, dict) or ref.get("on") is not False


def _now(fields, root: str | None = None) -> tuple[tuple, tuple]:
    """``(modules, constants)`` of the identity of a record with key fields ``fields`` at the checkout ``root``."""
    spec = fields.get("method") if isinstance(fields, dict) else None
    roots = identity_roots(spec, references_on(fields), root)
    return import_closure(roots, root, ARTIFACTS), closure_constants(roots, root, ARTIFACTS)


def current_code(fields, root: str | None = None) -> dict:
    """What a record with key fields ``fields`` would hold as ``code`` had the checkout
    ``root`` (default: this one) made it: its ``sources`` digest, ``modules`` and
    ``constants`` (:func:`_now`), and ``reference`` (the identity of the code that solves
    references) where ``fields["code"]`` has one; the other entries kept. A dict."""
    code = dict(fields.get("code") or {}) if isinstance(fields, dict) else {}
    mods, consts = _now(fields, root)
    code.update(sources=modules_digest(mods, root, consts), modules=list(mods), constants=list(consts))
    if "reference" in code:
        code["reference"] = artifact_identity(root)
    return code


def changed_since(mods, consts, tree: Path, root: str | None = None) -> list[str]:
    """The modules (and constants) of ``mods``/``consts`` whose code differs between the
    sources under ``tree`` (a commit's, as :class:`CommitTrees` extracts them: never
    changed while it exists) and the checkout ``root`` (a definition moved is no change:
    :func:`eval.run.code_identity.same_code`). Cached per process by the checkout's file
    stamps (:func:`eval.run.code_identity.sources_snapshot`): the rows one commit made for
    one method ask once."""
    return list(_changed(tuple(mods), tuple(consts), str(tree), root, sources_snapshot(root)))


@functools.lru_cache(maxsize=1024)
def _changed(mods: tuple, consts: tuple, tree: str, root: str | None, snapshot: tuple) -> tuple[str, ...]:
    out = [m for m in mods if not same_code(m, tree, root)]
    out += [c for c in consts if modules_digest((), tree, (c,)) != modules_digest((), root, (c,))]
    return tuple(out)


def row_state(folder, rec: dict, trees: CommitTrees, root: str | None = None) -> RowState:
    """The :class:`RowState` of a record ``rec`` (read from ``folder``'s store and found
    valid there): stale when of another store version or when its code identity's
    sources differ from those of the checkout ``root`` (default: this one) for its
    method; ``why`` names the modules that changed since its commit where git has that commit."""
    row = rec.get("row") if isinstance(rec.get("row"), dict) else {}
    git = rec.get("git") if isinstance(rec.get("git"), dict) else {}
    st = RowState(Path(folder), str(rec.get("case")), str(rec.get("method")), False, commit=git.get("commit"),
                  time_s=row.get("time_s") if isinstance(row.get("time_s"), (int, float)) else None)
    if rec.get("version") != STORE_VERSION:
        st.stale, st.why = True, (f"store version {rec.get('version')!r}, now {STORE_VERSION}"
                                  + (" (python -m eval.reproduce --rekey)" if rec.get("version") in REKEY_FROM else ""))
        return st
    fields = rec.get("key_fields") if isinstance(rec.get("key_fields"), dict) else {}
    code = fields.get("code") if isinstance(fields.get("code"), dict) else {}
    if code.get("plugin") is not None:  # results/ holds the project's methods' rows only
        st.stale, st.why = True, "a plug-in's row: its source lies outside this repository, so its code cannot be held"
        return st
    mods, consts = _now(fields, root)
    if code.get("sources") == modules_digest(mods, root, consts):
        return _reference_state(st, code, trees, git, root) if references_on(fields) else st
    st.stale = True
    tree = trees.tree(st.commit) if not git.get("dirty") else None  # extracted only for a stale row
    if list(mods) != code.get("modules") or list(consts) != code.get("constants"):
        st.why = "the modules its method's code is made of changed"
    elif tree is None:
        st.why = "its code changed (its commit is not in this clone)"
    else:
        names = changed_since(mods, consts, tree, root)
        st.why, st.extra["changed"] = f"{', '.join(names) or 'its code'} changed since {str(st.commit)[:7]}", names
    return st


def _reference_state(st: RowState, code: dict, trees: CommitTrees, git: dict, root: str | None) -> RowState:
    """``st`` of a row with reference columns whose own code is current: stale when the
    code that solves its reference (:func:`eval.run.code_identity.artifact_identity`)
    changed since, with the modules named where git has its commit; a resumed run then
    solves the reference again and keeps the row when it comes out bit for bit the same
    as the one the row records (:mod:`eval.experiments.cases.reference_cutoff`)."""
    ref, now = code.get("reference") if isinstance(code.get("reference"), dict) else {}, artifact_identity(root)
    if ref.get("sources") == now["sources"]:
        return st
    st.stale = True
    tree = trees.tree(st.commit) if not git.get("dirty") else None
    names = changed_since(now["modules"], now["constants"], tree, root) if tree is not None else []
    st.extra["changed"] = names
    st.why = (f"its reference solver ({', '.join(names) or 'its code'}) changed since {str(st.commit)[:7]}: "
              "a resumed run keeps it if the reference comes out bit for bit the same")
    return st


def _valid(folder, p: Path) -> tuple[dict | None, str]:
    """A record file read as untrusted input: ``(record, "")`` when it is whole and valid
    for its store version, else ``(None, why)``."""
    if p.is_symlink() or not p.is_file():
        return None, f"invalid: {'a link' if p.is_symlink() else 'not a file'} where a record belongs"
    rec = _read_json(p)
    if not isinstance(rec, dict) or not isinstance(rec.get("method"), str) or not isinstance(rec.get("case"), str):
        return None, "invalid: not a record"
    try:
        if ResultStore(folder).path(rec["case"], rec["method"]).resolve() != p.resolve():
            return None, "invalid: it names another pair than its file"
    except SShaDeError as e:
        return None, f"invalid: {e}"
    if rec.get("version") == STORE_VERSION:
        found = ResultStore(folder).read(rec["case"], rec["method"])
        return (found.record, "") if found.record is not None else (None, found.why or "invalid")
    if rec.get("digest") != record_digest(rec):
        return None, "invalid: edited (its digest does not match)"
    if rec.get("key") != fields_digest(rec.get("key_fields")):
        return None, "invalid: its key is not its key fields' digest (edited)"
    bad = check_row(rec.get("row"), rec["case"], rec["method"])
    return (None, f"invalid: {bad}") if bad else (rec, "")


def folder_states(folder, trees: CommitTrees, root: str | None = None) -> list[RowState]:
    """The :class:`RowState` of every record of ``folder``'s store (:func:`row_state`; an
    invalid record is stale, with why), in :func:`record_paths` order; ``root``: the
    checkout whose code the rows are held to (default: this one)."""
    out = []
    for case_dir, p in record_paths(folder):
        rec, bad = _valid(folder, p)
        out.append(row_state(folder, rec, trees, root) if rec else RowState(Path(folder), case_dir, p.stem, True, bad))
    return out


def table_problems(folder) -> list[str]:
    """What a reader of ``folder``'s ``cases.csv`` would take that its records do not say,
    one line each (``[]`` when nothing): the file missing, a link or unreadable; a row
    whose record is absent, invalid or holds other numbers
    (:func:`eval.run.row_check.check_rows`); a valid record whose row the file does not list."""
    p = Path(folder) / "cases.csv"
    if p.is_symlink() or not os.path.lexists(p):
        return [f"{p}: {'a link' if p.is_symlink() else 'missing'}, where the rows of {STORE_DIR}/ belong"]
    try:
        df = read_cases(p)
    except (OSError, ValueError) as e:
        return [f"{p}: unreadable ({getattr(e, 'strerror', None) or type(e).__name__})"]
    chk = check_rows(df, folder)
    out = [f"{p}: {x}" for x in chk.problems] + [f"{p}: {x}: no record in {STORE_DIR}/" for x in chk.absent]
    if "case" in df.columns and "method" in df.columns:
        listed = set(zip(df["case"].astype(str), df["method"].astype(str)))
        for _, rp in record_paths(folder):
            rec, _ = _valid(folder, rp)
            if rec is not None and (str(rec["case"]), str(rec["method"])) not in listed:
                out.append(f"{rp}: a record whose row cases.csv does not list")
    return out


def settings_marks(states: list[RowState], marks) -> list[RowState]:
    """``states`` with each row that its code leaves current but that its table marks
    pending for other settings than its run's (``marks``: :func:`eval.run.pending_rows.marked_pending`,
    a why beginning with :data:`eval.run.result_store.OTHER_SETTINGS`; only the code is
    judged here, the settings by the run) stale again, with that why: the mark stays until
    the row is made again (by another commit)."""
    for st in states:
        why = marks.get((st.case, st.method, short_commit(st.commit))) if isinstance(marks, dict) else None
        if not st.stale and isinstance(why, str) and why.startswith(OTHER_SETTINGS):
            st.stale, st.why = True, why
    return states


def check_folders(folders, trees: CommitTrees, root: str | None = None, marked=None) -> dict[str, dict[str, dict]]:
    """``{folder: {method: {"rows": n, "stale": k, "marked": j, "why": {why: count},
    "stale_s": s, "commits": {commit[:7]}, "changed": {module}}}}`` for every record of
    every folder in ``folders`` (:func:`folder_states`; ``commits``: those that made the
    stale rows, as :func:`eval.run.pending_rows.short_commit` names them; ``changed``: the
    modules changed since, where git has those commits;
    ``stale_s``: the stored seconds of the stale rows, the time their recomputation is
    estimated at; ``marked``: of the stale rows, those its tables mark pending, as
    ``marked(folder)`` says, a set of ``(case, method, commit[:7])``; none without it);
    ``root``: the checkout whose code the rows are held to (default: this one)."""
    out: dict[str, dict[str, dict]] = {}
    for folder in folders:
        per = out.setdefault(str(folder), {})
        marks = marked(folder) if marked is not None else {}
        for st in settings_marks(folder_states(folder, trees, root), marks):
            m = per.setdefault(st.method, {"rows": 0, "stale": 0, "marked": 0, "why": {}, "stale_s": 0.0,
                                           "commits": set(), "changed": set()})
            m["rows"] += 1
            if st.stale:
                m["stale"] += 1
                m["marked"] += (st.case, st.method, short_commit(st.commit)) in marks
                m["commits"].add(short_commit(st.commit))
                m["changed"].update(st.extra.get("changed") or ())
                m["why"][st.why] = m["why"].get(st.why, 0) + 1
                m["stale_s"] += st.time_s or 0.0
    return out


def _verified(code: dict, tree: Path, by: Path | None = None) -> bool:
    """Whether a record's code identity ``code`` is that of the sources under ``tree``
    (its commit's): its modules' and constants' digest there, or, for a record re-keyed
    after a definition moved (:func:`eval.run.code_identity.modules_digest_at`), there
    with the moved modules as in this checkout or as in ``by``, the sources of the commit
    that re-keyed it (a module new since its commit: :func:`_sources_at`'s digest)."""
    mods, consts = code.get("modules") or [], code.get("constants") or ()
    for digest in (lambda: modules_digest(mods, str(tree), consts),
                   lambda: _sources_at(mods, tree, consts),
                   lambda: modules_digest_at(mods, tree, str(by), consts) if by is not None else None):
        try:
            if digest() == code.get("sources"):
                return True
        except KeyError:
            continue
    return False


@functools.lru_cache(maxsize=1)
def _head() -> str | None:
    """This checkout's commit (40 hex digits) when its packages' sources are that
    commit's, None when they have uncommitted changes (the records re-keyed then name
    their code by the commit that stores them, :func:`_rekeyed_by`) or git cannot say."""
    try:
        r = subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
                           timeout=60, check=False)
        d = subprocess.run(["git", "-C", str(REPO_ROOT), "status", "--porcelain", "--", *PACKAGES],
                           capture_output=True, text=True, timeout=60, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return r.stdout.strip() if r.returncode == 0 and d.returncode == 0 and not d.stdout.strip() else None


def _rekeyed_by(rec: dict, p: Path) -> str | None:
    """The commit whose code re-keyed record ``rec`` (file ``p``): its ``rekeyed.by``, or,
    for a record re-keyed before that was written, the last commit that changed its file."""
    by = rec["rekeyed"].get("by")
    if isinstance(by, str):
        return by
    try:
        r = subprocess.run(["git", "-C", str(REPO_ROOT), "log", "-1", "--format=%H", "--", str(Path(p).resolve())],
                           capture_output=True, text=True, timeout=60, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return r.stdout.strip() or None if r.returncode == 0 else None


def _versions(old: dict, mods) -> dict | None:
    """The numerical libraries' versions a record re-keyed for the modules ``mods`` keeps:
    those of its recorded ``versions`` that its code uses
    (:func:`eval.run.code_identity.row_libraries`), as recorded."""
    v = old.get("versions")
    if not isinstance(v, dict):
        return v
    used = row_libraries(mods)
    return {d: v.get(d) for d in used}


def _reference_tree(rec: dict, tree: Path, trees: CommitTrees) -> tuple[Path | None, str]:
    """The sources whose code solved the reference a record was scored against: its
    commit's (``tree``), or, for a row kept since because its reference came out the same
    (``reproduced``), those of the commit that kept it; ``(None, why)`` when git cannot
    give them."""
    rep = rec.get("reproduced")
    if not isinstance(rep, dict):
        return tree, ""
    if rep.get("dirty") is not False:
        return None, "its reference was solved again by a checkout with uncommitted changes"
    t = trees.tree(rep.get("commit"))
    return (t, "") if t is not None else (None, f"commit {rep.get('commit')!r} is not in this repository")


def _sources_at(mods, tree, consts) -> str:
    """:func:`eval.run.code_identity.modules_digest_at` of ``mods`` under ``tree`` (a
    commit's sources), or, when one of them is new since (missing there), a digest no
    checkout has: the code changed since, so a record keyed by it stays stale."""
    try:
        return modules_digest_at(mods, tree, None, consts)
    except KeyError as e:
        return f"a module new since its commit: {e}"


def rekey_record(folder, p: Path, trees: CommitTrees) -> str:
    """Re-key one record file ``p`` of ``folder``'s store (store version :data:`REKEY_FROM`
    or this one) under the identity rules of this checkout, in place (atomically):
    ``"rekeyed"``, ``"current"`` (its key is already what the rules give) or
    ``"refused: <why>"`` (left as it is: not valid, made by a dirty checkout, its commit
    not in git, its recorded identity not that commit's sources, a module of its reference
    solver's identity missing there). The new identity: :func:`eval.run.code_identity.code_identity`'s
    modules and constants for its method (and its reference columns where it has them)
    at this checkout, their code as at its commit (:func:`eval.run.code_identity.modules_digest_at`:
    a definition moved since counts as the same code); the numerical
    versions and plug-in digest as recorded. A record whose code changed since its
    commit (a module of this checkout's identity new since then included) is re-keyed and
    stays stale."""
    rec, bad = _valid(folder, p)
    if rec is None:
        return f"refused: {bad}"
    if rec.get("version") not in (*REKEY_FROM, STORE_VERSION):
        return f"refused: store version {rec.get('version')!r}"
    fields, git = rec.get("key_fields"), rec.get("git")
    if not isinstance(fields, dict) or not isinstance(git, dict) or not isinstance(fields.get("code"), dict):
        return "refused: no key fields or git state"
    if fields_digest(fields) != rec.get("key"):
        return "refused: its key is not its key fields' digest"
    old = fields["code"]
    if old.get("plugin") is not None:
        return "refused: a plug-in's row (its source lies outside this repository)"
    if git.get("dirty") is not False:
        return "refused: made by a checkout with uncommitted changes"
    tree = trees.tree(git.get("commit"))
    if tree is None:
        return f"refused: commit {git.get('commit')!r} is not in this repository"
    try:
        by = trees.tree(_rekeyed_by(rec, p)) if isinstance(rec.get("rekeyed"), dict) else None
        if not _verified(old, tree, by):
            return f"refused: its code identity is not that of {git['commit'][:7]}'s sources"
        mods, consts = _now(fields)
        code = {"sources": _sources_at(mods, tree, consts), "modules": list(mods),
                "constants": list(consts), "versions": _versions(old, mods), "plugin": old.get("plugin")}
        if references_on(fields):
            rtree, why = _reference_tree(rec, tree, trees)
            if rtree is None or (isinstance(old.get("reference"), dict) and not _verified(old["reference"], rtree, by)):
                return f"refused: {why or 'its reference solver identity is not that of its commit'}"
            ref = artifact_identity()
            code["reference"] = {**ref, "sources": _sources_at(ref["modules"], rtree, ref["constants"])}
    except KeyError as e:
        return f"refused: module {e} is not at {git['commit'][:7]}"
    key, new_fields = pair_key(fields.get("method"), fields.get("case"), fields.get("extra"), code)
    if rec.get("version") == STORE_VERSION and key == rec.get("key"):
        return "current"
    rec.update(version=STORE_VERSION, key=key, key_fields=new_fields,
               rekeyed={"from_version": rec.get("version"), "from_key": rec.get("key"), "commit": git["commit"],
                        "by": _head()})
    rec["digest"] = record_digest(rec)
    ResultStore(folder).rewrite(p, rec)
    return "rekeyed"



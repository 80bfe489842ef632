"""Output folders: a command writes only where it may, and never outside its folder.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

Every command of the harness that writes a folder of results (the evaluator
``python -m eval``, the sweeps ``python -m eval.sweeps``, ``python -m eval.reproduce``)
first *claims* it with :func:`claim_output_dir`, before any work. A folder may be
claimed when it is new, empty, or the same command's own earlier output (set aside until
the new run has its first result: :mod:`eval.run.earlier_output`); a run killed in it is
recovered by the next claim, which keeps what someone added since (:func:`alive`). One
evaluator run in its folder: :mod:`eval.run.run_folder`."""
from __future__ import annotations

import contextlib
import datetime as _dt
import errno
import json
import os
import socket
import sys
from dataclasses import dataclass, field
from pathlib import Path

from eval.run.earlier_output import ASIDE, clean, files_under, ours, remove_entry, restore, set_aside
from sshade.errors import SShaDeError
from sshade.json_file import read_json

__all__ = ["MARKER", "LOCK", "REPRODUCE_ENV", "OutputDirError", "OutputClaim", "claim_output_dir",
           "first_result_written",
           "results_dir", "refuse_results", "read_marker", "check_earlier_output",
           "record_output_files", "resume_command", "alive"]

MARKER = ".sshade-output.json"   #: names the kind of output a folder holds, and its files
LOCK = ".sshade-output.lock"     #: flock-ed by the process writing into the folder
REPRODUCE_ENV = "SSHADE_REPRODUCE"  #: "1" in the commands eval.reproduce runs: results/ allowed
_OWN = {MARKER, LOCK, ASIDE}
_REPO = Path(__file__).resolve().parents[2]

class OutputDirError(SShaDeError):
    """An output folder that this command may not write into."""


def results_dir() -> Path | None:
    """The ``results/`` folder of this source checkout (None for an installed copy)."""
    return _REPO / "results" if (_REPO / "pyproject.toml").is_file() else None


def refuse_results(path, what: str) -> None:
    """Raise :class:`OutputDirError` when ``path`` lies inside this checkout's
    ``results/`` and the command does not run under ``python -m eval.reproduce``
    (:data:`REPRODUCE_ENV`). ``what`` names the command for the message."""
    p = Path(os.path.abspath(Path(str(path)).expanduser()))
    res = results_dir()
    if _inside(p, res) and os.environ.get(REPRODUCE_ENV) != "1":
        raise OutputDirError(f"refusing to write into {p}: {res} holds the committed results and is written only "
                             f"by python -m eval.reproduce; {what} (e.g. under outputs/)")


def read_marker(path) -> dict | None:
    """The marker of folder ``path`` (:data:`MARKER`), or None when absent/unreadable.
    Raises OutputDirError when it names an entry or file that is not a plain path inside
    its folder (:func:`_marker_problem`): a marker is input, whoever wrote the folder."""
    try:
        m = read_json(Path(path) / MARKER)
    except (OSError, ValueError):
        return None
    if not isinstance(m, dict):
        return None
    bad = _marker_problem(m)
    if bad:
        raise OutputDirError(f"{Path(path) / MARKER}: {bad}, not a plain entry inside its folder; this marker is "
                             "not one our runs write: remove it (and the folder's .sshade-earlier) to use the folder")
    return m


def _plain(name) -> bool:
    """Whether ``name`` is a plain entry name: a non-empty string, not ``.`` or ``..``,
    without a path separator or NUL."""
    return isinstance(name, str) and name not in ("", ".", "..") and not any(c in name for c in "/\\\0")


def _marker_problem(m: dict) -> str:
    """What a marker ``m`` names that no run of ours writes there, in words (``""`` when
    nothing): its entry lists (``files``, ``foreign``, ``aside.names``) hold plain names,
    its file lists (``paths``, ``user_paths``, ``aside.user_paths``, ``own``) relative
    paths of plain names, its ``first_result`` a relative pattern of plain names, its
    ``since_ns`` an integer."""
    aside = m.get("aside") if isinstance(m.get("aside"), dict) else {}
    names = {"files": m.get("files"), "foreign": m.get("foreign"), "aside.names": aside.get("names")}
    paths = {"paths": m.get("paths"), "user_paths": m.get("user_paths"), "aside.user_paths": aside.get("user_paths"),
             "own": m.get("own")}
    for key, (v, ok) in {**{k: (v, _plain) for k, v in names.items()}, **{k: (v, _plain_path) for k, v in paths.items()}
                         }.items():
        if v is not None and not isinstance(v, list):
            return f"{key} names {v!r}"
        bad = [x for x in v or [] if not ok(x)]
        if bad:
            return f"{key} names {bad[0]!r}"
    first, since = aside.get("first_result"), aside.get("since_ns")
    if since is not None and (not isinstance(since, int) or isinstance(since, bool)):
        return f"aside.since_ns is {since!r}"
    return f"aside.first_result names {first!r}" if first is not None and not _plain_path(first) else ""


def check_earlier_output(path, kind: str, what: str) -> Path:
    """The folder ``path`` (absolute) when a command may add files to it afterwards
    (e.g. ``python -m eval.report`` its page): an earlier output of ``kind`` (its marker
    says so), or, under ``python -m eval.reproduce`` (:data:`REPRODUCE_ENV`), a folder of
    ``results/`` without a marker (written before markers existed).

    Raises
    ------
    OutputDirError: not a folder; inside ``results/`` outside ``eval.reproduce``
        (:func:`refuse_results`, ``what`` ends that message); no output of ``kind``.
    """
    p = Path(os.path.abspath(Path(str(path)).expanduser()))
    refuse_results(p, what)
    if not p.is_dir():
        raise OutputDirError(f"{p} is not a folder")
    m = read_marker(p)
    reproducing = os.environ.get(REPRODUCE_ENV) == "1" and _inside(p, results_dir())
    if not (m is not None and m.get("kind") == kind or reproducing and m is None):
        raise OutputDirError(f"refusing to write into {p}: it is not an earlier {kind} output (its {MARKER} "
                             f"{'names ' + repr(m.get('kind')) if m else 'is missing'}); name a folder that "
                             f"python -m {kind} wrote")
    return p


def record_output_files(path, names) -> None:
    """Add ``names`` (entries of folder ``path``) to its marker's ``files``, so the next
    run that replaces the folder removes them too (nothing without a marker)."""
    m = read_marker(path)
    if m is None:
        return
    m["files"] = sorted(set(m.get("files") or []) | {str(n) for n in names})
    if isinstance(m.get("paths"), list):
        m["paths"] = sorted(set(m["paths"]) | set(files_under(Path(path), [str(n) for n in names])))
    _write_marker(Path(path), m)


@dataclass
class OutputClaim:
    """A claimed output folder (:func:`claim_output_dir`); a context manager that finishes
    the claim (``done``, or ``failed`` on an exception).

    Attributes
    ----------
    path : the folder (absolute).
    kind : the kind of output (``eval``, ``sweep``).
    replaced : names of the earlier run's entries set aside for this run (removed once
        it has its first result, put back if it fails before: :mod:`eval.run.earlier_output`).
    foreign : names that were in the folder before and are not ours (kept).
    first_result : the file, or a pattern of files (``**/runs/*/*.json``), whose writing
        says this run has its first result (:func:`first_result_written`), or None: any
        entry written, or the run done.
    aside : the marker's record of the earlier output set aside, or None.
    user_paths : files under our entries that no run of ours wrote (kept, never recorded).
    kept : the files added to the earlier output, put back once this run had a result.
    continued : names of the earlier output's entries this run continues (``keep`` names
        them): never removed by this claim, not even when the run ends without a result.
    own : paths (files, or folders and all under them) that the run writes all along for
        itself (its log, its config record, ``first_result``): a killed run's even when
        changed after its last sign of life (:func:`alive`).
    message : one line saying what was claimed (new folder, replaced files, ...).
    created : the folder was created by this claim.
    parents : the folders above it that this claim created (outermost first).
    """
    path: Path
    kind: str
    replaced: list = field(default_factory=list)
    foreign: list = field(default_factory=list)
    message: str = ""
    created: bool = False
    fd: int | None = None
    parents: list = field(default_factory=list)
    first_result: str | None = None
    aside: dict | None = None
    user_paths: list = field(default_factory=list)
    kept: list = field(default_factory=list)
    continued: list = field(default_factory=list)
    own: list = field(default_factory=list)

    def finish(self, status: str, *, drop_if_unused: str | None = None, result: bool | None = None,
               **extra) -> None:
        """Record the run's end in the marker (``status`` done / failed / interrupted) with
        the entries and files this run wrote (every entry of the folder but the foreign
        ones, every file under them but the ones someone else added), and release the
        lock. A run without its first result (``drop_if_unused`` or :attr:`first_result`
        never written, e.g. a run refused for a bad config value; without either: nothing
        written and not done) has what it wrote removed and an earlier output it replaced
        put back as it was (byte for byte, marker and lock included); without an earlier
        output, the folder and the parents this claim created go too, when nothing else is
        left in them. ``result`` (True / False) says whether the run has its first result
        where the caller knows better (a sweep whose jobs all failed: their ends are its
        result). Never raises."""
        lock_bytes = None
        try:
            if self.path.is_dir():
                mark = drop_if_unused or self.first_result
                written = set(os.listdir(self.path)) - set(self.foreign) - _OWN
                if result is None:
                    since = self.aside.get("since_ns") if self.aside is not None else None
                    result = first_result_written(self.path, mark, since) if mark else bool(written)
                has_result = status == "done" or result
                if not has_result and (self.aside is not None or drop_if_unused):
                    lock_bytes = self._undo()
                    return
                if self.aside is not None:
                    self.kept = clean(self.path, self.aside)
                    self.aside = None
                    if self.kept:
                        _log_kept(self.path, self.kept)
                names = sorted(set(os.listdir(self.path)) - set(self.foreign) - _OWN)
                theirs = set(self.kept) | set(self.user_paths)
                m = read_marker(self.path) or {}
                m.pop("aside", None)
                m.update(kind=self.kind, status=status, files=names, finished=_now(),
                         paths=[r for r in files_under(self.path, names) if r not in theirs],
                         user_paths=sorted(theirs), **extra)
                _write_marker(self.path, m)
        except OSError:
            pass
        finally:
            self.release(lock_bytes)

    def __enter__(self) -> OutputClaim:
        return self

    def __exit__(self, exc_type, *exc) -> bool:
        """As a ``with`` block: :meth:`finish` with ``done``, or ``failed`` when the block
        raised (an interrupt included); the exception propagates."""
        self.finish("done" if exc_type is None else "failed")
        return False

    def _undo(self) -> bytes | None:
        """Remove what this claim wrote (every entry but the foreign ones); then put back
        the earlier output it set aside (returns that output's lock bytes), or, without
        one, remove the marker and lock when nothing else is left, the folder if this claim
        created it, and the created parents that are empty."""
        _drop_entries(self.path, set(self.foreign) | set(self.continued))
        if self.aside is not None:
            lock = restore(self.path, self.aside, MARKER)
            self.aside = None
            return lock
        if set(os.listdir(self.path)) - _OWN:
            m = read_marker(self.path) or {}
            m.update(kind=self.kind, status="failed", files=[], finished=_now())
            _write_marker(self.path, m)
            return None
        for n in _OWN:
            with contextlib.suppress(OSError):
                (self.path / n).unlink()
        for d in ([self.path] if self.created else []) + list(reversed(self.parents)):
            with contextlib.suppress(OSError):
                d.rmdir()  # only when empty
        return None

    def release(self, content: bytes | None = None) -> None:
        """Release the folder's lock (also released when the process ends), its file left
        holding ``content`` when given (an earlier output's, put back)."""
        if self.fd is not None:
            with contextlib.suppress(OSError):
                if content is not None:
                    os.ftruncate(self.fd, 0)
                    os.pwrite(self.fd, content, 0)
                os.close(self.fd)
            self.fd = None


def _log_kept(path: Path, kept: list) -> None:
    import logging
    logging.getLogger("eval").info("kept %d file(s) you added to the earlier output in %s: %s%s", len(kept), path,
                                   ", ".join(kept[:8]), " ..." if len(kept) > 8 else "")


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _write_marker(path: Path, m: dict) -> None:
    tmp = path / f".{MARKER}.{os.getpid()}.tmp"
    tmp.write_text(json.dumps(m, indent=1) + "\n")
    os.replace(tmp, path / MARKER)


def _inside(p: Path, root: Path | None) -> bool:
    if root is None:
        return False
    try:
        p.relative_to(root.resolve())
        return True
    except ValueError:
        return False


def _how(kind: str) -> str:
    return "--force" if kind == "deform" else "overwrite=true"


def _mkdir_fresh(path: Path) -> Path:
    """Create ``path``, or ``path_2``, ``path_3``, ... when it exists (atomic: two
    processes never get the same folder)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    for i in range(1, 10000):
        p = path if i == 1 else path.with_name(f"{path.name}_{i}")
        try:
            os.mkdir(p)
            return p
        except FileExistsError:
            continue
    raise OutputDirError(f"cannot create a new folder next to {path}: 10000 names taken")


def _lock(path: Path) -> int:
    """Take the folder's lock or refuse: another live process writes into it."""
    import fcntl
    fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as e:
        other = (os.pread(fd, 200, 0) or b"").decode(errors="replace").strip()
        os.close(fd)
        if e.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK):
            raise OutputDirError(f"another run is writing into {path} ({other or 'a live process'}); "
                                 "wait for it to end or choose another folder") from None
        raise
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}".encode(), 0)
    return fd


def _drop_entries(p: Path, foreign: set) -> None:
    """Remove every entry of folder ``p`` but the ``foreign`` ones and the bookkeeping."""
    for n in sorted(set(os.listdir(p)) - foreign - _OWN):
        with contextlib.suppress(OSError):
            remove_entry(p / n)


def _recover(p: Path, m: dict | None, alive_ns: int | None) -> tuple[dict | None, list[str]]:
    """``(marker, left)``: the marker of ``p`` (locked by this process) once a run that
    died there without finishing (its marker still ``running``) is accounted for: an
    earlier output it had set aside is put back when that run had no first result yet
    (over the entries of the same names; any other entry, which the dead run or someone
    after it made, stays and is ``left``, to be named as kept), else cleaned
    (:mod:`eval.run.earlier_output`); the dead run's entries (all but the foreign ones it
    recorded) become its ``files``, so the next replacement removes them, all but the
    files changed after its last sign of life ``alive_ns`` (the lock's mtime, ns;
    :func:`alive`) and not its :attr:`OutputClaim.own`: someone added those after it
    died (or it wrote them after its last record): they are ``left``, its ``user_paths``."""
    if m is None or m.get("status") != "running":
        return m, []
    foreign = set(m.get("foreign") or [])
    rec = m.get("aside")
    kept: list = []
    if isinstance(rec, dict) and (p / ASIDE).is_dir():
        mark = rec.get("first_result")
        if mark and not first_result_written(p, str(mark), rec.get("since_ns")):  # died before its first result
            left = sorted(set(os.listdir(p)) - foreign - _OWN - {ASIDE} - set(rec.get("names") or []))
            restore(p, rec, MARKER)
            return read_marker(p), left
        kept = clean(p, rec)
    names = sorted(set(os.listdir(p)) - foreign - _OWN)
    late = _changed_after(p, names, alive_ns, m.get("own") or [])
    m.pop("aside", None)
    m.pop("paths", None)  # a record of a run it continued: the dead run's own files are not in it
    m.update(status="killed", files=names, user_paths=sorted(set(m.get("user_paths") or []) | set(kept) | set(late)))
    _write_marker(p, m)
    return m, sorted(set(late) - set(kept))


def first_result_written(p: Path, pattern: str, since_ns: int | None) -> bool:
    """Whether a run writing folder ``p`` has its first result: a file below ``p`` (not a
    link, resolved inside ``p``, under no hidden folder such as the aside) matching the
    relative glob ``pattern`` (a name such as ``run.json``, or ``**/runs/*/*.json``) and,
    with ``since_ns`` (ns, the file system's clock: the time the earlier output was set
    aside, :func:`eval.run.earlier_output.set_aside`, or a claim's), modified since then,
    so that the files of the entries a run continues (a resumed sweep's jobs) count only
    once it rewrote them. Never raises."""
    try:
        root = p.resolve()
        for f in p.glob(pattern):
            with contextlib.suppress(OSError):
                rel = f.relative_to(p).parts
                if (not any(n.startswith(".") for n in rel[:-1]) and not f.is_symlink() and f.is_file()
                        and f.resolve().is_relative_to(root)
                        and (since_ns is None or f.stat().st_mtime_ns >= since_ns)):
                    return True
    except (OSError, ValueError):  # an unreadable folder, an empty or absolute pattern
        pass
    return False


def _changed_after(p: Path, names: list, alive_ns: int | None, own: list) -> list[str]:
    """The files under the entries ``names`` of ``p`` (:func:`eval.run.earlier_output.files_under`)
    whose status changed after ``alive_ns`` (ctime, which no copy or touch sets back),
    but those under ``own``; none when ``alive_ns`` is None (no sign of life known)."""
    if alive_ns is None:
        return []
    out = []
    for rel in files_under(p, names):
        if any(rel == o or rel.startswith(o.rstrip("/") + "/") for o in own):
            continue
        with contextlib.suppress(OSError):
            if os.lstat(p / rel).st_ctime_ns > alive_ns:
                out.append(rel)
    return out


def _plain_path(rel) -> bool:
    """``rel`` a relative path of plain names, inside its folder."""
    return isinstance(rel, str) and bool(rel) and not rel.startswith("/") and all(_plain(n) for n in rel.split("/"))


def alive(folder) -> None:
    """Sign of life of the run writing ``folder`` (its lock's mtime set to now): a file
    changed there later, should the run be killed, was not its own (:func:`_recover`).
    Called once a file the run wrote is in place (a stored record); nothing when the
    folder holds no lock file of its own. Never raises."""
    q = Path(folder) / LOCK
    with contextlib.suppress(OSError):
        if q.is_file() and not q.is_symlink():
            os.utime(q)


def claim_output_dir(path, kind: str, *, overwrite: bool = False, fresh: bool = False,
                     keep=False, option: str | None = None, name: str = "out_dir",
                     first_result: str | None = None, own=()) -> OutputClaim:
    """Claim folder ``path`` for an output of ``kind`` (module docstring), before any work.

    Parameters
    ----------
    path : str or Path, the folder (relative paths against the current directory).
    kind : str, the kind of output (``eval``: one evaluator run; ``sweep``: a sweep folder).
    overwrite : bool, write into a non-empty folder that is not ours (the user asked).
    fresh : bool, ``path`` is a default name: never reuse it, add ``_2``, ``_3``, ... instead.
    keep : bool, or a collection of top-level entry names: true, an own earlier output is
        continued, not replaced (a sweep's resume); names, those entries of an own earlier
        output are continued and its other entries replaced (set aside as without
        ``keep``: a sweep run again with ``resume=true`` keeps the folders of its jobs).
    option : str, how the user says ``overwrite`` on this command (for the message; ""
        when the command has no such option).
    name : str, how the user names the folder on this command (for the message).
    first_result : str or None, the file (e.g. ``run.json``) or the relative glob of files
        (a sweep's ``**/runs/*/*.json``) whose writing says the run has its first result
        (a match modified since the claim set the earlier output aside): an earlier output
        replaced is set aside until then and put back if the run ends before
        (:meth:`OutputClaim.finish`), or is killed before (the next claim); None: any entry
        written.
    own : relative paths the run writes all along for itself (:attr:`OutputClaim.own`;
        ``first_result`` is one).

    Returns
    -------
    OutputClaim; the folder exists, is writable, holds the marker (status ``running``)
    and this process holds its lock until it exits.

    Raises
    ------
    OutputDirError
        ``path`` is a file; inside this checkout's ``results/`` without
        :data:`REPRODUCE_ENV`; not writable; another live run writes into it; a non-empty
        folder that is not this command's earlier output of the same kind (unless
        ``overwrite``); a non-empty folder holding a symbolic link anywhere inside (a
        write or a removal through it would reach outside).
    """
    how = _how(kind) if option is None else option
    raw = str(path).strip()
    if not raw:
        raise OutputDirError(f"the output folder is empty: name a new folder ({name}=DIR)")
    p = Path(os.path.abspath(Path(raw).expanduser()))
    refuse_results(p, "choose a folder outside it")
    if p.exists() and not p.is_dir():
        raise OutputDirError(f"output folder {p} is a file; choose a folder")
    made = [a for a in reversed(p.parents) if not a.exists()]  # created below; removed by a run refused early
    try:
        claim = _claim(p, kind, overwrite, fresh, keep, how, first_result,
                       sorted({*map(str, own), *([first_result] if first_result and _plain(first_result) else [])}))
    except OSError as e:
        raise OutputDirError(f"cannot create or use output folder {p}: {e.strerror or e}") from None
    claim.parents = made
    return claim


def _claim(p: Path, kind: str, overwrite: bool, fresh: bool, keep, how: str,
           first_result: str | None, own: list) -> OutputClaim:
    """:func:`claim_output_dir` once ``p`` is checked: create or take the folder."""
    if fresh:
        p = _mkdir_fresh(p)
        return _take(p, kind, [], [], f"writing into the new folder {p}", created=True, first_result=first_result,
                     own=own)
    created = False
    if not p.exists():
        p.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.mkdir(p)
            created = True
        except FileExistsError:
            pass
    if not os.access(p, os.W_OK | os.X_OK):
        raise OutputDirError(f"output folder {p} is not writable; choose another folder")
    return _claim_existing(p, kind, created, overwrite, keep, how, first_result, own)


def _links_inside(p: Path) -> list[str]:
    """Entries under folder ``p`` (walked without following links) that are symbolic
    links resolving outside ``p`` (dangling ones by where they point), as paths relative
    to ``p``. Links that stay inside (e.g. submitit's ``.submitit/`` bookkeeping) are
    harmless: a write or removal through them stays in the folder."""
    root = os.path.realpath(p)
    out = []
    for top, dirs, files in os.walk(p, followlinks=False):
        for n in dirs + files:
            q = os.path.join(top, n)
            if os.path.islink(q) and os.path.commonpath([root, os.path.realpath(q)]) != root:
                out.append(os.path.relpath(q, p))
    return sorted(out)


def _claim_existing(p: Path, kind: str, created: bool, overwrite: bool, keep, how: str,
                    first_result: str | None, own: list) -> OutputClaim:
    names = sorted(set(os.listdir(p)) - _OWN)
    if created or not names and not (p / ASIDE).exists():
        return _take(p, kind, [], [], f"writing into the {'new' if created else 'empty'} folder {p}", created=created,
                     first_result=first_result, own=own)
    links = _links_inside(p)
    if links:  # a write or a removal through one would reach outside the folder
        raise OutputDirError(f"refusing to write into {p}: {links[0]} is a symbolic link out of it (to "
                             f"{os.readlink(p / links[0])}){f' and {len(links) - 1} more' if len(links) > 1 else ''}; "
                             "an output folder must hold no links out: remove them or choose a new folder")
    m = read_marker(p)
    reproducing = os.environ.get(REPRODUCE_ENV) == "1" and _inside(p, results_dir())
    if m is not None and m.get("kind") == kind or reproducing and m is None:
        plain_lock = (p / LOCK).is_file() and not (p / LOCK).is_symlink()
        lock_before = (p / LOCK).read_bytes() if plain_lock else None
        alive_ns = os.lstat(p / LOCK).st_mtime_ns if plain_lock else None  # before _lock writes it
        fd = _lock(p)  # refuse while another run writes here, before moving anything
        m, left = _recover(p, m, alive_ns)
        left = (f" (kept {len(left)} that a killed run left or someone added: {', '.join(left[:8])}"
                f"{' ...' if len(left) > 8 else ''})" if left else "")
        wrote = ours(m)
        if keep is True:
            user = [r for r in files_under(p, (m or {}).get("files") or []) if not wrote(r)]
            return _take(p, kind, [], [], f"continuing the earlier {kind} output in {p}{left}", fd=fd,
                         first_result=first_result, user_paths=user, own=own)
        if os.path.lexists(p / ASIDE):  # no run of ours left it there without a record
            OutputClaim(path=p, kind=kind, replaced=[], foreign=[], message="", fd=fd).release(lock_before)
            raise OutputDirError(f"refusing to write into {p}: it holds {ASIDE}, which no run recorded setting aside "
                                 f"(made by hand, or by a copy of the folder); move it out of {p} or remove it")
        earlier = [str(n) for n in (m or {}).get("files") or [] if str(n) not in _OWN]
        kept = sorted({str(n) for n in keep or ()} & set(earlier))  # only entries the earlier output wrote
        rec = set_aside(p, [n for n in earlier if n not in kept], p / MARKER, lock_before, m)
        gone = rec["names"]
        rest = sorted(set(os.listdir(p)) - _OWN - set(kept))
        msg = (f"{'continuing' if kept else 'replacing'} the earlier {kind} output in {p}" +
               (f" (kept {len(kept)}: {', '.join(kept[:8])}{' ...' if len(kept) > 8 else ''})" if kept else "") +
               (f" (set aside {len(gone)}: {', '.join(gone[:8])}{' ...' if len(gone) > 8 else ''}; removed once this "
                "run has its first result, put back if it ends before)" if gone else "") +
               left)
        user = [r for r in files_under(p, kept) if not wrote(r)]
        return _take(p, kind, gone, rest, msg, fd=fd, first_result=first_result, aside=rec, user_paths=user,
                     continued=kept, own=own)
    if not overwrite:
        what = (f"another kind of output ({m.get('kind')})" if m else
                f"{len(names)} {'entry' if len(names) == 1 else 'entries'} that no earlier {kind} run wrote "
                f"({', '.join(names[:4])}"
                f"{' ...' if len(names) > 4 else ''})")
        alt = f", or pass {how} to write into it anyway (files of the same name are replaced)" if how else ""
        raise OutputDirError(f"refusing to write into {p}: it holds {what}. Choose a new or empty folder{alt}")
    return _take(p, kind, [], names, f"writing into {p} ({how}: {len(names)} entries there kept unless "
                                      "replaced by files of the same name)", own=own)


def _command() -> list[str]:
    """The command line, ``python -m pkg`` for a package's ``__main__.py``."""
    prog = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path("python")
    if prog.suffix == ".py" and (prog.parent / "__init__.py").is_file():
        mod = prog.parent.name if prog.name == "__main__.py" else f"{prog.parent.name}.{prog.stem}"
        return ["python", "-m", mod, *sys.argv[1:]]
    return [prog.name, *sys.argv[1:]]


def resume_command(out_dir) -> str:
    """The command line that continues this evaluator run in ``out_dir`` (its stored
    pairs kept, :mod:`eval.run.result_store`): ``python -m eval`` with the run's own overrides
    (Hydra's, else the command line's) and ``resume=true out_dir=<out_dir>`` in place of
    any ``resume`` or ``out_dir`` given, quoted for a POSIX shell. Running the command
    again without ``resume=true`` would clear the stored pairs."""
    import re
    import shlex
    args = None
    try:
        from hydra.core.hydra_config import HydraConfig
        if HydraConfig.initialized():
            args = [str(o) for o in HydraConfig.get().overrides.task]
    except (ImportError, ValueError):  # pragma: no cover -- hydra-core is a dependency
        pass
    if args is None:
        cmd = _command()
        args = [a for a in cmd[3 if cmd[1:2] == ["-m"] else 1:] if a not in ("-m", "--multirun")]
    keep = [a for a in args if not re.match(r"^[+~]*(resume|out_dir)(=|$)", a)]
    return shlex.join(["python", "-m", "eval", *keep, "resume=true", f"out_dir={os.path.abspath(str(out_dir))}"])


def _take(p: Path, kind: str, gone: list, foreign: list, message: str, *, fd: int | None = None,
          created: bool = False, first_result: str | None = None, aside: dict | None = None,
          user_paths: list | None = None, continued: list | None = None, own: list | None = None) -> OutputClaim:
    fd = _lock(p) if fd is None else fd
    old = read_marker(p) or {}
    m = {"kind": kind, "status": "running", "pid": os.getpid(), "host": socket.gethostname(), "started": _now(),
         "command": _command(),
         "files": [f for f in old.get("files", []) if f not in gone and (p / f).exists()],
         "foreign": list(foreign), "user_paths": list(user_paths or []), "own": list(own or [])}
    if isinstance(old.get("paths"), list) and aside is None:  # continued: its record of files stands
        m["paths"] = old["paths"]
    if aside is not None:
        m["aside"] = {**aside, "first_result": first_result}
    _write_marker(p, m)
    return OutputClaim(path=p, kind=kind, replaced=gone, foreign=foreign, message=message, created=created, fd=fd,
                       first_result=first_result, aside=aside, user_paths=list(user_paths or []),
                       continued=list(continued or []), own=list(own or []))

"""An earlier output replaced without loss: set aside until the run replacing it has its
first result, then cleaned file by file (only the files that earlier run wrote), else put
back as it was. Floor 0 of eval/ (eval/run/); used by :mod:`eval.run.outdir`.

* :func:`set_aside`: an earlier output's entries moved into ``ASIDE`` (one rename each),
  with its marker's and lock's bytes, before the new run writes anything;
* :func:`restore`: the aside put back (the new run failed before its first result);
* :func:`clean`: the aside removed, the files someone added to the earlier output moved
  back to their place (the new run has its first result);
* :func:`files_under`, :func:`ours`: the files of a folder, and which an output wrote.
The marker's ``aside`` entry records what was set aside, so that a run killed with the
earlier output aside is recovered by the next claim (:func:`eval.run.outdir.claim_output_dir`).
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

__all__ = ["ASIDE", "files_under", "ours", "set_aside", "restore", "clean", "remove_entry"]

ASIDE = ".sshade-earlier"  #: the folder an earlier output waits in while a new run replaces it
_MARKER_COPY, _LOCK_COPY = ".marker", ".lock"  # the earlier marker's and lock's bytes, inside ASIDE


def files_under(path: Path, names) -> list[str]:
    """Relative POSIX paths of the files and links under the entries ``names`` of folder
    ``path`` (an entry that is a file or a link is its own path), walked without following
    links; sorted."""
    out = []
    for n in names:
        q = path / n
        if q.is_symlink() or not q.is_dir():
            if os.path.lexists(q):
                out.append(n)
            continue
        for top, dirs, files in os.walk(q, followlinks=False):
            rel = Path(top).relative_to(path).as_posix()
            out += [f"{rel}/{f}" for f in files]
            out += [f"{rel}/{d}" for d in dirs if os.path.islink(os.path.join(top, d))]
    return sorted(out)


def ours(marker: dict | None):
    """Predicate on a relative path: did the output of ``marker`` write it? Its ``paths``
    when it has them; else every path but its ``user_paths`` (a run killed before its
    end, or one older than file-level records: then every path)."""
    m = marker or {}
    if isinstance(m.get("paths"), list):
        written = {str(p) for p in m["paths"]}
        return written.__contains__
    user = {str(p) for p in m.get("user_paths") or []}
    return lambda rel: rel not in user


def set_aside(path: Path, names, marker_file: Path, lock_bytes: bytes | None, earlier: dict | None) -> dict:
    """Move the entries ``names`` of folder ``path`` (an earlier output's own, top level)
    into ``path/ASIDE``, with a copy of the bytes of ``marker_file`` and the earlier lock's
    ``lock_bytes`` (None: it had no lock file).

    Returns
    -------
    dict, the marker's ``aside`` record: ``names`` (moved), ``user_paths`` (the files
    under them that the earlier output did not write, :func:`ours` of ``earlier``),
    ``since_ns`` (``ASIDE``'s modification time once filled, ns, by the file system's own
    clock: a file the new run writes afterwards is at least as new).
    """
    a = path / ASIDE
    a.mkdir()
    if marker_file.is_file() and not marker_file.is_symlink():
        shutil.copyfile(marker_file, a / _MARKER_COPY)
    if lock_bytes is not None:
        (a / _LOCK_COPY).write_bytes(lock_bytes)
    moved = []
    for n in names:
        n = str(n)
        if not n or "/" in n or n in (".", "..", _MARKER_COPY, _LOCK_COPY) or not os.path.lexists(path / n):
            continue
        os.rename(path / n, a / n)
        moved.append(n)
    wrote = ours(earlier)
    return {"names": moved, "user_paths": [r for r in files_under(a, moved) if not wrote(r)],
            "since_ns": os.stat(a).st_mtime_ns}


def restore(path: Path, record: dict, marker_name: str) -> bytes | None:
    """Put the aside of ``record`` back into ``path`` (whatever the new run left under the
    same names is removed first) and the earlier marker's bytes as ``marker_name``;
    remove ``ASIDE``. Returns the earlier lock's bytes (None if it had none)."""
    a = path / ASIDE
    for n in record.get("names") or []:
        src, dst = a / n, path / n
        if not os.path.lexists(src):
            continue
        remove_entry(dst)
        os.rename(src, dst)
    if (a / _MARKER_COPY).is_file():
        os.replace(a / _MARKER_COPY, path / marker_name)
    lock = (a / _LOCK_COPY).read_bytes() if (a / _LOCK_COPY).is_file() else None
    shutil.rmtree(a, ignore_errors=True)
    return lock


def clean(path: Path, record: dict) -> list[str]:
    """The new run in ``path`` has its first result: the files someone added to the
    earlier output (``record["user_paths"]``) go back to their place (as ``NAME.kept``,
    ``NAME.kept2``, ... where the new run wrote that path, or where a file of the new run
    stands in for a folder of the path), the rest of ``ASIDE`` is removed.
    Returns the kept files' new relative paths."""
    a, kept = path / ASIDE, []
    for rel in record.get("user_paths") or []:
        src = a / rel
        if not os.path.lexists(src):
            continue
        dst = _free(path, rel)
        dst.parent.mkdir(parents=True, exist_ok=True)
        os.rename(src, dst)
        kept.append(dst.relative_to(path).as_posix())
    shutil.rmtree(a, ignore_errors=True)
    return kept


def _free(path: Path, rel: str) -> Path:
    """``path/rel``, or beside it with ``.kept``, ``.kept2``, ... when that name is taken;
    a parent that is not a folder (the new run wrote a file there) sends it to the top
    level with its path flattened."""
    dst = path / rel
    parent_ok = all(not os.path.lexists(p) or (p.is_dir() and not p.is_symlink())
                    for p in [path / q for q in Path(rel).parents if str(q) != "."])
    if not parent_ok:
        dst = path / rel.replace("/", "__")
    base, i = dst, 1
    while os.path.lexists(dst):
        dst = base.with_name(base.name + (".kept" if i == 1 else f".kept{i}"))
        i += 1
    return dst


def remove_entry(p: Path) -> None:
    """Remove ``p``: a folder with what it holds, a file or a link (never what it points
    to); nothing when it does not exist."""
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    elif os.path.lexists(p):
        p.unlink()

"""Files written and paths trusted by every layer, below every mesh and method module:
:func:`atomic_write` (a file is whole or absent, never half-written) and
:func:`inside_folder` (a path checked to lie inside its folder, no link on the way).

Writing a file imports no mesh reader: the record writers, the caches, the DeFAUST store
and the commands take these from here (a row's code identity then holds no reader,
docs/implementation.md); the bounded JSON reader is :mod:`sshade.json_file`.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from .errors import SShaDeError

__all__ = ["atomic_write", "inside_folder"]


@contextlib.contextmanager
def atomic_write(path, mode: str = "w", **kw):
    """Open a temporary file beside ``path`` and rename it onto ``path`` on success.

    Nothing half-written is ever left at ``path``: on an exception the temporary file is
    removed and ``path`` keeps its previous content (or stays absent).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "x.txt"
    >>> with atomic_write(p) as fh:
    ...     _ = fh.write("hello")
    >>> p.read_text()
    'hello'
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **kw) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def inside_folder(root, path, what: str = "path") -> Path:
    """``path`` checked to lie inside the folder ``root`` with no link on the way.

    Every component of ``path`` below ``root`` that exists must be a real file or folder
    (not a symbolic link), so that writing or reading ``path`` stays inside ``root``
    whatever was placed there. ``root`` itself may be a link (the user chose it).

    Parameters
    ----------
    root : str or Path, the folder. path : str or Path, absolute or relative to ``root``.
    what : str, what the path is, for the message.

    Returns
    -------
    Path, ``path`` under ``root``'s resolved location (not resolved further).

    Raises
    ------
    SShaDeError naming the link (or the path, when it leaves ``root`` through ``..``).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> inside_folder(d, "runs/a.json") == d.resolve() / "runs" / "a.json"
    True
    """
    base = Path(root).resolve()
    p = Path(path)
    if p.is_absolute():
        rel = [p.relative_to(r) for r in (Path(root), base) if p.is_relative_to(r)]
        if not rel:
            raise SShaDeError(f"{what} {path} is not inside {root}")
        p = rel[0]
    if any(part in ("..", "") for part in p.parts):
        raise SShaDeError(f"{what} {path} leaves {root} (it has '..')")
    q = base
    for part in p.parts:
        q = q / part
        if q.is_symlink():
            raise SShaDeError(f"{what}: {q} is a link (to {os.readlink(q)}); links inside {base} are refused: "
                              "replace it by a real folder or file")
    return q

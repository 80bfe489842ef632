"""Files read as untrusted input: a regular file only (a FIFO, a device or a folder is
refused without blocking), its size bounded by the bytes read rather than by what ``stat``
says, JSON nesting bounded.

* :func:`read_bounded`: the bytes of a regular file of at most ``max_bytes``;
* :func:`open_regular`, :func:`read_prefix`: a regular file opened without blocking, and
  its first ``n`` bytes (a header, a generator tag);
* :func:`loads`: :func:`json.loads` whose too-deep nesting is a ``ValueError``;
* :func:`read_json`: both, for a JSON file (``MAX_JSON_BYTES`` by default);
* :func:`regular_file`: a path checked to name a regular file before a reader opens it.
Callers catch ``OSError`` (unreadable, not a regular file, too large) and ``ValueError``
(not UTF-8, not JSON, nested too deeply) as they did for ``Path.read_text`` and ``json.loads``.
"""
from __future__ import annotations

import contextlib
import errno
import json
import os
import stat
from pathlib import Path

from .errors import SShaDeError

__all__ = ["MAX_JSON_BYTES", "read_bounded", "open_regular", "read_prefix", "loads", "read_json", "regular_file"]

MAX_JSON_BYTES = 256 * 2**20  #: a JSON file larger than this is refused (bytes)


def read_bounded(path, max_bytes: int) -> bytes:
    """The bytes of the regular file ``path`` (links followed).

    Parameters
    ----------
    path : str or Path. max_bytes : int >= 0, the most bytes accepted.

    Returns
    -------
    bytes, at most ``max_bytes`` of them.

    Raises
    ------
    OSError: unreadable; not a regular file (``EINVAL``: a FIFO, a device, a folder;
        opened without blocking); more than ``max_bytes`` bytes read (``EFBIG``), whatever
        its size on disk says.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        if st.st_size > max_bytes:  # refused before a byte is read (a sparse file included)
            raise OSError(errno.EFBIG, f"larger than {max_bytes} bytes", str(path))
        chunks, n = [], 0
        while True:
            b = os.read(fd, min(1 << 20, max_bytes + 1 - n))
            if not b:
                return b"".join(chunks)
            chunks.append(b)
            n += len(b)
            if n > max_bytes:
                raise OSError(errno.EFBIG, f"larger than {max_bytes} bytes", str(path))
    finally:
        os.close(fd)


@contextlib.contextmanager
def open_regular(path):
    """The regular file ``path`` (links followed) opened for binary reading, without
    blocking: a context manager giving the file object, closed on exit.

    Raises
    ------
    OSError: unreadable, absent (``FileNotFoundError``), or not a regular file
        (``EINVAL``: a FIFO, a device, a folder), before a byte is read.
    """
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        fh = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with fh:
        yield fh


def read_prefix(path, n: int) -> bytes:
    """The first ``n`` (>= 0) bytes of the regular file ``path`` (fewer when it is
    shorter), read through :func:`open_regular`; OSError as it raises."""
    with open_regular(path) as fh:
        return fh.read(n)


def _kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words, when it is no regular file."""
    for test, word in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return word
    return "not a regular file"


def regular_file(path, what: str = "file"):
    """``path`` (a :class:`pathlib.Path`) when it names a regular file (a link to one
    included), checked before a reader opens it: a FIFO would block the reader, a folder
    or a device (``/dev/zero``) has no end it could trust. ``what``: the kind of file, for
    the message. Raises :class:`sshade.errors.SShaDeError` naming ``path``: not found,
    unreadable, or what it is instead."""
    p = Path(path)
    try:
        mode = os.stat(p).st_mode
    except FileNotFoundError:
        raise SShaDeError(f"{what} not found: {p}") from None
    except OSError as e:
        raise SShaDeError(f"{p}: cannot read it ({e.strerror or type(e).__name__})") from None
    if not stat.S_ISREG(mode):
        raise SShaDeError(f"{p}: {_kind(mode)}, not a {what} (a regular file)")
    return p


def loads(text):
    """:func:`json.loads` of ``text`` (str or bytes); ValueError (``json.JSONDecodeError``
    or nesting deeper than the interpreter's recursion allows) when it is no JSON.

    >>> loads("[1, {}]"), loads("[" * 100_000) if False else None
    ([1, {}], None)
    """
    try:
        return json.loads(text)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None


def read_json(path, max_bytes: int = MAX_JSON_BYTES):
    """The JSON value in the file ``path`` (UTF-8, a BOM allowed): :func:`read_bounded`
    then :func:`loads`. Raises OSError or ValueError as they do (``UnicodeDecodeError``
    is a ValueError)."""
    return loads(read_bounded(path, max_bytes).decode("utf-8-sig"))

"""What the mesh format readers share: the rows of a text mesh file parsed into arrays, and
the errors that name a bad file, line or byte.

* :func:`text_lines`, :func:`text_chunks`, :func:`without_bom`: a file's text cut into
  lines (``#`` comments removed) and into chunks of about :data:`TEXT_CHUNK` bytes;
* :func:`number_table` (vectorised, None when a line does not fit) and :func:`float_rows`
  (per line, naming the first bad one): numbers, correctly rounded;
* :func:`unreadable`, :func:`show_tokens`, :func:`short_error`: the SShaDeError of a bad
  file and the pieces of its message; :func:`refuse_nul`, :func:`text_prefix`: a text
  format's check of a file's first bytes (:func:`sshade.mesh.io.read_mesh`).
Used by :mod:`~sshade.mesh.obj`, :mod:`~sshade.mesh.off`, :mod:`~sshade.mesh.ply`, :mod:`~sshade.mesh.stl`.
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import SShaDeError

__all__ = ["TEXT_CHUNK", "unreadable", "short_error", "show_tokens", "float_rows", "number_table", "text_lines",
           "text_chunks", "without_bom", "refuse_nul", "text_prefix"]

#: bytes of a text mesh file parsed at once: the parse's memory is this chunk's, not the file's
TEXT_CHUNK = 1 << 20


def unreadable(p: Path, what: str) -> SShaDeError:
    """The error for the file ``p`` (its format named by its extension) that is bad for ``what``."""
    return SShaDeError(f"{p}: unreadable {p.suffix[1:].upper()} file ({what})")


def short_error(e: BaseException) -> str:
    """One short line describing an exception."""
    s = " ".join(str(e).split())
    return (s[:120] + "...") if len(s) > 120 else (s or type(e).__name__)


def show_tokens(toks) -> str:
    """The tokens (bytes) of a line as an ASCII text of at most 60 bytes for a message."""
    return repr(b" ".join(toks)[:60])[1:]  # ASCII only: raw bytes never reach the terminal


def float_rows(rows, p: Path, what: str) -> np.ndarray:
    """(k, 3) float64 from the first three tokens of each row ``(line, tokens)``
    (correctly rounded: Python's float); an SShaDeError names the first bad line."""
    try:
        return np.array([(float(t[0]), float(t[1]), float(t[2])) for _, t in rows], np.float64).reshape(-1, 3)
    except (ValueError, IndexError):
        for i, t in rows:
            try:
                float(t[0]), float(t[1]), float(t[2])
            except (ValueError, IndexError):
                raise SShaDeError(f"{p}: line {i}: {what} {show_tokens(t)} is not three numbers") from None
        raise


_WS = np.zeros(256, bool)
_WS[[9, 10, 11, 12, 13, 32]] = True


def number_table(lines: list, ncols: int, dtype):
    """(k, ncols) array of the numbers on ``lines`` (bytes, one row each), vectorised;
    None when some line does not hold exactly ``ncols`` numbers (the caller's per-line
    path then names the problem). Floats are correctly rounded (bit-exact round trip)."""
    if not lines:
        return np.zeros((0, ncols), dtype)
    blob = b"\n".join(lines)
    a = np.frombuffer(blob, np.uint8)
    sp = _WS[a]
    start = ~sp
    start[1:] &= sp[:-1]
    counts = np.bincount(np.cumsum(a == 10)[start], minlength=len(lines))
    if len(counts) != len(lines) or (counts != ncols).any():
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            vals = np.fromstring(blob, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    return vals.reshape(-1, ncols) if vals.size == len(lines) * ncols else None


def text_lines(data: bytes) -> list:
    """Lines of a text file, ``#`` comments removed."""
    lines = data.splitlines()
    if b"#" in data:
        lines = [ln.split(b"#", 1)[0] if b"#" in ln else ln for ln in lines]
    return lines


def text_chunks(data: bytes, size: int = TEXT_CHUNK):
    """``data`` in pieces of about ``size`` bytes, each ending at a line break (``\n``)
    or at the end: yields the pieces in order."""
    start, n = 0, len(data)
    while start < n:
        end = data.find(b"\n", min(start + size, n) - 1)
        end = n if end < 0 else end + 1
        yield data[start:end]
        start = end


def without_bom(data: bytes) -> bytes:
    """``data`` without a leading UTF-8 byte-order mark (editors on Windows write one)."""
    return data[3:] if data.startswith(b"\xef\xbb\xbf") else data


def refuse_nul(text: bytes, p: Path) -> None:
    """Refuse the file ``p`` whose bytes ``text``, meant to be text, hold a NUL byte (a
    sparse or binary file named so)."""
    i = text.find(b"\0")
    if i >= 0:
        raise unreadable(p, f"byte {i}: a NUL byte, so no {p.suffix[1:].upper()} text (a binary or empty file "
                            "named so?)")


def text_prefix(head: bytes, size: int, p: Path) -> None:
    """The check of a text format's first bytes ``head`` (``size``: the file's size in
    bytes, unused): :func:`refuse_nul`."""
    refuse_nul(head, p)

"""Object File Format (OFF): the reader (bytes -> (V, F)) and the writer ((V, F) -> bytes).

:func:`read_off` reads OFF and its COFF/NOFF/CNOFF variants (extra values per line
ignored; ST, 4 and nD variants refused), the counts line on the ``OFF`` line or the next,
and checks the header's counts against the lines present before anything is allocated.
:func:`off_bytes` writes ``OFF``, a comment, the counts, vertices with 17 significant
digits and ``3 a b c`` faces. Format reference: the Geomview manual, "OFF Files"
(http://www.geomview.org/docs/html/OFF.html). :data:`READERS`, :data:`PREFIX_CHECKS` and
:data:`WRITERS`, :data:`SIGNED` are this format's entries in :mod:`sshade.mesh.io`'s dispatch.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import SShaDeError
from .text_rows import float_rows, number_table, show_tokens, text_lines, text_prefix, unreadable, without_bom

__all__ = ["read_off", "off_bytes", "off_signed", "READERS", "PREFIX_CHECKS", "WRITERS", "SIGNED"]


def read_off(data: bytes, p: Path):
    """OFF (also COFF/NOFF/CNOFF: extra values per line ignored): header counts checked
    against the lines present before anything is allocated.

    Parameters
    ----------
    data : bytes, the file's content; p : Path, its name (for the messages).

    Returns
    -------
    V : (n, 3) float64; F : (m, 3) int64.
    """
    lines = text_lines(without_bom(data))
    keep = [i for i, ln in enumerate(lines) if ln.strip()]
    if not keep:
        raise unreadable(p, "empty file")
    t = lines[keep[0]].split()
    start = 1
    if t[0].upper().endswith(b"OFF"):
        if t[0].upper().startswith(b"ST") or b"4" in t[0] or t[0].upper().startswith(b"N") and len(t[0]) > 5:
            raise unreadable(p, f"unsupported OFF variant {t[0][:20]!r}")
        t = t[1:]
        if not t:
            if len(keep) < 2:
                raise unreadable(p, "truncated: no counts line after OFF")
            t = lines[keep[1]].split()
            start = 2
    if len(t) < 2 or not (t[0].isdigit() and t[1].isdigit()):
        raise unreadable(p, f"line {keep[start - 1] + 1}: expected the counts 'nvertices nfaces nedges', "
                            f"got {show_tokens(t)}")
    nv, nf = int(t[0]), int(t[1])
    have = len(keep) - start
    if nv + nf > have:
        raise unreadable(p, f"truncated: the header announces {nv} vertices and {nf} faces but only {have} "
                            "data lines follow")
    vk, fk = keep[start:start + nv], keep[start + nv:start + nv + nf]
    V = number_table([lines[i] for i in vk], 3, np.float64)
    if V is None:
        V = float_rows([(i + 1, lines[i].split()) for i in vk], p, "vertex")
    F4 = number_table([lines[i] for i in fk], 4, np.int64)
    if F4 is not None and (F4[:, 0] == 3).all():
        return V, F4[:, 1:]
    return V, _off_faces(p, [(i + 1, lines[i].split()) for i in fk])


def _off_faces(p: Path, frows) -> np.ndarray:
    """Per-line parse of OFF face rows ``(line, tokens)``: names the first bad line."""
    for j, (i, t) in enumerate(frows):
        if t[0] != b"3":
            try:
                k = int(t[0])
            except ValueError:
                raise SShaDeError(f"{p}: line {i}: face {show_tokens(t)} does not start with a vertex count") from None
            raise SShaDeError(f"{p}: face {j} (line {i}) has {k} vertices; only triangle meshes are supported")
    try:
        return np.array([(int(t[1]), int(t[2]), int(t[3])) for _, t in frows], np.int64).reshape(-1, 3)
    except (ValueError, IndexError, OverflowError):
        for i, t in frows:
            try:
                np.array([int(t[1]), int(t[2]), int(t[3])], np.int64)
            except (ValueError, IndexError, OverflowError):
                raise SShaDeError(f"{p}: line {i}: face {show_tokens(t)} does not hold three vertex indices") from None
        raise


def off_bytes(V: np.ndarray, F: np.ndarray, comment: str) -> bytes:
    """An OFF file: ``OFF``, ``# comment``, the counts, the vertices (``%.17g``: read back
    bit for bit) and ``3 a b c`` faces. ``V`` (n, 3) float64, ``F`` (m, 3) int64, 0-based,
    checked by the caller (:func:`sshade.mesh.io.write_mesh`)."""
    return (f"OFF\n# {comment}\n{len(V)} {len(F)} 0\n"
            + ("%.17g %.17g %.17g\n" * len(V)) % tuple(V.ravel().tolist())
            + ("3 %d %d %d\n" * len(F)) % tuple(F.ravel().tolist())).encode("ascii")


def off_signed(head: bytes, comment: str) -> bool:
    """Whether the first bytes ``head`` of an OFF file begin as :func:`off_bytes` writes
    them with ``comment``: ``OFF``, then ``# comment``, then more."""
    lines = head.split(b"\n")
    return len(lines) > 2 and lines[0] == b"OFF" and lines[1] == b"# " + comment.encode()


READERS = {".off": read_off}
PREFIX_CHECKS = {".off": text_prefix}
WRITERS = {".off": off_bytes}
SIGNED = {".off": off_signed}

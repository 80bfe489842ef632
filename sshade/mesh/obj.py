"""Wavefront OBJ: the reader (bytes -> (V, F)) and the writer ((V, F) -> bytes).

:func:`read_obj` takes the ``v`` and ``f`` statements (``f a/b/c`` keeps the vertex index,
negative indices count back from the last vertex so far; other statements are ignored,
a line that is no statement is refused), parsed in chunks of
:data:`sshade.mesh.text_rows.TEXT_CHUNK` bytes. :func:`obj_bytes` writes ``v`` lines with
17 significant digits and ``f`` lines with 1-based indices. Format reference: the
Wavefront OBJ specification (Appendix B1 of the Advanced Visualizer manual,
https://paulbourke.net/dataformats/obj/). :data:`READERS`, :data:`PREFIX_CHECKS` and
:data:`WRITERS`, :data:`SIGNED` are this format's entries in :mod:`sshade.mesh.io`'s dispatch.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import SShaDeError
from .text_rows import (
    float_rows,
    number_table,
    show_tokens,
    text_chunks,
    text_lines,
    text_prefix,
    unreadable,
    without_bom,
)

__all__ = ["read_obj", "obj_bytes", "obj_signed", "READERS", "PREFIX_CHECKS", "WRITERS", "SIGNED"]


def read_obj(data: bytes, p: Path):
    """OBJ ``v`` and ``f`` statements (other statements ignored; ``f a/b/c`` keeps the
    vertex index; negative indices count back from the last vertex so far), parsed in
    chunks of :data:`~sshade.mesh.text_rows.TEXT_CHUNK` bytes (the first bad line ends the parse).

    Parameters
    ----------
    data : bytes, the file's content; p : Path, its name (for the messages).

    Returns
    -------
    V : (n, 3) float64; F : (m, 3) int64, 0-based.
    """
    data = without_bom(data)
    Vs, Fs, line, nv = [], [], 0, 0
    for chunk in text_chunks(data):
        V, F, n_lines = _obj_chunk(chunk, p, line, nv)
        Vs.append(V)
        Fs.append(F)
        line, nv = line + n_lines, nv + len(V)
    return np.concatenate(Vs) if Vs else np.zeros((0, 3)), np.concatenate(Fs) if Fs else np.zeros((0, 3), np.int64)


def _obj_chunk(data: bytes, p: Path, line0: int, nv0: int):
    """One chunk of an OBJ (:func:`read_obj`) whose first line is line ``line0 + 1`` of
    the file and follows ``nv0`` vertices: its vertices (k, 3), its faces (j, 3) as
    0-based indices into the whole file's vertices, and its line count."""
    lines = text_lines(data)
    fast = (b"v ", b"f ", b"vn", b"vt", b"")
    for i, ln in enumerate(lines):
        if ln[:2] not in fast:  # unusual line: check its keyword, normalise v/f statements
            t = ln.split()
            if t and t[0] in (b"v", b"f"):
                lines[i] = t[0] + b" " + b" ".join(t[1:])
            elif t and not t[0].replace(b"_", b"").isalpha():
                raise unreadable(p, f"line {line0 + i + 1} is not an OBJ statement: {show_tokens(t)}")
    vi = [i for i, ln in enumerate(lines) if ln[:2] == b"v "]
    fi = [i for i, ln in enumerate(lines) if ln[:2] == b"f "]
    V = number_table([lines[i][2:] for i in vi], 3, np.float64)
    if V is None:
        V = float_rows([(line0 + i + 1, lines[i].split()[1:]) for i in vi], p, "vertex")
    fl = [lines[i][2:] for i in fi]
    if any(b"/" in s for s in fl):
        fl = [re.sub(rb"/\S*", b"", s) for s in fl]
    F = number_table(fl, 3, np.int64)
    if F is None:
        F = _obj_faces(p, [(line0 + i + 1, fl[k].split()) for k, i in enumerate(fi)])
    if (F == 0).any():
        i = fi[int(np.flatnonzero((F == 0).any(1))[0])] + 1
        raise SShaDeError(f"{p}: line {line0 + i}: vertex index 0 (OBJ indices start at 1)")
    neg = F < 0
    F = F - 1
    if neg.any():  # relative indices: -1 is the last vertex defined before the face
        before = nv0 + np.searchsorted(np.asarray(vi), np.asarray(fi))
        F[neg] += np.repeat(before, 3).reshape(-1, 3)[neg] + 1
    return V, F, len(lines)


def _obj_faces(p: Path, rows) -> np.ndarray:
    """Per-line parse of OBJ face rows ``(line, index tokens)``: names the first bad line."""
    for i, t in rows:
        if len(t) != 3:
            raise SShaDeError(f"{p}: line {i} is a face with {len(t)} vertices; only triangle meshes are supported")
        try:
            np.array([int(s) for s in t], np.int64)
        except (ValueError, OverflowError):
            raise SShaDeError(f"{p}: line {i}: face {show_tokens(t)} does not hold three vertex indices") from None
    return np.array([[int(s) for s in t] for _, t in rows], np.int64).reshape(-1, 3)


def obj_bytes(V: np.ndarray, F: np.ndarray, comment: str) -> bytes:
    """An OBJ file: ``# comment``, then ``v`` lines (``%.17g``: read back bit for bit) and
    ``f`` lines (1-based). ``V`` (n, 3) float64, ``F`` (m, 3) int64, 0-based, checked by
    the caller (:func:`sshade.mesh.io.write_mesh`)."""
    return (f"# {comment}\n" + ("v %.17g %.17g %.17g\n" * len(V)) % tuple(V.ravel().tolist())
            + ("f %d %d %d\n" * len(F)) % tuple((F + 1).ravel().tolist())).encode("ascii")


def obj_signed(head: bytes, comment: str) -> bool:
    """Whether the first bytes ``head`` of an OBJ file begin as :func:`obj_bytes` writes
    them with ``comment``: the first line is ``# comment``."""
    return head.split(b"\n")[0] == b"# " + comment.encode()


READERS = {".obj": read_obj}
PREFIX_CHECKS = {".obj": text_prefix}
WRITERS = {".obj": obj_bytes}
SIGNED = {".obj": obj_signed}

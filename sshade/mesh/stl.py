"""STL (stereolithography): the reader (bytes -> (V, F)) and the check of a file's first
bytes; STL is read, never written (:func:`sshade.mesh.io.write_mesh` writes OBJ, OFF, PLY).

:func:`read_stl` reads binary STL (a file of exactly 84 + 50 n bytes) and ASCII STL
(``vertex x y z`` lines), and merges corners with identical coordinates into one vertex
(STL is a triangle soup), vertices in order of first appearance. :func:`check_stl_prefix`
refuses a NUL byte in the first bytes of a file that is not binary STL. Format
reference: 3D Systems, "StereoLithography Interface Specification" (1989; summary at
https://paulbourke.net/dataformats/stl/). :data:`READERS` and :data:`PREFIX_CHECKS` are
this format's entries in :mod:`sshade.mesh.io`'s dispatch (no writer).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import SShaDeError
from .text_rows import float_rows, refuse_nul

__all__ = ["read_stl", "check_stl_prefix", "READERS", "PREFIX_CHECKS", "WRITERS", "SIGNED"]


def check_stl_prefix(head: bytes, size: int, p: Path) -> None:
    """Refuse, before the rest is read, the STL file ``p`` whose first bytes ``head`` hold
    a NUL byte unless its size ``size`` (bytes) is that of a binary STL (84 + 50 n, n
    the triangle count in its header)."""
    if not (len(head) >= 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little")):
        refuse_nul(head, p)


def read_stl(data: bytes, p: Path):
    """Binary STL (size 84 + 50 n) or ASCII STL (``vertex x y z`` lines); corners with
    identical coordinates merged into one vertex (STL is a triangle soup), vertices in
    order of first appearance.

    Parameters
    ----------
    data : bytes, the file's content; p : Path, its name (for the messages).

    Returns
    -------
    V : (n, 3) float64; F : (m, 3) int64.
    """
    n = int.from_bytes(data[80:84], "little") if len(data) >= 84 else -1
    if n >= 0 and len(data) == 84 + 50 * n:
        dt = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
        corners = np.frombuffer(data, dt, n, 84)["v"].astype(np.float64).reshape(-1, 3)
    else:
        head = data[:512].lstrip().lower()
        if not head.startswith(b"solid"):
            raise SShaDeError(f"{p}: unreadable STL file (neither binary: its size, {len(data)} bytes, does not "
                              "match the triangle count in its header; nor ASCII: no 'solid' line)")
        try:
            text = data.decode("ascii")
        except UnicodeDecodeError as e:
            raise SShaDeError(f"{p}: unreadable STL file (ASCII STL with a non-ASCII byte at {e.start})") from None
        rows = [(i, t[1:]) for i, ln in enumerate(text.encode().splitlines(), 1)
                if (t := ln.split()) and t[0].lower() == b"vertex"]
        if len(rows) % 3:
            raise SShaDeError(f"{p}: unreadable STL file ({len(rows)} vertex lines, not a multiple of 3)")
        corners = float_rows(rows, p, "vertex")
    if not np.isfinite(corners).all():
        raise SShaDeError(f"{p}: NaN/inf vertex coordinates in the STL file")
    # merge corners with identical coordinates (STL has no vertex indices); vertices in
    # order of first appearance
    order = np.lexsort((np.arange(len(corners)), corners[:, 2], corners[:, 1], corners[:, 0]))
    c = corners[order]
    new = np.ones(len(c), bool)
    new[1:] = (c[1:] != c[:-1]).any(axis=1)
    group = np.cumsum(new) - 1  # group of each sorted corner; its first corner is the earliest
    first = order[new]
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    F = np.empty(len(corners), np.int64)
    F[order] = rank[group]
    return corners[np.sort(first)], F.reshape(-1, 3)


READERS = {".stl": read_stl}
PREFIX_CHECKS = {".stl": check_stl_prefix}
WRITERS: dict = {}  # read only
SIGNED: dict = {}

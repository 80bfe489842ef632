"""Polygon File Format (PLY, Stanford): the reader (bytes -> (V, F)), the writer ((V, F) ->
bytes) and the check of a file's first bytes.

:func:`read_ply` reads ASCII and binary (little- and big-endian) PLY: the ``vertex``
element's x, y, z and the ``face`` element's one list property (triangles only), other
properties and elements skipped, each element's count checked against the bytes present.
:func:`check_ply_prefix` refuses a binary file larger than its header's elements can fill
(at most :data:`PLY_LIST_MAX` entries per list) before the rest is read. :func:`ply_bytes`
writes binary little-endian doubles (faces: uchar 3 + int32 indices). Format reference:
Greg Turk, "The PLY Polygon File Format" (https://paulbourke.net/dataformats/ply/).
:data:`READERS`, :data:`PREFIX_CHECKS`, :data:`WRITERS`, :data:`SIGNED` are this format's
entries in :mod:`sshade.mesh.io`'s dispatch.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import SShaDeError
from .text_rows import number_table, refuse_nul, short_error, show_tokens, text_chunks, unreadable, without_bom

__all__ = ["PLY_LIST_MAX", "read_ply", "check_ply_prefix", "ply_bytes", "ply_signed", "READERS", "PREFIX_CHECKS",
           "WRITERS", "SIGNED"]

#: The most entries a PLY face list is taken to hold when a binary file's size is bounded
#: by its header (a triangle has 3; polygons are refused later, by name).
PLY_LIST_MAX = 16

_PLY_TYPES = {b"char": "i1", b"int8": "i1", b"uchar": "u1", b"uint8": "u1", b"short": "i2", b"int16": "i2",
              b"ushort": "u2", b"uint16": "u2", b"int": "i4", b"int32": "i4", b"uint": "u4", b"uint32": "u4",
              b"float": "f4", b"float32": "f4", b"double": "f8", b"float64": "f8"}


def check_ply_prefix(head: bytes, size: int, p: Path) -> None:
    """Refuse, before the rest is read, the PLY file ``p`` whose first bytes ``head`` hold
    a NUL byte in its text (the header; the whole of an ASCII PLY) or whose size ``size``
    (bytes) exceeds what its binary elements can fill (at most :data:`PLY_LIST_MAX`
    entries per list)."""
    text = head[:_ply_body(head)]
    if head.startswith(b"ply") and b"\0" not in text:
        fmt, elems, body = _ply_header(head, p)
        if fmt == b"ascii":
            text = head
        else:
            most = body + sum(n * sum(np.dtype(t).itemsize + (0 if c is None else np.dtype(c).itemsize
                                                              + (PLY_LIST_MAX - 1) * np.dtype(t).itemsize)
                                      for _, t, c in props) for _, n, props in elems)
            if size > most:
                raise unreadable(p, f"{size} bytes, more than its header's elements can hold ({most})")
    refuse_nul(text, p)


def _ply_body(head: bytes) -> int:
    """The offset of a PLY's body in ``head`` (the end of its ``end_header`` line), or its length."""
    end = head.find(b"end_header")
    nl = head.find(b"\n", end) if end >= 0 else -1
    return nl + 1 if nl >= 0 else len(head)


def _ply_header(data: bytes, p: Path):
    """(format, [(element name, count, [(prop name, type, list count type or None)])], body offset)."""
    if not data.startswith(b"ply"):
        raise unreadable(p, "no 'ply' magic line")
    end = data.find(b"end_header", 0, 1 << 16)
    if end < 0:
        raise unreadable(p, "no end_header line in the first 64 KiB")
    nl = data.find(b"\n", end)
    body = len(data) if nl < 0 else nl + 1
    fmt, elems = None, []
    for i, ln in enumerate(data[:end].splitlines()[1:], 2):
        t = ln.split()
        if not t or t[0] in (b"comment", b"obj_info"):
            continue
        if t[0] == b"format" and len(t) >= 2:
            fmt = t[1]
        elif t[0] == b"element" and len(t) == 3 and t[2].isdigit():
            elems.append((t[1], int(t[2]), []))
        elif t[0] == b"property" and elems and len(t) == 3 and t[1] in _PLY_TYPES:
            elems[-1][2].append((t[2], _PLY_TYPES[t[1]], None))
        elif (t[0] == b"property" and elems and len(t) == 5 and t[1] == b"list" and t[2] in _PLY_TYPES
              and t[3] in _PLY_TYPES):
            elems[-1][2].append((t[4], _PLY_TYPES[t[3]], _PLY_TYPES[t[2]]))
        else:
            raise unreadable(p, f"header line {i} not understood: {show_tokens(t)}")
    if fmt not in (b"ascii", b"binary_little_endian", b"binary_big_endian"):
        raise unreadable(p, f"format {fmt!r} (ascii, binary_little_endian or binary_big_endian)")
    return fmt, elems, body


def read_ply(data: bytes, p: Path):
    """PLY (ASCII or binary): the ``vertex`` element's x, y, z and the ``face``
    element's vertex index list; element counts checked against the file size first.

    Parameters
    ----------
    data : bytes, the file's content; p : Path, its name (for the messages).

    Returns
    -------
    V : (n, 3) float64; F : (m, 3) int64.
    """
    data = without_bom(data)
    fmt, elems, pos = _ply_header(data, p)
    names = [e[0] for e in elems]
    if b"vertex" not in names or b"face" not in names:
        raise unreadable(p, "no vertex or no face element")
    if fmt == b"ascii":
        return _ply_ascii(data[pos:], elems, p)
    bo = "<" if fmt == b"binary_little_endian" else ">"
    out = {}
    for name, count, props in elems:
        if name not in (b"vertex", b"face"):
            if any(c for _, _, c in props):
                if not {b"vertex", b"face"} <= set(out):
                    raise unreadable(p, f"element {name!r} with a list property before the mesh (unsupported)")
                break
        lists = [k for k, (_, _, c) in enumerate(props) if c]
        if name == b"vertex" and lists:
            raise unreadable(p, "list property in the vertex element (unsupported)")
        if name == b"face" and len(lists) != 1:
            raise unreadable(p, "the face element needs exactly one list property (vertex_indices)")
        fields = []
        for pname, typ, ctyp in props:
            if ctyp:
                fields += [("n", bo + ctyp), ("idx", bo + typ, (3,))]
            else:
                fields.append(("_" + pname.decode("ascii", "replace"), bo + typ))
        dt = np.dtype(fields)
        if count * dt.itemsize > len(data) - pos:
            raise unreadable(p, f"truncated: element {name.decode('ascii', 'replace')} announces {count} items "
                                f"({count * dt.itemsize} bytes at least) but {len(data) - pos} bytes follow")
        arr = np.frombuffer(data, dt, count, pos)
        if lists:
            bad = np.flatnonzero(arr["n"] != 3)
            if bad.size:
                raise SShaDeError(f"{p}: face {int(bad[0])} has {int(arr['n'][bad[0]])} vertices; "
                                  "only triangle meshes are supported")
        out[name] = (arr, props)
        pos += count * dt.itemsize
    return _ply_arrays(out[b"vertex"][0], out[b"face"][0], p)


def _ply_arrays(varr, farr, p: Path):
    """(V, F) from structured vertex and face arrays."""
    missing = [c for c in ("_x", "_y", "_z") if c not in varr.dtype.names]
    if missing:
        raise unreadable(p, f"vertex element lacks {', '.join(m[1:] for m in missing)}")
    V = np.stack([varr[c].astype(np.float64) for c in ("_x", "_y", "_z")], axis=1)
    idx = farr["idx"]
    if idx.dtype.kind == "f":
        if not (np.isfinite(idx).all() and (idx == np.round(idx)).all()):
            raise unreadable(p, "face indices are not integers")
    elif idx.dtype.kind == "u" and idx.dtype.itemsize == 8:
        raise unreadable(p, "64-bit unsigned face indices")
    return V, idx.astype(np.int64)


def _ply_ascii(body: bytes, elems, p: Path):
    """ASCII PLY body: one element item per non-blank line, in header order, read in
    chunks of :data:`~sshade.mesh.text_rows.TEXT_CHUNK` bytes (each element's rows parsed
    chunk by chunk)."""
    batches = ([ln for ln in c.splitlines() if ln.strip()] for c in text_chunks(body))
    total, seen, pending, out = sum(c for _, c, _ in elems), 0, [], {}
    parse = {b"vertex": _ply_ascii_vertices, b"face": _ply_ascii_faces}
    for name, count, props in elems:
        parts, done = [], 0
        while done < count:
            if not pending:
                pending = next(batches, None)
                if pending is None:
                    raise unreadable(p, f"truncated: the header announces {total} items but {seen} lines follow")
            take, pending = pending[:count - done], pending[count - done:]
            if name in parse:
                parts.append(parse[name](take, props, p, done))
            done, seen = done + len(take), seen + len(take)
        if name in parse:
            out[name] = np.concatenate(parts) if parts else parse[name]([], props, p)
    return _ply_arrays(out[b"vertex"], out[b"face"], p)


def _ply_ascii_vertices(chunk: list, props, p: Path, first: int = 0) -> np.ndarray:
    """Structured array (fields ``_<property>``, float64) of ASCII PLY vertex lines, the
    first of them vertex ``first``."""
    if any(c for _, _, c in props):
        raise unreadable(p, "list property in the vertex element (unsupported)")
    want = len(props)
    vals = number_table(chunk, want, np.float64)
    if vals is None:
        rows = [ln.split() for ln in chunk]
        for j, t in enumerate(rows):
            if len(t) != want:
                raise unreadable(p, f"vertex {first + j} has {len(t)} values, the header says {want}")
        try:
            vals = np.array([float(x) for t in rows for x in t], np.float64).reshape(len(rows), want)
        except ValueError as e:
            raise unreadable(p, f"a vertex value is not a number ({short_error(e)})") from None
    arr = np.zeros(len(chunk), np.dtype([("_" + pn.decode("ascii", "replace"), "f8") for pn, _, _ in props]))
    for c, name in enumerate(arr.dtype.names):
        arr[name] = vals[:, c]
    return arr


def _ply_ascii_faces(chunk: list, props, p: Path, first: int = 0) -> np.ndarray:
    """Structured array (``n``, ``idx`` (3,) int64) of ASCII PLY face lines, triangles
    only, the first of them face ``first``."""
    ks = [j for j, (_, _, c) in enumerate(props) if c]
    if len(ks) != 1 or any(props[j][2] for j in range(ks[0])):
        raise unreadable(p, "the face element needs exactly one list property (vertex_indices)")
    k = ks[0]
    tab = number_table(chunk, len(props) + 3, np.int64)
    if tab is None or (tab[:, k] != 3).any():
        for j, t in enumerate(ln.split() for ln in chunk):
            m = int(t[k]) if len(t) > k and t[k].isdigit() else -1
            if m < 0:
                raise unreadable(p, f"face {first + j}: {show_tokens(t)} is not a vertex count and indices")
            if m != 3:
                raise SShaDeError(f"{p}: face {first + j} has {m} vertices; only triangle meshes are supported")
            if len(t) != len(props) + 3:
                raise unreadable(p, f"face {first + j} has {len(t)} values, expected {len(props) + 3}")
            try:
                np.array([int(x) for x in t[k + 1:k + 4]], np.int64)
            except (ValueError, OverflowError):
                raise unreadable(p, f"face {first + j}: {show_tokens(t)} does not hold three vertex indices") from None
        raise unreadable(p, "face values are not integers")
    arr = np.zeros(len(chunk), np.dtype([("n", "i8"), ("idx", "i8", (3,))]))
    arr["n"] = 3
    arr["idx"] = tab[:, k + 1:k + 4]
    return arr


def ply_bytes(V: np.ndarray, F: np.ndarray, comment: str) -> bytes:
    """A binary little-endian PLY with ``comment``: double x y z (read back bit for bit),
    faces as uchar 3 + int32 indices. ``V`` (n, 3) float64, ``F`` (m, 3) int64, 0-based and
    within int32, checked by the caller (:func:`sshade.mesh.io.write_mesh`)."""
    head = (f"ply\nformat binary_little_endian 1.0\ncomment {comment}\nelement vertex {len(V)}\n"
            "property double x\nproperty double y\nproperty double z\n"
            f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n").encode("ascii")
    fa = np.empty(len(F), np.dtype([("n", "u1"), ("idx", "<i4", (3,))]))
    fa["n"] = 3
    fa["idx"] = F
    return head + V.astype("<f8").tobytes() + fa.tobytes()


def ply_signed(head: bytes, comment: str) -> bool:
    """Whether the first bytes ``head`` of a PLY file begin as :func:`ply_bytes` writes
    them with ``comment``: ``ply``, and ``comment <comment>`` among the first four lines."""
    lines = head.split(b"\n")
    return lines[0] == b"ply" and b"comment " + comment.encode() in lines[:4]


READERS = {".ply": read_ply}
PREFIX_CHECKS = {".ply": check_ply_prefix}
WRITERS = {".ply": ply_bytes}
SIGNED = {".ply": ply_signed}

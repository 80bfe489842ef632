"""Reading and writing triangle meshes (OBJ, OFF, PLY, STL) with clear errors; the files
are written atomically (:func:`sshade.files.atomic_write`, re-exported here with
:func:`sshade.files.inside_folder` for the callers of before).

Generic mesh I/O of every layer (the DeFAUST builder, the evaluator, ``python -m sshade
deform``); the geometry core (remesh, ARAP, transfer) never reads or writes files.
"""
from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import SShaDeError
from ..files import atomic_write, inside_folder
from ..json_file import regular_file
from .validate import validate_mesh

__all__ = ["read_mesh", "write_mesh", "atomic_write", "inside_folder", "written_by_sshade", "SIGNATURE"]

_EXTS = {".obj", ".off", ".ply", ".stl"}


def read_mesh(path, *, validate: bool = True, allow_components: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh.

    Parameters
    ----------
    path : str or Path, an ``.obj``, ``.off``, ``.ply`` or ``.stl`` file.
    validate : bool, run :func:`sshade.mesh.validate.validate_mesh` on the result.
    allow_components : bool, with ``validate``: accept several connected components
        (scans, character models; deformed per component, :mod:`sshade.components`).

    Returns
    -------
    V : (n, 3) float64 vertex positions, in the file's units.
    F : (m, 3) int64 triangle indices.

    Raises
    ------
    SShaDeError
        Missing or unreadable file, unknown extension, non-triangle faces (polygons are
        not silently triangulated), and with ``validate`` every problem
        :func:`~sshade.mesh.validate.validate_mesh` names.

    Examples
    --------
    Example::

        V, F = read_mesh("../shared/data/classic/bunny.off")
    """
    p = regular_file(path, "mesh file")
    ext = p.suffix.lower()
    if ext not in _EXTS:
        raise SShaDeError(f"{p}: unsupported mesh format {ext!r} (use one of {sorted(_EXTS)})")
    try:
        with open(p, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            _check_prefix(fh.read(PREFIX_BYTES), size, ext, p)  # before the rest is read: bounded by the header
            fh.seek(0)
            data = fh.read()
    except OSError as e:
        raise SShaDeError(f"{p}: unreadable mesh file ({e.strerror or type(e).__name__})") from None
    if ext != ".stl" and data.startswith(b"\xef\xbb\xbf"):  # a UTF-8 byte-order mark (editors on Windows)
        data = data[3:]
    # pure-Python/numpy readers: a truncated or lying file is an SShaDeError, never a
    # native abort (libigl's readers double-free on some of them) nor a huge allocation
    reader = {".obj": _read_obj, ".off": _read_off, ".ply": _read_ply, ".stl": _read_stl}[ext]
    try:
        V, F = reader(data, p)
    except SShaDeError:
        raise
    except (ValueError, IndexError, KeyError, OverflowError, TypeError, MemoryError) as e:
        raise SShaDeError(f"{p}: unreadable {ext[1:].upper()} file (malformed: {_short(e)})") from None
    V = np.ascontiguousarray(V, dtype=np.float64).reshape(-1, 3)
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    if len(V) == 0 or len(F) == 0:
        raise SShaDeError(f"{p}: unreadable mesh file (no vertices or no faces found)")
    if validate:
        V, F = validate_mesh(V, F, name=str(p), allow_components=allow_components)
    return V, F


#: The bytes of a mesh file read and checked before the rest (:func:`_check_prefix`).
PREFIX_BYTES = 1 << 16
#: The most entries a PLY face list is taken to hold when a binary file's size is bounded
#: by its header (a triangle has 3; polygons are refused later, by name).
PLY_LIST_MAX = 16


def _check_prefix(head: bytes, size: int, ext: str, p: Path) -> None:
    """Refuse, before reading the rest, a mesh file whose first bytes ``head`` show it is no
    such file, or whose size exceeds what its header promises: a NUL byte in the text of
    an OBJ, OFF, ASCII PLY or ASCII STL (a sparse or binary file named so); a binary PLY
    larger than its elements can fill (at most :data:`PLY_LIST_MAX` entries per list).
    ``size``: the file's size in bytes."""
    text = head[:_ply_body(head)] if ext == ".ply" else head
    binary_stl = ext == ".stl" and len(head) >= 84 and size == 84 + 50 * int.from_bytes(head[80:84], "little")
    if ext == ".ply" and head.startswith(b"ply") and b"\0" not in text:
        fmt, elems, body = _ply_header(head, p)
        if fmt == b"ascii":
            text = head
        else:
            most = body + sum(n * sum(np.dtype(t).itemsize + (0 if c is None else np.dtype(c).itemsize
                                                              + (PLY_LIST_MAX - 1) * np.dtype(t).itemsize)
                                      for _, t, c in props) for _, n, props in elems)
            if size > most:
                raise _bad(p, f"{size} bytes, more than its header's elements can hold ({most})")
    i = -1 if binary_stl else text.find(b"\0")
    if i >= 0:
        raise _bad(p, f"byte {i}: a NUL byte, so no {ext[1:].upper()} text (a binary or empty file named so?)")


def _ply_body(head: bytes) -> int:
    """The offset of a PLY's body in ``head`` (the end of its ``end_header`` line), or its length."""
    end = head.find(b"end_header")
    nl = head.find(b"\n", end) if end >= 0 else -1
    return nl + 1 if nl >= 0 else len(head)


def _short(e: BaseException) -> str:
    """One short line describing an exception."""
    s = " ".join(str(e).split())
    return (s[:120] + "...") if len(s) > 120 else (s or type(e).__name__)


def _bad(p: Path, what: str) -> SShaDeError:
    return SShaDeError(f"{p}: unreadable {p.suffix[1:].upper()} file ({what})")


def _floats(rows, p: Path, what: str) -> np.ndarray:
    """(k, 3) float64 from the first three tokens of each row ``(line, tokens)``
    (correctly rounded: Python's float); an SShaDeError names the first bad line."""
    try:
        return np.array([(float(t[0]), float(t[1]), float(t[2])) for _, t in rows], np.float64).reshape(-1, 3)
    except (ValueError, IndexError):
        for i, t in rows:
            try:
                float(t[0]), float(t[1]), float(t[2])
            except (ValueError, IndexError):
                raise SShaDeError(f"{p}: line {i}: {what} {_show(t)} is not three numbers") from None
        raise


def _show(toks) -> str:
    return repr(b" ".join(toks)[:60])[1:]  # ASCII only: raw bytes never reach the terminal


_WS = np.zeros(256, bool)
_WS[[9, 10, 11, 12, 13, 32]] = True


def _table(lines: list, ncols: int, dtype):
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


def _lines(data: bytes) -> list:
    """Lines of a text file, ``#`` comments removed."""
    lines = data.splitlines()
    if b"#" in data:
        lines = [ln.split(b"#", 1)[0] if b"#" in ln else ln for ln in lines]
    return lines


#: bytes of an OBJ parsed at once: the parse's memory is this chunk's, not the file's
OBJ_CHUNK = 1 << 20


def _text_chunks(data: bytes, size: int = OBJ_CHUNK):
    """``data`` in pieces of about ``size`` bytes, each ending at a line break (``\n``)
    or at the end: yields the pieces in order."""
    start, n = 0, len(data)
    while start < n:
        end = data.find(b"\n", min(start + size, n) - 1)
        end = n if end < 0 else end + 1
        yield data[start:end]
        start = end


def _read_obj(data: bytes, p: Path):
    """OBJ ``v`` and ``f`` statements (other statements ignored; ``f a/b/c`` keeps the
    vertex index; negative indices count back from the last vertex so far), parsed in
    chunks of :data:`OBJ_CHUNK` bytes (the first bad line ends the parse)."""
    Vs, Fs, line, nv = [], [], 0, 0
    for chunk in _text_chunks(data):
        V, F, n_lines = _obj_chunk(chunk, p, line, nv)
        Vs.append(V)
        Fs.append(F)
        line, nv = line + n_lines, nv + len(V)
    return np.concatenate(Vs) if Vs else np.zeros((0, 3)), np.concatenate(Fs) if Fs else np.zeros((0, 3), np.int64)


def _obj_chunk(data: bytes, p: Path, line0: int, nv0: int):
    """One chunk of an OBJ (:func:`_read_obj`) whose first line is line ``line0 + 1`` of
    the file and follows ``nv0`` vertices: its vertices (k, 3), its faces (j, 3) as
    0-based indices into the whole file's vertices, and its line count."""
    lines = _lines(data)
    fast = (b"v ", b"f ", b"vn", b"vt", b"")
    for i, ln in enumerate(lines):
        if ln[:2] not in fast:  # unusual line: check its keyword, normalise v/f statements
            t = ln.split()
            if t and t[0] in (b"v", b"f"):
                lines[i] = t[0] + b" " + b" ".join(t[1:])
            elif t and not t[0].replace(b"_", b"").isalpha():
                raise _bad(p, f"line {line0 + i + 1} is not an OBJ statement: {_show(t)}")
    vi = [i for i, ln in enumerate(lines) if ln[:2] == b"v "]
    fi = [i for i, ln in enumerate(lines) if ln[:2] == b"f "]
    V = _table([lines[i][2:] for i in vi], 3, np.float64)
    if V is None:
        V = _floats([(line0 + i + 1, lines[i].split()[1:]) for i in vi], p, "vertex")
    fl = [lines[i][2:] for i in fi]
    if any(b"/" in s for s in fl):
        fl = [re.sub(rb"/\S*", b"", s) for s in fl]
    F = _table(fl, 3, np.int64)
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
            raise SShaDeError(f"{p}: line {i}: face {_show(t)} does not hold three vertex indices") from None
    return np.array([[int(s) for s in t] for _, t in rows], np.int64).reshape(-1, 3)


def _read_off(data: bytes, p: Path):
    """OFF (also COFF/NOFF/CNOFF: extra values per line ignored): header counts checked
    against the lines present before anything is allocated."""
    lines = _lines(data)
    keep = [i for i, ln in enumerate(lines) if ln.strip()]
    if not keep:
        raise _bad(p, "empty file")
    t = lines[keep[0]].split()
    start = 1
    if t[0].upper().endswith(b"OFF"):
        if t[0].upper().startswith(b"ST") or b"4" in t[0] or t[0].upper().startswith(b"N") and len(t[0]) > 5:
            raise _bad(p, f"unsupported OFF variant {t[0][:20]!r}")
        t = t[1:]
        if not t:
            if len(keep) < 2:
                raise _bad(p, "truncated: no counts line after OFF")
            t = lines[keep[1]].split()
            start = 2
    if len(t) < 2 or not (t[0].isdigit() and t[1].isdigit()):
        raise _bad(p, f"line {keep[start - 1] + 1}: expected the counts 'nvertices nfaces nedges', got {_show(t)}")
    nv, nf = int(t[0]), int(t[1])
    have = len(keep) - start
    if nv + nf > have:
        raise _bad(p, f"truncated: the header announces {nv} vertices and {nf} faces but only {have} "
                      "data lines follow")
    vk, fk = keep[start:start + nv], keep[start + nv:start + nv + nf]
    V = _table([lines[i] for i in vk], 3, np.float64)
    if V is None:
        V = _floats([(i + 1, lines[i].split()) for i in vk], p, "vertex")
    F4 = _table([lines[i] for i in fk], 4, np.int64)
    if F4 is not None and (F4[:, 0] == 3).all():
        return V, F4[:, 1:]
    frows = [(i + 1, lines[i].split()) for i in fk]
    for j, (i, t) in enumerate(frows):
        if t[0] != b"3":
            try:
                k = int(t[0])
            except ValueError:
                raise SShaDeError(f"{p}: line {i}: face {_show(t)} does not start with a vertex count") from None
            raise SShaDeError(f"{p}: face {j} (line {i}) has {k} vertices; only triangle meshes are supported")
    try:
        F = np.array([(int(t[1]), int(t[2]), int(t[3])) for _, t in frows], np.int64).reshape(-1, 3)
    except (ValueError, IndexError, OverflowError):
        for i, t in frows:
            try:
                np.array([int(t[1]), int(t[2]), int(t[3])], np.int64)
            except (ValueError, IndexError, OverflowError):
                raise SShaDeError(f"{p}: line {i}: face {_show(t)} does not hold three vertex indices") from None
        raise
    return V, F


_PLY_TYPES = {b"char": "i1", b"int8": "i1", b"uchar": "u1", b"uint8": "u1", b"short": "i2", b"int16": "i2",
              b"ushort": "u2", b"uint16": "u2", b"int": "i4", b"int32": "i4", b"uint": "u4", b"uint32": "u4",
              b"float": "f4", b"float32": "f4", b"double": "f8", b"float64": "f8"}


def _ply_header(data: bytes, p: Path):
    """(format, [(element name, count, [(prop name, type, list count type or None)])], body offset)."""
    if not data.startswith(b"ply"):
        raise _bad(p, "no 'ply' magic line")
    end = data.find(b"end_header", 0, 1 << 16)
    if end < 0:
        raise _bad(p, "no end_header line in the first 64 KiB")
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
            raise _bad(p, f"header line {i} not understood: {_show(t)}")
    if fmt not in (b"ascii", b"binary_little_endian", b"binary_big_endian"):
        raise _bad(p, f"format {fmt!r} (ascii, binary_little_endian or binary_big_endian)")
    return fmt, elems, body


def _read_ply(data: bytes, p: Path):
    """PLY (ASCII or binary): the ``vertex`` element's x, y, z and the ``face``
    element's vertex index list; element counts checked against the file size first."""
    fmt, elems, pos = _ply_header(data, p)
    names = [e[0] for e in elems]
    if b"vertex" not in names or b"face" not in names:
        raise _bad(p, "no vertex or no face element")
    if fmt == b"ascii":
        return _ply_ascii(data[pos:], elems, p)
    bo = "<" if fmt == b"binary_little_endian" else ">"
    out = {}
    for name, count, props in elems:
        if name not in (b"vertex", b"face"):
            if any(c for _, _, c in props):
                if not {b"vertex", b"face"} <= set(out):
                    raise _bad(p, f"element {name!r} with a list property before the mesh (unsupported)")
                break
        lists = [k for k, (_, _, c) in enumerate(props) if c]
        if name == b"vertex" and lists:
            raise _bad(p, "list property in the vertex element (unsupported)")
        if name == b"face" and len(lists) != 1:
            raise _bad(p, "the face element needs exactly one list property (vertex_indices)")
        fields = []
        for pname, typ, ctyp in props:
            if ctyp:
                fields += [("n", bo + ctyp), ("idx", bo + typ, (3,))]
            else:
                fields.append(("_" + pname.decode("ascii", "replace"), bo + typ))
        dt = np.dtype(fields)
        if count * dt.itemsize > len(data) - pos:
            raise _bad(p, f"truncated: element {name.decode('ascii', 'replace')} announces {count} items "
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
        raise _bad(p, f"vertex element lacks {', '.join(m[1:] for m in missing)}")
    V = np.stack([varr[c].astype(np.float64) for c in ("_x", "_y", "_z")], axis=1)
    idx = farr["idx"]
    if idx.dtype.kind == "f":
        if not (np.isfinite(idx).all() and (idx == np.round(idx)).all()):
            raise _bad(p, "face indices are not integers")
    elif idx.dtype.kind == "u" and idx.dtype.itemsize == 8:
        raise _bad(p, "64-bit unsigned face indices")
    return V, idx.astype(np.int64)


def _ply_ascii(body: bytes, elems, p: Path):
    """ASCII PLY body: one element item per non-blank line, in header order, read in
    chunks of :data:`OBJ_CHUNK` bytes (each element's rows parsed chunk by chunk)."""
    batches = ([ln for ln in c.splitlines() if ln.strip()] for c in _text_chunks(body))
    total, seen, pending, out = sum(c for _, c, _ in elems), 0, [], {}
    parse = {b"vertex": _ply_ascii_vertices, b"face": _ply_ascii_faces}
    for name, count, props in elems:
        parts, done = [], 0
        while done < count:
            if not pending:
                pending = next(batches, None)
                if pending is None:
                    raise _bad(p, f"truncated: the header announces {total} items but {seen} lines follow")
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
        raise _bad(p, "list property in the vertex element (unsupported)")
    want = len(props)
    vals = _table(chunk, want, np.float64)
    if vals is None:
        rows = [ln.split() for ln in chunk]
        for j, t in enumerate(rows):
            if len(t) != want:
                raise _bad(p, f"vertex {first + j} has {len(t)} values, the header says {want}")
        try:
            vals = np.array([float(x) for t in rows for x in t], np.float64).reshape(len(rows), want)
        except ValueError as e:
            raise _bad(p, f"a vertex value is not a number ({_short(e)})") from None
    arr = np.zeros(len(chunk), np.dtype([("_" + pn.decode("ascii", "replace"), "f8") for pn, _, _ in props]))
    for c, name in enumerate(arr.dtype.names):
        arr[name] = vals[:, c]
    return arr


def _ply_ascii_faces(chunk: list, props, p: Path, first: int = 0) -> np.ndarray:
    """Structured array (``n``, ``idx`` (3,) int64) of ASCII PLY face lines, triangles
    only, the first of them face ``first``."""
    ks = [j for j, (_, _, c) in enumerate(props) if c]
    if len(ks) != 1 or any(props[j][2] for j in range(ks[0])):
        raise _bad(p, "the face element needs exactly one list property (vertex_indices)")
    k = ks[0]
    tab = _table(chunk, len(props) + 3, np.int64)
    if tab is None or (tab[:, k] != 3).any():
        for j, t in enumerate(ln.split() for ln in chunk):
            m = int(t[k]) if len(t) > k and t[k].isdigit() else -1
            if m < 0:
                raise _bad(p, f"face {first + j}: {_show(t)} is not a vertex count and indices")
            if m != 3:
                raise SShaDeError(f"{p}: face {first + j} has {m} vertices; only triangle meshes are supported")
            if len(t) != len(props) + 3:
                raise _bad(p, f"face {first + j} has {len(t)} values, expected {len(props) + 3}")
            try:
                np.array([int(x) for x in t[k + 1:k + 4]], np.int64)
            except (ValueError, OverflowError):
                raise _bad(p, f"face {first + j}: {_show(t)} does not hold three vertex indices") from None
        raise _bad(p, "face values are not integers")
    arr = np.zeros(len(chunk), np.dtype([("n", "i8"), ("idx", "i8", (3,))]))
    arr["n"] = 3
    arr["idx"] = tab[:, k + 1:k + 4]
    return arr


def _read_stl(data: bytes, p: Path):
    """Binary STL (size 84 + 50 n) or ASCII STL (``vertex x y z`` lines); corners with
    identical coordinates merged into one vertex (STL is a triangle soup), vertices in
    order of first appearance."""
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
        corners = _floats(rows, p, "vertex")
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


SIGNATURE = "written by sshade"


def write_mesh(path, V: np.ndarray, F: np.ndarray) -> None:
    """Write a triangle mesh atomically (format from the extension: .obj, .off, .ply),
    without losing precision: OBJ and OFF as text with 17 significant digits
    (``%.17g``), PLY as binary little-endian doubles (faces: uchar count + int32
    indices), so :func:`read_mesh` gives ``V`` back bit for bit. Each file carries the
    comment ``written by sshade`` (:func:`written_by_sshade`), which readers ignore.

    Parameters
    ----------
    path : str or Path.
    V : (n, 3) float64 (any unit); F : (m, 3) int, 0-based vertex indices.

    Raises
    ------
    SShaDeError on an unsupported extension, wrong shapes or face indices that do not
    fit in int32 (PLY); OSError if the file cannot be written (``path`` then keeps its
    previous content, :func:`atomic_write`).
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in {".obj", ".off", ".ply"}:
        raise SShaDeError(f"{path}: unsupported output mesh format {ext!r}")
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise SShaDeError(f"{path}: cannot write V {V.shape} and F {F.shape}; expected (n, 3) and (m, 3)")
    if F.size and (F.min() < 0 or F.max() >= max(len(V), 1) or F.max() > np.iinfo(np.int32).max):
        raise SShaDeError(f"{path}: face indices outside [0, {len(V)})")
    if ext == ".ply":
        data = _ply_bytes(V, F)
    elif ext == ".obj":
        data = (f"# {SIGNATURE}\n" + ("v %.17g %.17g %.17g\n" * len(V)) % tuple(V.ravel().tolist())
                + ("f %d %d %d\n" * len(F)) % tuple((F + 1).ravel().tolist())).encode("ascii")
    else:
        data = (f"OFF\n# {SIGNATURE}\n{len(V)} {len(F)} 0\n"
                + ("%.17g %.17g %.17g\n" * len(V)) % tuple(V.ravel().tolist())
                + ("3 %d %d %d\n" * len(F)) % tuple(F.ravel().tolist())).encode("ascii")
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def _ply_bytes(V: np.ndarray, F: np.ndarray) -> bytes:
    """Binary little-endian PLY: double x y z, faces as uchar 3 + int32 indices."""
    head = (f"ply\nformat binary_little_endian 1.0\ncomment {SIGNATURE}\nelement vertex {len(V)}\n"
            "property double x\nproperty double y\nproperty double z\n"
            f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n").encode("ascii")
    fa = np.empty(len(F), np.dtype([("n", "u1"), ("idx", "<i4", (3,))]))
    fa["n"] = 3
    fa["idx"] = F
    return head + V.astype("<f8").tobytes() + fa.tobytes()


def written_by_sshade(path) -> bool:
    """True if ``path`` is a mesh file that :func:`write_mesh` wrote (its signature
    comment is in the file's header: first line of an OBJ, second of an OFF, a PLY
    ``comment`` line). False for any other file, a missing one or a folder."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(512)
    except OSError:
        return False
    sig = SIGNATURE.encode()
    lines = head.split(b"\n")
    ext = Path(path).suffix.lower()
    if ext == ".obj":
        return lines[0] == b"# " + sig
    if ext == ".off":
        return len(lines) > 2 and lines[0] == b"OFF" and lines[1] == b"# " + sig
    if ext == ".ply":
        return lines[0] == b"ply" and b"comment " + sig in lines[:4]
    return False

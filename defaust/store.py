"""Byte-deterministic files for the DeFAUST builder: binary PLY (:func:`ply_bytes`,
``double`` coordinates), NPZ with fixed member timestamps (:func:`write_npz`), SHA-256,
written atomically (:func:`sshade.files.atomic_write`). Meshes are read back with
:func:`sshade.mesh.io.read_mesh` or, from bytes (an archive's member), with
:func:`read_ply_bytes`; :func:`read_npz` reads an ``.npz`` as untrusted input (expected
members only, each bounded in size before it is decompressed). Why not trimesh's PLY or
:func:`numpy.savez`: docs/defaust.md, "Implementation notes: defaust/store.py".
"""
from __future__ import annotations

import hashlib
import io
import math
import re
import zipfile
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError
from sshade.files import atomic_write

__all__ = ["write_ply", "ply_bytes", "read_ply_bytes", "write_npz", "read_npz", "sha256_file", "sha256_bytes",
           "sha256_stream", "MAX_MEMBER_BYTES"]

_ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # the earliest date a zip entry can hold


def ply_bytes(V, F) -> bytes:
    """Binary little-endian PLY of a triangle mesh: ``double`` x/y/z, ``int`` indices.

    Parameters
    ----------
    V : (n, 3) array_like of float, vertex positions (written as float64, exact).
    F : (m, 3) array_like of int, triangles (0-based, written as int32).

    Returns
    -------
    bytes, identical for identical arrays (no comment, no timestamp).

    Raises
    ------
    SShaDeError on wrong shapes or indices that do not fit int32.

    Examples
    --------
    >>> b = ply_bytes(np.eye(3), [[0, 1, 2]])
    >>> b[:3]
    b'ply'
    """
    V = np.ascontiguousarray(V, dtype="<f8")
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise SShaDeError(f"ply_bytes: need V (n, 3) and F (m, 3), got {V.shape} and {F.shape}")
    if F.size and (F.min() < 0 or F.max() >= min(len(V), 2**31 - 1)):
        raise SShaDeError("ply_bytes: face indices out of range")
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {len(V)}\nproperty double x\nproperty double y\nproperty double z\n"
              f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n").encode("ascii")
    faces = np.zeros(len(F), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    faces["n"] = 3
    faces["i"] = F
    return header + V.tobytes() + faces.tobytes()


def read_ply_bytes(data: bytes, name: str = "PLY") -> tuple[np.ndarray, np.ndarray]:
    """The mesh of a PLY that :func:`ply_bytes` wrote (its fixed header: binary
    little-endian, ``double`` x/y/z, ``uchar`` + ``int`` triangles), read as untrusted
    input from bytes (an archive member; a folder's files are read by
    :func:`sshade.mesh.io.read_mesh`, which gives the same arrays).

    Parameters
    ----------
    data : bytes, the whole file. name : str, how messages name the file.

    Returns
    -------
    V : (n, 3) float64, F : (m, 3) int64 (writable copies).

    Raises
    ------
    SShaDeError, one line naming the file: another header, a size other than the
    header's counts need, a face that is not a triangle or an index out of range.

    Examples
    --------
    >>> V, F = read_ply_bytes(ply_bytes(np.eye(3), [[0, 1, 2]]))
    >>> V.shape, F.tolist()
    ((3, 3), [[0, 1, 2]])
    """
    m = _PLY_HEADER.match(data[:512])
    if m is None:
        raise SShaDeError(f"{name}: not a PLY of the DeFAUST builder (its header differs from the one "
                          "defaust.store.ply_bytes writes)")
    n, k, start = int(m[1]), int(m[2]), m.end()
    need = start + 24 * n + 13 * k
    if len(data) != need:
        raise SShaDeError(f"{name}: {len(data)} bytes, its header ({n} vertices, {k} faces) needs {need}")
    V = np.frombuffer(data, "<f8", 3 * n, start).reshape(n, 3).astype(np.float64)
    faces = np.frombuffer(data, [("n", "u1"), ("i", "<i4", (3,))], k, start + 24 * n)
    if k and (faces["n"] != 3).any():
        raise SShaDeError(f"{name}: face {int(np.flatnonzero(faces['n'] != 3)[0])} is not a triangle")
    F = faces["i"].astype(np.int64)
    if F.size and (F.min() < 0 or F.max() >= n):
        raise SShaDeError(f"{name}: face indices out of range (the mesh has {n} vertices)")
    return V, F


#: The header :func:`ply_bytes` writes, its two counts captured.
_PLY_HEADER = re.compile(rb"ply\nformat binary_little_endian 1\.0\nelement vertex (\d{1,10})\nproperty double x\n"
                         rb"property double y\nproperty double z\nelement face (\d{1,10})\n"
                         rb"property list uchar int vertex_indices\nend_header\n")


def write_ply(path, V, F) -> str:
    """Write :func:`ply_bytes` atomically and return the file's SHA-256 (hex).

    Examples
    --------
    Example::

        digest = write_ply("/tmp/t.ply", np.eye(3), [[0, 1, 2]])
    """
    data = ply_bytes(V, F)
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return sha256_bytes(data)


def write_npz(path, arrays: dict) -> str:
    """Write arrays as an uncompressed ``.npz`` with fixed member timestamps.

    Readable with :func:`numpy.load` (no pickles: object arrays are refused).

    Parameters
    ----------
    path : str or Path.
    arrays : dict name -> array_like, written in sorted name order.

    Returns
    -------
    str, SHA-256 (hex) of the written bytes.

    Raises
    ------
    SShaDeError if an array has dtype ``object``.

    Examples
    --------
    Example::

        digest = write_npz("/tmp/t.npz", {"a": np.arange(3)})
    """
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name in sorted(arrays):
            a = np.asanyarray(arrays[name])
            if a.dtype.hasobject:
                raise SShaDeError(f"write_npz: array {name!r} has dtype object; use fixed-width types")
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asarray(a, order="C"), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_DATE)
            info.external_attr = 0o644 << 16
            zf.writestr(info, member.getvalue())
    data = buf.getvalue()
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return sha256_bytes(data)


#: Default bound on one member of an ``.npz`` that :func:`read_npz` reads (uncompressed
#: bytes, the ``.npy`` header included).
MAX_MEMBER_BYTES = 1 << 30


def read_npz(path, keys=None, *, optional=(), max_bytes=MAX_MEMBER_BYTES, name=None) -> dict[str, np.ndarray]:
    """Read an ``.npz`` into a dict of arrays (no pickles), as untrusted input: the
    members' names and sizes are checked from the zip directory before any member is
    decompressed, and only the wanted members are read.

    Parameters
    ----------
    path : str or Path, or a seekable binary file object (an archive's member).
    keys : iterable of str, the arrays the file must hold; None reads every member.
    optional : iterable of str, arrays the file may hold besides ``keys`` (read when there).
        With ``keys`` given, any other member is refused.
    max_bytes : int, or dict name -> int, the largest uncompressed size in bytes (``.npy``
        header included) accepted for a member (default :data:`MAX_MEMBER_BYTES`).
    name : str or None, how messages name the file (default: ``path``).

    Returns
    -------
    dict name -> array (writable copies; names without the ``.npy`` suffix).

    Raises
    ------
    SShaDeError, one line naming the file and the member: a missing or unreadable file, an
    unexpected, missing, repeated or oversized member, a member that is not a ``.npy``
    array of a fixed-width dtype (object arrays are refused), or one whose data does not
    match its header's shape.

    Examples
    --------
    Example::

        d = read_npz("subject_00/pose_01_handles.npz", ["rest_positions"], optional=["seed"])
        d["rest_positions"].shape
        # -> (180, 3)
    """
    if hasattr(path, "read"):
        p, src = name or getattr(path, "name", "npz file"), path
    else:
        p = src = Path(path)
        if not p.is_file():
            raise SShaDeError(f"file not found: {p}")
        p = name or p
    try:
        with zipfile.ZipFile(src) as zf:
            members = _npz_members(p, zf, keys, optional)
            return {k: _read_member(p, zf, info, k, max_bytes) for k, info in members.items()}
    except SShaDeError:  # a ValueError too, already naming the file
        raise
    except (zipfile.BadZipFile, ValueError, EOFError, OSError, RuntimeError, NotImplementedError) as e:
        # RuntimeError: an encrypted member; NotImplementedError: an unknown compression
        raise SShaDeError(f"{p}: unreadable npz file ({type(e).__name__}: {e})") from None


def _npz_members(p, zf: zipfile.ZipFile, keys, optional) -> dict:
    """``{array name: ZipInfo}`` of the members to read, after checking the names."""
    infos = zf.infolist()
    names = [i.filename[:-4] if i.filename.endswith(".npy") else i.filename for i in infos]
    seen = set()
    for n in names:
        if n in seen:
            raise SShaDeError(f"{p}: member {n!r} appears twice")
        seen.add(n)
    if keys is not None:
        need, allowed = list(keys), set(keys) | set(optional)
        extra = [n for n in names if n not in allowed]
        if extra:
            raise SShaDeError(f"{p}: unexpected array {extra[0]!r} (expected {sorted(allowed)})")
        missing = [k for k in need if k not in seen]
        if missing:
            raise SShaDeError(f"{p}: missing array {missing[0]!r}")
    return dict(zip(names, infos))


def _read_member(p, zf: zipfile.ZipFile, info: zipfile.ZipInfo, name: str, max_bytes) -> np.ndarray:
    """One ``.npy`` member read after checking its declared size against ``max_bytes``;
    zipfile stops at the declared size and checks the CRC, so no more is decompressed."""
    cap = max_bytes.get(name, MAX_MEMBER_BYTES) if isinstance(max_bytes, dict) else max_bytes
    if info.file_size > cap:
        raise SShaDeError(f"{p}: array {name!r} is {info.file_size} bytes uncompressed, more than the "
                          f"{cap} bytes it may have")
    with zf.open(info) as fh:
        data = fh.read(info.file_size + 1)
    fh = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(fh)
        if version not in ((1, 0), (2, 0)):
            raise ValueError(f".npy version {version}, not 1.0 or 2.0")
        read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read(fh)
    except ValueError as e:
        raise SShaDeError(f"{p}: array {name!r} is not a readable .npy array ({e})") from None
    if dtype.hasobject:
        raise SShaDeError(f"{p}: array {name!r} has dtype object (pickles are refused)")
    start, count = fh.tell(), math.prod(shape)
    if dtype.itemsize == 0 or len(data) - start != count * dtype.itemsize:
        raise SShaDeError(f"{p}: array {name!r} holds {len(data) - start} data bytes, its header "
                          f"({dtype}, shape {shape}) needs {count * dtype.itemsize}")
    a = np.frombuffer(data, dtype=dtype, count=count, offset=start)
    a = a.reshape(shape[::-1]).T if fortran else a.reshape(shape)
    return a.copy(order="K")


def sha256_bytes(data: bytes) -> str:
    """SHA-256 hex digest of ``data``.

    Examples
    --------
    >>> sha256_bytes(b"")[:8]
    'e3b0c442'
    """
    return hashlib.sha256(data).hexdigest()


def sha256_stream(fh, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest of what remains to be read from the binary file object ``fh``.

    Examples
    --------
    >>> sha256_stream(io.BytesIO(b""))[:8]
    'e3b0c442'
    """
    h = hashlib.sha256()
    for block in iter(lambda: fh.read(chunk), b""):
        h.update(block)
    return h.hexdigest()


def sha256_file(path, chunk: int = 1 << 20) -> str | None:
    """SHA-256 hex digest of a file, or ``None`` if it does not exist.

    Examples
    --------
    >>> sha256_file("/nonexistent") is None
    True
    """
    p = Path(path)
    if not p.is_file():
        return None
    with open(p, "rb") as fh:
        return sha256_stream(fh, chunk)

"""Handle files of the field, read into ``(handles, targets)`` for a mesh of ``n`` vertices:
Botsch & Sorkine's deformation benchmark (IEEE TVCG 2008: ``.sel`` per-vertex status and
``.def`` 4x4 matrix), libigl's tutorial ``.dmat`` selection (with a ``.def``), and
``.json`` / ``.csv`` of vertex indices and target positions (mesh units).

Every reader raises :class:`SShaDeError` with one line naming the file and the problem.
The formats in detail: docs/implementation.md ("Implementation notes: sshade/mesh/handle_files.py").
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from ..errors import SShaDeError
from ..files import atomic_write
from ..json_file import regular_file
from .validate import validate_handles

__all__ = ["read_sel", "read_dmat_selection", "read_def", "apply_def", "selection_handles", "read_handle_file",
           "write_sel", "write_def", "FIXED", "FREE", "HANDLE", "check_affine", "read_moving_handles"]

#: Per-vertex status codes (those of the ``.sel`` format).
FIXED, FREE, HANDLE = 0, 1, 2


#: Largest handle file read (bytes): a selection or handle list of a mesh of n vertices
#: needs far less than 64 MiB + 256 bytes per vertex; a .def holds 16 numbers.
MAX_BYTES, PER_VERTEX_BYTES, MAX_DEF_BYTES = 64 << 20, 256, 1 << 16


def _check_size(p: Path, what: str, limit: int) -> None:
    """Refuse a file larger than ``limit`` bytes before reading it."""
    size = p.stat().st_size
    if size > limit:
        raise SShaDeError(f"{p}: {size} bytes is too large for a {what} file (at most {limit} here); "
                          "is it the right file?")


def _text_lines(path, what: str, limit: int = MAX_BYTES) -> list[tuple[int, str]]:
    """(line number, stripped text) of the non-empty, non-comment lines of a text file
    of at most ``limit`` bytes."""
    p = regular_file(path, f"{what} file")
    _check_size(p, what, limit)
    try:
        text = p.read_text(encoding="utf-8-sig")  # a byte-order mark is not text
    except (OSError, UnicodeDecodeError) as e:
        raise SShaDeError(f"{p}: unreadable {what} file ({type(e).__name__})") from None
    return [(i, s) for i, ln in enumerate(text.splitlines(), 1) if (s := ln.strip()) and not s.startswith("#")]


def read_sel(path, n: int) -> np.ndarray:
    """Per-vertex status of a ``.sel`` file (deformation benchmark; the format:
    docs/implementation.md, "Implementation notes: sshade/mesh/handle_files.py").

    Parameters
    ----------
    path : str or Path. n : int, the mesh's vertex count.

    Returns
    -------
    (n,) int8 status: :data:`FIXED` (0), :data:`FREE` (1), :data:`HANDLE` (2).

    Raises
    ------
    SShaDeError naming the file: missing or unreadable, a line that is not one of 0, 1,
    2, a number of values other than ``n``, or neither a fixed nor a handle vertex.
    """
    rows = _text_lines(path, ".sel", MAX_BYTES + PER_VERTEX_BYTES * n)
    vals = np.empty(len(rows), np.int8)
    for k, (i, s) in enumerate(rows):
        if s not in ("0", "1", "2"):
            raise SShaDeError(f"{path}: line {i} is {s[:40]!r}; a .sel line is 0 (fixed), 1 (free) or 2 (handle)")
        vals[k] = int(s)
    if len(vals) != n:
        raise SShaDeError(f"{path}: {len(vals)} vertex values but the mesh has {n} vertices")
    if not (vals != FREE).any():
        raise SShaDeError(f"{path}: every vertex is free (1); mark fixed (0) or handle (2) vertices")
    return vals


def read_dmat_selection(path, n: int) -> np.ndarray:
    """Per-vertex status from a libigl ``.dmat`` selection (the format: docs/implementation.md,
    "Implementation notes: sshade/mesh/handle_files.py"), in the ``.sel`` codes: ``-1`` ->
    :data:`FREE`, ``0`` -> :data:`FIXED`, ``>= 1`` -> :data:`HANDLE`.

    Parameters
    ----------
    path : str or Path (ASCII or binary ``.dmat``, libigl's ``readDMAT`` formats).
    n : int, the mesh's vertex count.

    Returns
    -------
    (n,) int8 status codes.

    Raises
    ------
    SShaDeError naming the file: missing or unreadable, not one value per vertex (an
    (n, 1) or (1, n) matrix), values that are not integers >= -1 or not finite, or no
    fixed and no handle vertex.
    """
    p = regular_file(path, ".dmat file")
    _check_size(p, ".dmat", MAX_BYTES + PER_VERTEX_BYTES * n)
    S = _read_dmat(p)
    if S.ndim != 2 or 1 not in S.shape or S.size != n:
        raise SShaDeError(f"{p}: a selection needs one value per vertex ({n}), got a {S.shape[0]}x{S.shape[1]} "
                          "matrix" if S.ndim == 2 else f"{p}: unreadable .dmat file")
    S = S.ravel()
    if not np.isfinite(S).all():
        raise SShaDeError(f"{p}: NaN/inf in the selection (first: vertex {int(np.flatnonzero(~np.isfinite(S))[0])})")
    bad = (S != np.round(S)) | (S < -1)
    if bad.any():
        v = int(np.flatnonzero(bad)[0])
        raise SShaDeError(f"{p}: vertex {v} has selection value {S[v]:g}; use -1 (free), 0 (fixed) or >= 1 (handle)")
    out = np.where(S < 0, FREE, np.where(S == 0, FIXED, HANDLE)).astype(np.int8)
    if not (out != FREE).any():
        raise SShaDeError(f"{p}: every vertex is free (-1); mark fixed (0) or handle (>= 1) vertices")
    return out


def _read_dmat(p: Path) -> np.ndarray:
    """(rows, cols) float64 of a libigl ``.dmat``: ASCII ``ncols nrows`` then the values
    column by column, or binary (``0 0`` line, ``ncols nrows`` line, little-endian
    doubles). Counts are checked against the file before anything is allocated; no
    native reader runs (libigl's prints on stderr)."""
    data = p.read_bytes()
    lines = data.split(b"\n", 2)
    head = lines[0].split()

    def dims(toks):
        if len(toks) != 2 or not all(t.isdigit() for t in toks):
            raise SShaDeError(f"{p}: unreadable .dmat file (no 'ncols nrows' header)")
        return int(toks[1]), int(toks[0])
    rows, cols = dims(head)
    if rows == 0 and cols == 0 and len(lines) == 3:  # binary variant
        rows, cols = dims(lines[1].split())
        body = lines[2]
        if len(body) != 8 * rows * cols:
            raise SShaDeError(f"{p}: unreadable .dmat file (header says {cols}x{rows} doubles, "
                              f"{len(body)} bytes follow)")
        return np.frombuffer(body, "<f8").reshape(cols, rows).T.astype(np.float64)
    toks = data.split(b"\n", 1)[1].split() if len(lines) > 1 else []
    if len(toks) != rows * cols:
        raise SShaDeError(f"{p}: unreadable .dmat file (header says {cols}x{rows} values, {len(toks)} found)")
    try:
        vals = np.array([float(t) for t in toks], np.float64)
    except ValueError:
        bad = next(t for t in toks if not _is_float(t))
        raise SShaDeError(f"{p}: unreadable .dmat file (value {repr(bad[:30])[1:]} is not a number)") from None
    return vals.reshape(cols, rows).T


def _is_float(t: bytes) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def read_def(path) -> np.ndarray:
    """The 4x4 handle transformation of a ``.def`` file (the format:
    docs/implementation.md, "Implementation notes: sshade/mesh/handle_files.py").

    Returns
    -------
    (4, 4) float64 M, acting on homogeneous column vectors: ``p' = M[:3, :3] p + M[:3, 3]``.

    Raises
    ------
    SShaDeError naming the file: missing or unreadable, not 4 rows of 4 numbers, NaN/inf,
    a last row other than ``0 0 0 1`` (not affine), or a singular 3x3 part
    (non-invertible: it would flatten the handle).
    """
    rows = _text_lines(path, ".def", MAX_DEF_BYTES)
    try:
        M = np.array([[float(x) for x in s.split()] for _, s in rows], np.float64)
    except ValueError as e:
        raise SShaDeError(f"{path}: not a 4x4 matrix of numbers ({e})") from None
    if M.shape != (4, 4):
        raise SShaDeError(f"{path}: a .def file holds a 4x4 matrix (4 lines of 4 numbers), got "
                          f"{[len(s.split()) for _, s in rows]} numbers per line")
    return check_affine(M, str(path))


def check_affine(M: np.ndarray, where: str) -> np.ndarray:
    """Check a (4, 4) float64 matrix as a handle transformation: finite, last row
    ``0 0 0 1`` (affine), invertible 3x3 part (scale-free test). Returns ``M``.

    Raises
    ------
    SShaDeError naming ``where`` (a file, a frame) on any of these.

    Examples
    --------
    >>> check_affine(np.eye(4), "frame 0").shape
    (4, 4)
    """
    if not np.isfinite(M).all():
        raise SShaDeError(f"{where}: the matrix has NaN/inf entries")
    if not np.allclose(M[3], [0, 0, 0, 1], rtol=0, atol=1e-12):
        raise SShaDeError(f"{where}: last row is {M[3].tolist()}, not [0, 0, 0, 1]: only affine transformations "
                          "are supported")
    A = M[:3, :3]
    s = float(np.abs(A).max())
    det = float(np.linalg.det(A / s)) if s > 0 else 0.0  # scale-free: a 1e200 scaling is not singular
    if abs(det) <= 1e-12:
        raise SShaDeError(f"{where}: the 3x3 part of the matrix is singular (det {det:.3g} after scaling to max 1): "
                          "a non-invertible transformation would flatten the handle")
    return M


def apply_def(M: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(k, 3) float64 ``P`` mapped by the 4x4 affine ``M``: ``P @ M[:3, :3].T + M[:3, 3]``."""
    return np.asarray(P, np.float64) @ M[:3, :3].T + M[:3, 3]


def selection_handles(V: np.ndarray, status: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Handles and targets of a per-vertex selection: fixed vertices stay at their rest
    positions, handle vertices move by ``M``, free vertices are not handles.

    Parameters
    ----------
    V : (n, 3) float64 rest positions; status : (n,) codes (:data:`FIXED`, :data:`FREE`,
    :data:`HANDLE`); M : (4, 4) float64 affine matrix (:func:`read_def`).

    Returns
    -------
    handles : (h,) int64 sorted vertex indices; targets : (h, 3) float64.
    """
    handles = np.flatnonzero(np.asarray(status) != FREE).astype(np.int64)
    targets = np.array(V[handles], np.float64)
    moved = status[handles] == HANDLE
    targets[moved] = apply_def(M, targets[moved])
    return handles, targets


def read_moving_handles(n: int, *, sel=None, dmat=None, handles=None) -> tuple[np.ndarray, np.ndarray]:
    """The handle vertices of one handle source and which of them a motion moves.

    Parameters
    ----------
    n : int, the mesh's vertex count. sel, dmat : path of a ``.sel`` / ``.dmat`` selection
        (its fixed and handle vertices are the handles, the handle ones move); handles :
        path of a ``.json`` / ``.csv`` handle file (every handle moves; its targets are not
        used). The first of ``sel``, ``dmat``, ``handles`` given is read.

    Returns
    -------
    handles : (h,) int64 (a selection's in increasing order, a file's in its order);
    moved : (h,) bool.

    Raises
    ------
    SShaDeError on a bad file (as :func:`read_sel`, :func:`read_dmat_selection`,
    :func:`read_handle_file`).
    """
    if sel or dmat:
        status = read_sel(sel, n) if sel else read_dmat_selection(dmat, n)
        h = np.flatnonzero(status != FREE).astype(np.int64)
        return h, status[h] == HANDLE
    h, _ = read_handle_file(handles, n)
    return h, np.ones(len(h), bool)


def read_handle_file(path, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Handles and targets of a ``.json`` or ``.csv`` file (the formats:
    docs/implementation.md, "Implementation notes: sshade/mesh/handle_files.py").

    Parameters
    ----------
    path : str or Path. n : int, the mesh's vertex count.

    Returns
    -------
    handles : (h,) int64; targets : (h, 3) float64 (mesh units).

    Raises
    ------
    SShaDeError naming the file: missing or unreadable, another extension, a missing
    key or column, non-integer indices, and every problem of
    :func:`sshade.mesh.validate.validate_handles` (index out of range, duplicates, NaN, ...).
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in (".json", ".csv"):
        raise SShaDeError(f"{p}: handle file must be .json or .csv, got {ext or 'no extension'!r}")
    regular_file(p, "handle file")
    try:
        if ext == ".json":
            h, T = _json_handles(p, n)
        else:
            h, T = _csv_handles(p, n)
        return validate_handles(np.zeros((n, 3)), h, T)  # the target scale is checked against the mesh later
    except SShaDeError as e:
        msg = str(e)
        raise SShaDeError(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None


def _json_handles(p: Path, n: int):
    _check_size(p, "handle", MAX_BYTES + PER_VERTEX_BYTES * n)
    try:
        d = json.loads(p.read_text(encoding="utf-8-sig"))
    except RecursionError:
        raise SShaDeError(f"{p}: unreadable JSON (nested too deeply)") from None
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise SShaDeError(f"{p}: unreadable JSON ({' '.join(str(e).split())})") from None
    if not isinstance(d, dict) or "handles" not in d or "targets" not in d:
        raise SShaDeError(f"{p}: expected an object with keys \"handles\" (vertex indices) and \"targets\" "
                          "(one [x, y, z] per handle)")
    h, T = d["handles"], d["targets"]
    if not isinstance(h, list) or not all(isinstance(i, int) and not isinstance(i, bool) for i in h):
        raise SShaDeError(f"{p}: \"handles\" must be a list of integer vertex indices")
    _check_indices(p, h, n)
    if not isinstance(T, list) or not all(isinstance(t, list) and len(t) == 3 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in t) for t in T):
        raise SShaDeError(f"{p}: \"targets\" must be a list of [x, y, z] numbers")
    try:
        T = np.array(T, np.float64).reshape(-1, 3)
    except OverflowError:
        raise SShaDeError(f"{p}: a target coordinate overflows float64 (|x| > 1.8e308)") from None
    return np.array(h, np.int64), T


def _check_indices(p: Path, h, n: int) -> None:
    """Refuse an index outside [0, n) while it is still a Python int (no int64 overflow)."""
    for i in h:
        if not 0 <= i < n:
            shown = str(i) if len(str(i)) < 30 else f"{str(i)[:12]}...({len(str(i))} digits)"
            raise SShaDeError(f"{p}: handle index {shown} is out of range [0, {n}) (handle off the surface)")


def _csv_handles(p: Path, n: int):
    _check_size(p, "handle", MAX_BYTES + PER_VERTEX_BYTES * n)
    try:
        with open(p, newline="", encoding="utf-8-sig") as fh:  # a byte-order mark is not a cell
            rows = [(i, r) for i, r in enumerate(csv.reader(fh), 1) if r and any(c.strip() for c in r)
                    and not r[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise SShaDeError(f"{p}: unreadable CSV ({type(e).__name__}: {e})") from None
    if rows and [c.strip().lower() for c in rows[0][1]] == ["index", "x", "y", "z"]:
        rows = rows[1:]
    h, T = [], []
    for i, r in rows:
        if len(r) != 4:
            raise SShaDeError(f"{p}: line {i} has {len(r)} fields; rows are index,x,y,z")
        try:
            h.append(int(r[0]))
        except ValueError:
            raise SShaDeError(f"{p}: line {i}: vertex index {r[0].strip()!r} is not an integer") from None
        try:
            T.append([float(x) for x in r[1:]])
        except ValueError:
            raise SShaDeError(f"{p}: line {i}: target {r[1:]} is not three numbers") from None
    _check_indices(p, h, n)
    return np.array(h, np.int64), np.array(T, np.float64).reshape(-1, 3)


def write_sel(path, status) -> None:
    """Write a ``.sel`` file atomically: the benchmark's two comment lines, then one
    status per line. ``status`` : (n,) ints in {0 fixed, 1 free, 2 handle}.
    Raises SShaDeError on another value."""
    st = np.asarray(status).ravel()
    if not np.isin(st, (FIXED, FREE, HANDLE)).all():
        raise SShaDeError("a .sel status is 0 (fixed), 1 (free) or 2 (handle)")
    with atomic_write(path) as fh:
        fh.write(f"# per vertex status: 0=fixed, 1=deformable-region, 2=handle\n# {len(st)} vertices\n")
        fh.write("\n".join(str(int(x)) for x in st) + "\n")


def write_def(path, M) -> None:
    """Write a ``.def`` file atomically: a comment line, then the (4, 4) matrix ``M``,
    row by row, each value with 17 significant digits (exact round trip)."""
    M = np.asarray(M, np.float64).reshape(4, 4)
    with atomic_write(path) as fh:
        fh.write("# 4x4 handle transformation matrix\n")
        fh.write("".join(" ".join(f"{x:.17g}" for x in row) + "\n" for row in M))

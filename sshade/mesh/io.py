"""Reading and writing triangle meshes with clear errors: the dispatch by extension to
one module per format, each holding its reader, its writer (if written) and their tables:
:mod:`~sshade.mesh.obj`, :mod:`~sshade.mesh.off`, :mod:`~sshade.mesh.ply` (the three
written) and :mod:`~sshade.mesh.stl` (read only), with the text-row helpers they share in
:mod:`~sshade.mesh.text_rows`. A new format is its module and its entry in :data:`FORMATS`.
Files are written atomically (:func:`sshade.files.atomic_write`).

Generic mesh I/O of every layer (the DeFAUST builder, the evaluator, ``python -m sshade
deform``); the geometry core (remesh, ARAP, transfer) never reads or writes files.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import SShaDeError
from ..files import atomic_write
from ..json_file import regular_file
from . import obj, off, ply, stl
from .text_rows import short_error
from .validate import validate_mesh

__all__ = ["read_mesh", "write_mesh", "written_by_sshade", "SIGNATURE", "FORMATS", "READERS", "PREFIX_CHECKS",
           "WRITERS", "SIGNED"]

#: The format modules, each with its tables (extension -> function), merged below into
#: the dispatch: ``READERS``, ``PREFIX_CHECKS``, ``WRITERS`` and ``SIGNED`` (empty for a
#: format read only).
FORMATS = (obj, off, ply, stl)
#: extension -> reader: (the file's bytes, its path) -> (V, F)
READERS = {ext: f for m in FORMATS for ext, f in m.READERS.items()}
#: extension -> check of the first :data:`PREFIX_BYTES` bytes, before the rest is read
PREFIX_CHECKS = {ext: f for m in FORMATS for ext, f in m.PREFIX_CHECKS.items()}
#: extension -> writer: (V, F, signature comment) -> the file's bytes
WRITERS = {ext: f for m in FORMATS for ext, f in m.WRITERS.items()}
#: extension -> whether a file's first bytes carry the writer's comment: (head, comment) -> bool
SIGNED = {ext: f for m in FORMATS for ext, f in m.SIGNED.items()}
#: The bytes of a mesh file read and checked before the rest (:data:`PREFIX_CHECKS`): a
#: file that is no such file, or larger than its header promises, is refused unread.
PREFIX_BYTES = 1 << 16
#: The comment every file :func:`write_mesh` writes carries (:func:`written_by_sshade`).
SIGNATURE = "written by sshade"


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
    if ext not in READERS:
        raise SShaDeError(f"{p}: unsupported mesh format {ext!r} (use one of {sorted(READERS)})")
    try:
        with open(p, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            PREFIX_CHECKS[ext](fh.read(PREFIX_BYTES), size, p)  # before the rest is read: bounded by the header
            fh.seek(0)
            data = fh.read()
    except OSError as e:
        raise SShaDeError(f"{p}: unreadable mesh file ({e.strerror or type(e).__name__})") from None
    # pure-Python/numpy readers: a truncated or lying file is an SShaDeError, never a
    # native abort (libigl's readers double-free on some of them) nor a huge allocation
    try:
        V, F = READERS[ext](data, p)
    except SShaDeError:
        raise
    except (ValueError, IndexError, KeyError, OverflowError, TypeError, MemoryError) as e:
        raise SShaDeError(f"{p}: unreadable {ext[1:].upper()} file (malformed: {short_error(e)})") from None
    V = np.ascontiguousarray(V, dtype=np.float64).reshape(-1, 3)
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    if len(V) == 0 or len(F) == 0:
        raise SShaDeError(f"{p}: unreadable mesh file (no vertices or no faces found)")
    if validate:
        V, F = validate_mesh(V, F, name=str(p), allow_components=allow_components)
    return V, F


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
    if ext not in WRITERS:
        raise SShaDeError(f"{path}: unsupported output mesh format {ext!r}")
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3:
        raise SShaDeError(f"{path}: cannot write V {V.shape} and F {F.shape}; expected (n, 3) and (m, 3)")
    if F.size and (F.min() < 0 or F.max() >= max(len(V), 1) or F.max() > np.iinfo(np.int32).max):
        raise SShaDeError(f"{path}: face indices outside [0, {len(V)})")
    data = WRITERS[ext](V, F, SIGNATURE)
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def written_by_sshade(path) -> bool:
    """True if ``path`` is a mesh file that :func:`write_mesh` wrote (its signature
    comment is in the file's header: first line of an OBJ, second of an OFF, a PLY
    ``comment`` line). False for any other file, a missing one or a folder."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(512)
    except OSError:
        return False
    signed = SIGNED.get(Path(path).suffix.lower())
    return signed is not None and signed(head, SIGNATURE)

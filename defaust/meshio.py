"""Reading and writing triangle meshes (OBJ, OFF, PLY, STL) with clear errors and
atomic writes.

File formats live here (the data stage), not in the geometry core.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError

__all__ = ["read_mesh", "write_mesh", "atomic_write"]

_EXTS = {".obj", ".off", ".ply", ".stl"}


def read_mesh(path, *, validate: bool = True, allow_components: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh.

    Parameters
    ----------
    path : str or Path, an ``.obj``, ``.off``, ``.ply`` or ``.stl`` file.
    validate : bool, run :func:`sshade.validate.validate_mesh` on the result.
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
        :func:`~sshade.validate.validate_mesh` names.

    Examples
    --------
    >>> V, F = read_mesh("../shared/data/classic/bunny.off")  # doctest: +SKIP
    """
    p = Path(path)
    if not p.is_file():
        raise SShaDeError(f"mesh file not found: {p}")
    ext = p.suffix.lower()
    if ext not in _EXTS:
        raise SShaDeError(f"{p}: unsupported mesh format {ext!r} (use one of {sorted(_EXTS)})")
    _check_polygon_faces(p, ext)
    try:
        if ext == ".stl":
            # STL is a triangle soup: merge coincident vertices to recover connectivity
            import trimesh
            tm = trimesh.load(str(p), file_type="stl", process=True, force="mesh")
            V, F = np.asarray(tm.vertices), np.asarray(tm.faces)
        else:
            import igl
            V, F = igl.read_triangle_mesh(str(p))
    except Exception as e:  # libigl raises RuntimeError/ValueError on garbage
        raise SShaDeError(f"{p}: unreadable mesh file ({type(e).__name__}: {e})") from None
    V = np.ascontiguousarray(V, dtype=np.float64)
    F = np.ascontiguousarray(F, dtype=np.int64)
    if V.size == 0 or F.size == 0 or V.ndim != 2 or F.ndim != 2:
        raise SShaDeError(f"{p}: unreadable mesh file (no vertices or no faces found)")
    if F.shape[1] != 3:
        raise SShaDeError(f"{p}: faces have {F.shape[1]} vertices; only triangle meshes are supported")
    if validate:
        from sshade.validate import validate_mesh
        V, F = validate_mesh(V, F, name=str(p), allow_components=allow_components)
    return V, F


def _data_lines(p: Path):
    """Lines of a text mesh file with comments and blank lines removed, split in tokens."""
    with open(p, "rb") as fh:
        for i, line in enumerate(fh, 1):
            toks = line.split(b"#", 1)[0].split()
            if toks:
                yield i, toks


def _check_polygon_faces(p: Path, ext: str) -> None:
    """libigl would fan-triangulate polygons silently; refuse them instead."""
    try:
        if ext == ".obj":
            for i, toks in _data_lines(p):
                if toks[0] == b"f" and len(toks) != 4:
                    raise SShaDeError(f"{p}: line {i} is a face with {len(toks) - 1} vertices; "
                                      "only triangle meshes are supported")
        elif ext == ".off":
            it = _data_lines(p)
            _, toks = next(it)
            if toks[0].upper().endswith(b"OFF"):
                toks = toks[1:]
                if not toks:
                    _, toks = next(it)
            nv, nf = int(toks[0]), int(toks[1])
            for _ in range(nv):
                next(it)
            for j in range(nf):
                i, toks = next(it)
                if int(toks[0]) != 3:
                    raise SShaDeError(f"{p}: face {j} (line {i}) has {int(toks[0])} vertices; "
                                      "only triangle meshes are supported")
    except SShaDeError:
        raise
    except (StopIteration, ValueError, IndexError) as e:
        raise SShaDeError(f"{p}: unreadable {ext[1:].upper()} file (truncated or malformed: {e!r})") from None


@contextlib.contextmanager
def atomic_write(path, mode: str = "w", **kw):
    """Open a temporary file beside ``path`` and rename it onto ``path`` on success.

    Nothing half-written is ever left at ``path``: on an exception the temporary file is
    removed and ``path`` keeps its previous content (or stays absent).

    Examples
    --------
    >>> with atomic_write("/tmp/x.txt") as fh:  # doctest: +SKIP
    ...     fh.write("hello")
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode, **kw) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_mesh(path, V: np.ndarray, F: np.ndarray) -> None:
    """Write a triangle mesh atomically (format from the extension: .obj, .off, .ply),
    without losing precision: libigl's writers (OBJ and OFF as text with 17 significant
    digits, PLY as binary little-endian doubles), so :func:`read_mesh` gives ``V`` back
    bit for bit.

    Parameters
    ----------
    path : str or Path.
    V : (n, 3) float64; F : (m, 3) int.

    Raises
    ------
    SShaDeError on an unsupported extension; OSError if the file cannot be written
    (``path`` then keeps its previous content, :func:`atomic_write`).
    """
    import igl
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in {".obj", ".off", ".ply"}:
        raise SShaDeError(f"{path}: unsupported output mesh format {ext!r}")
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    with tempfile.TemporaryDirectory() as tmp:  # libigl writes a path: render there, then move atomically
        t = Path(tmp) / f"mesh{ext}"
        enc = igl.FileEncoding.Binary if ext == ".ply" else igl.FileEncoding.Ascii
        igl.write_triangle_mesh(str(t), V, F, enc)
        data = t.read_bytes()
    with atomic_write(path, "wb") as fh:
        fh.write(data)

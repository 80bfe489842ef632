"""``python -m defaust pack BUILD -o ARCHIVE`` (:func:`pack`): a DeFAUST build as one zip
archive to hand on, in one folder ``DeFAUST-<source>/``: the build's ``manifest.json`` byte
for byte, ``croissant.json`` (:mod:`defaust.croissant`), ``DATASHEET.md``
(:mod:`defaust.datasheet`) and every file the manifest lists, stored uncompressed with
fixed dates and permissions in a fixed order (the same build gives the same bytes). The
build is verified first and each file's sha256 checked again as it is copied; the archive
obeys the harness's output rules and is written atomically. :func:`defaust.load` reads it
in place (:class:`defaust.archive.ArchiveBuild`). docs/defaust.md §7.
"""
from __future__ import annotations

import hashlib
import re
import zipfile
from pathlib import Path

from sshade.errors import SShaDeError
from sshade.files import atomic_write, inside_folder

from .archive import PACK_COMMENT
from .croissant import CROISSANT, croissant_text
from .dataset import read_manifest, verify
from .datasheet import DATASHEET, datasheet
from .manifest import MANIFEST
from .store import sha256_bytes, sha256_file

__all__ = ["pack", "check_pack_output", "is_pack"]

_ZIP_DATE = (1980, 1, 1, 0, 0, 0)
_CHUNK = 1 << 20


def is_pack(path) -> bool:
    """``path`` is a zip archive that :func:`pack` wrote (its comment says so).

    Examples
    --------
    >>> is_pack("/nonexistent.zip")
    False
    """
    try:
        with zipfile.ZipFile(path) as zf:
            return zf.comment.startswith(PACK_COMMENT)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError):
        return False


def check_pack_output(root, out, *, force: bool = False) -> None:
    """Refuse ``out`` before anything is read or written: a folder, a link, a path
    inside the build ``root`` (or ``root`` itself), a folder that does not exist, or an
    existing file that is not an earlier pack (unless ``force``).

    Raises
    ------
    SShaDeError, one line naming ``out`` and what to do.
    """
    root, out = Path(root).expanduser(), Path(out).expanduser()
    if out.is_symlink():
        raise SShaDeError(f"refusing to write {out}: it is a link; give the archive's own path")
    if out.is_dir():
        raise SShaDeError(f"refusing to write {out}: it is a folder; give a file path (e.g. {out / 'defaust.zip'})")
    r, o = root.resolve(), out.resolve()
    if o == r or r in o.parents:
        raise SShaDeError(f"refusing to write {out}: it is inside the DeFAUST build {root}; choose a path outside it")
    if not out.parent.is_dir():
        raise SShaDeError(f"refusing to write {out}: its folder {out.parent} does not exist")
    if out.exists() and not force and not is_pack(out):
        raise SShaDeError(f"refusing to replace {out}: it exists and is not an archive `python -m defaust pack` wrote; "
                          "choose another -o path (or pass --force to replace it)")


def _top_folder(m: dict) -> str:
    """The archive's folder: ``DeFAUST-<source>`` (one safe path component)."""
    src = re.sub(r"[^A-Za-z0-9_.-]", "_", str(m.get("source", "")))
    name = f"DeFAUST-{src}" if src else "DeFAUST"
    return name if name not in (".", "..") else "DeFAUST"


def _info(name: str, size: int) -> zipfile.ZipInfo:
    """A stored member with a fixed date and permissions (deterministic bytes)."""
    info = zipfile.ZipInfo(name, date_time=_ZIP_DATE)
    info.compress_type, info.create_system = zipfile.ZIP_STORED, 3
    info.external_attr = 0o100644 << 16  # a regular file, rw-r--r--
    info.file_size = size
    return info


def _copy(zf: zipfile.ZipFile, name: str, path: Path, want: str) -> int:
    """Copy the build's file ``path`` into the member ``name``, checking its sha256 on the
    way (it may have changed since the build was verified); returns its size."""
    size = path.stat().st_size
    h = hashlib.sha256()
    with open(path, "rb") as src, zf.open(_info(name, size), "w") as dst:
        for block in iter(lambda: src.read(_CHUNK), b""):
            h.update(block)
            dst.write(block)
    if h.hexdigest() != want:
        raise SShaDeError(f"{path}: changed while it was packed (its sha256 differs from {MANIFEST}); pack again")
    return size


def pack(root, out, *, force: bool = False) -> dict:
    """Write the DeFAUST build folder ``root`` as one zip archive ``out``.

    Parameters
    ----------
    root : str or Path, a build folder (``out=`` of ``python -m defaust``).
    out : str or Path, the archive to write (:func:`check_pack_output`).
    force : bool, replace an existing file that is not an earlier pack.

    Returns
    -------
    dict: ``path`` (Path of the archive), ``folder`` (its top folder), ``files`` (int,
    members written), ``bytes`` (int, the archive's size), ``sha256`` (hex, of the
    archive), ``manifest_sha256`` (hex).

    Raises
    ------
    SShaDeError, one line: ``root`` is not a build folder, ``out`` is refused, or the
    build has a problem (:func:`defaust.verify`, the first one named); OSError when the
    archive cannot be written (nothing is left at ``out`` then).

    Example::

        info = pack("data/defaust", "defaust-anny.zip")
        info["files"], info["bytes"]
    """
    root, out = Path(root).expanduser(), Path(out).expanduser()
    if root.is_file():
        raise SShaDeError(f"pack takes a DeFAUST build folder; {root} is a file")
    if not root.is_dir():
        raise SShaDeError(f"DeFAUST folder not found: {root}")
    check_pack_output(root, out, force=force)
    problems = verify(root)
    if problems:
        raise SShaDeError(f"refusing to pack {root}: {len(problems)} problem(s), the first: {problems[0]} "
                          f"(`python -m defaust verify {root}` lists them)")
    m = read_manifest(root)
    manifest = (root / MANIFEST).read_bytes()
    sha = sha256_bytes(manifest)
    top = _top_folder(m)
    texts = {MANIFEST: manifest, CROISSANT: croissant_text(m, manifest_sha256=sha).encode(),
             DATASHEET: datasheet(m, manifest_sha256=sha).encode()}
    files = m["files"]
    with atomic_write(out, "wb") as fh, zipfile.ZipFile(fh, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
        for name, data in texts.items():
            zf.writestr(_info(f"{top}/{name}", len(data)), data)
        for rel in sorted(files):
            _copy(zf, f"{top}/{rel}", inside_folder(root, rel, "DeFAUST build"), files[rel])
        zf.comment = PACK_COMMENT + b" manifest.json sha256 " + sha.encode()
    return {"path": out, "folder": top, "files": len(texts) + len(files), "bytes": out.stat().st_size,
            "sha256": sha256_file(out), "manifest_sha256": sha}


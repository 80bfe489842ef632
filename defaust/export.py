"""A DeFAUST build written for tools outside this harness (:func:`export`): one file set per
case, NumPy's ``.npz`` or meshes (``.obj`` / ``.ply``) with the handles in a JSON beside
them, holding the cases :func:`defaust.dataset.load` gives (handles snapped, targets moved:
what the evaluator deforms), and ``export.json`` (:data:`MARKER`: the settings, the build's
manifest sha256, each file's sha256). It writes only into a new or empty folder or an
earlier export; anything else is refused before any file is read. The fields:
docs/defaust.md §6, "Export".

Example::

    files = export("data/defaust", "outputs/defaust_npz", fmt="npz", resolution="low")
"""
from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError
from sshade.files import atomic_write, inside_folder
from sshade.json_file import read_json
from sshade.mesh.io import write_mesh

from .croissant import CROISSANT
from .dataset import Case, FolderBuild, load, open_build, read_manifest
from .hf_export import arrow_schema, write_shards, write_shards_croissant
from .manifest import MANIFEST
from .resolutions import check_resolution
from .store import sha256_bytes, sha256_file

__all__ = ["FORMATS", "MARKER", "KIND", "export", "check_export_folder", "case_arrays"]

#: The export formats: one ``<case>.npz`` per case, or ``<case>.obj|ply`` (rest mesh),
#: ``<case>_gt.obj|ply`` (true pose, when the case has one) and ``<case>_handles.json``;
#: or ``hf``: Parquet shards of every case for HuggingFace ``datasets`` (:mod:`defaust.hf_export`).
FORMATS = ("npz", "obj", "ply", "hf")
#: The file that marks a folder as this exporter's output.
MARKER = "export.json"
#: ``kind`` of :data:`MARKER`.
KIND = "defaust-export"


def check_export_folder(root: Path, to: Path) -> None:
    """Refuse an export folder ``to`` that holds anything but an earlier export, or that
    is the build ``root`` or lies inside it.

    Raises
    ------
    SShaDeError naming the folder and what to do.
    """
    root, to = Path(root).expanduser().resolve(), Path(to).expanduser().resolve()
    if to == root or root in to.parents:
        raise SShaDeError(f"refusing to export into {to}: it is inside the DeFAUST build {root}; "
                          "choose a folder outside it")
    if to.exists() and not to.is_dir():
        raise SShaDeError(f"refusing to export into {to}: it is a file; choose a folder")
    if not to.exists() or not any(to.iterdir()):
        return
    marker = to / MARKER
    try:
        kind = read_json(marker).get("kind") if marker.is_file() else None
    except (ValueError, OSError, AttributeError):
        kind = None
    if kind != KIND:
        raise SShaDeError(f"refusing to export into {to}: the folder is not empty and holds no {MARKER} of an "
                          "earlier DeFAUST export; choose a new or empty folder")


def case_arrays(c: Case) -> dict:
    """The arrays of an exported ``.npz`` (keys and shapes: docs/defaust.md): ``V`` (n, 3)
    float64 metres, ``F`` (m, 3) int64, ``handles`` (h,) int64, ``targets`` (h, 3)
    float64, ``static`` (h,) bool, ``group`` (h,) int64, ``landmark_names`` (g,) str,
    ``snap_distance`` (h,) float64 metres, ``V_gt`` (n, 3) float64 when the case has a
    ground truth, and the scalars ``subject``, ``pose``, ``n_dropped``, ``seed`` (-1 for
    none), ``pose_name``, ``resolution``, ``source``."""
    d = {"V": c.V, "F": c.F, "handles": c.handles, "targets": c.targets, "static": c.static,
         "group": c.group, "landmark_names": np.array(c.landmark_names, dtype=str),
         "snap_distance": c.snap_distance, "subject": np.int64(c.subject), "pose": np.int64(c.pose),
         "n_dropped": np.int64(c.n_dropped), "seed": np.int64(-1 if c.seed is None else c.seed),
         "pose_name": np.array(c.pose_name), "resolution": np.array(c.resolution), "source": np.array(c.source)}
    if c.V_gt is not None:
        d["V_gt"] = c.V_gt
    return d


def _handles_json(c: Case, mesh: str, gt: str | None) -> str:
    """The ``<case>_handles.json`` of a mesh export."""
    return json.dumps({
        "case": c.name, "subject": c.subject, "pose": c.pose, "pose_name": c.pose_name, "source": c.source,
        "resolution": c.resolution, "units": "metres", "index_base": 0, "mesh": mesh, "ground_truth": gt,
        "handles": c.handles.tolist(), "targets": c.targets.tolist(), "static": c.static.tolist(),
        "group": c.group.tolist(), "landmark_names": list(c.landmark_names),
        "n_dropped": c.n_dropped, "seed": c.seed}, indent=1) + "\n"


def _write_case(c: Case, to: Path, fmt: str) -> dict:
    """Write case ``c``'s files into ``to``; ``{file name: sha256}``."""
    if fmt == "npz":
        buf = io.BytesIO()
        np.savez_compressed(buf, **case_arrays(c))
        name = f"{c.name}.npz"
        with atomic_write(to / name, "wb") as fh:
            fh.write(buf.getvalue())
        return {name: sha256_bytes(buf.getvalue())}
    mesh, gt = f"{c.name}.{fmt}", (f"{c.name}_gt.{fmt}" if c.V_gt is not None else None)
    write_mesh(to / mesh, c.V, c.F)
    if gt:
        write_mesh(to / gt, c.V_gt, c.F)
    text = _handles_json(c, mesh, gt)
    with atomic_write(to / f"{c.name}_handles.json") as fh:
        fh.write(text)
    out = {n: sha256_file(to / n) for n in (mesh, gt) if n}
    out[f"{c.name}_handles.json"] = sha256_bytes(text.encode())
    return out


def export(root, to, *, fmt: str = "npz", resolution: str = "high", subjects=None) -> list[Path]:
    """Export the cases of the DeFAUST build ``root`` into the folder ``to``.

    Parameters
    ----------
    root : str or Path, a DeFAUST build folder or archive (its files are checked against its
        manifest, every case read before any file is written).
    to : str or Path, the export folder: new, empty, or an earlier export (replaced file
        by file; files of cases no longer exported are left and not listed).
    fmt : one of :data:`FORMATS`. resolution : ``"high"``, ``"low"`` or ``"rN"`` (as :func:`load`).
    subjects : int, list of int or None (every subject).

    Returns
    -------
    list of Path, the files written (``export.json`` last).

    Raises
    ------
    SShaDeError on a bad ``fmt`` / ``resolution``, a refused folder
    (:func:`check_export_folder`, checked before any file is read) or a build that
    :func:`defaust.dataset.load` refuses; OSError when a file cannot be written.
    """
    if fmt not in FORMATS:
        raise SShaDeError(f"format must be one of {list(FORMATS)}, got {fmt!r}")
    check_resolution(resolution)
    if fmt == "hf":
        arrow_schema()  # pyarrow is there (the [hf] extra), before any case is read or folder made
    root, to = Path(root).expanduser(), Path(to).expanduser()
    check_export_folder(root, to)
    cases = load(root, resolution=resolution, subjects=subjects, eager=True)  # a bad file: before any is written
    src = open_build(root)
    manifest_sha256 = sha256_file(root / MANIFEST) if isinstance(src, FolderBuild) else src.sha256(MANIFEST)
    to.mkdir(parents=True, exist_ok=True)
    files: dict[str, str] = {}
    if fmt == "hf":
        manifest = read_manifest(root)
        files.update(write_shards(cases, to, manifest.get("subjects") or {}))
        files[CROISSANT] = write_shards_croissant(to, manifest, manifest_sha256=manifest_sha256,
                                                  resolution=resolution)
    else:
        for c in cases:
            files.update(_write_case(c, to, fmt))
    marker = {"kind": KIND, "format": fmt, "resolution": resolution, "source": cases[0].source,
              "cases": [c.name for c in cases], "build": str(root.resolve()),
              "build_manifest_sha256": manifest_sha256, "files": files}
    earlier = _earlier_files(to)
    with atomic_write(to / MARKER) as fh:
        fh.write(json.dumps(marker, indent=1) + "\n")
    for rel in sorted(set(earlier) - set(files)):  # the earlier export's own files this one did not write
        with contextlib.suppress(OSError, SShaDeError):
            inside_folder(to, rel, "earlier export").unlink()
    return [to / n for n in files] + [to / MARKER]


def _earlier_files(to: Path) -> list[str]:
    """The files an earlier export in ``to`` lists in its :data:`MARKER` (read as untrusted
    input: only plain relative paths of regular files inside ``to`` count; none when it
    has no such marker)."""
    try:
        old = read_json(to / MARKER) if (to / MARKER).is_file() and not (to / MARKER).is_symlink() else {}
    except (OSError, ValueError):
        return []
    files = old.get("files") if isinstance(old, dict) and old.get("kind") == KIND else None
    return [f for f in files if isinstance(f, str) and not Path(f).is_absolute() and ".." not in Path(f).parts
            and (to / f).is_file() and not (to / f).is_symlink()] if isinstance(files, dict) else []

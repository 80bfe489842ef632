"""The meshes of the scaling benchmark (``scaling.meshes``), checked before any mesh is built.

Each entry is ``{name: str, path: str, remesh: bool}``: ``path`` (relative to the cwd)
is a real mesh, ``remesh`` says how the benchmark sizes are built from it
(:func:`eval.experiments.scaling.scaling_experiment.build_mesh`: LS3 Loop subdivision, then isotropic
remeshing to the target size when true: a clean mesh; subdivision alone when false: the
base mesh's thin parts and anisotropy kept, a hard mesh). When ``scaling.meshes`` is null
the single ``scaling.base_mesh`` (with ``scaling.remesh``) is the set, named after its
file stem, as before the set existed.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from sshade.errors import SShaDeError

__all__ = ["MeshEntry", "mesh_entries", "cache_name"]

_KEYS = ("name", "path", "remesh")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")  # a file-name token: it names the cached meshes


@dataclass(frozen=True)
class MeshEntry:
    """One base mesh of the benchmark.

    Attributes
    ----------
    name : str, the row label (``mesh`` column) and the cached meshes' file-name prefix.
    path : str, the base mesh file as given (relative to the cwd or absolute).
    remesh : bool, LS3 Loop + isotropic remesh (clean) when true, LS3 Loop only (hard) when false.
    """

    name: str
    path: str
    remesh: bool

    @property
    def kind(self) -> str:
        """``"clean"`` (remeshed) or ``"hard"`` (subdivision only)."""
        return "clean" if self.remesh else "hard"


def mesh_entries(values) -> list[MeshEntry]:
    """The benchmark's meshes from the ``scaling`` section ``values`` (plain values), checked.

    Reads ``scaling.meshes`` (a list of ``{name, path, remesh}`` mappings) or, when it is
    null or absent, ``scaling.base_mesh`` with ``scaling.remesh`` (default true). Does not
    look at the files (:func:`eval.experiments.scaling.scaling_experiment.run_scaling` does, before building).

    Returns
    -------
    list of :class:`MeshEntry`, in config order (at least one).

    Raises
    ------
    SShaDeError, one line naming the entry and the key: an entry that is not a mapping,
    an unknown or missing key, a name that is not a file-name token (letters, digits,
    ``_ . -``) or that repeats, a path that is not a non-empty string, a ``remesh`` that
    is not true/false; an empty list; neither ``meshes`` nor ``base_mesh`` set.
    """
    raw = values.get("meshes", None)
    if raw is None:
        return [_base_entry(values)]
    if not isinstance(raw, list) or not raw:
        raise SShaDeError(f"scaling.meshes must be a non-empty list of {{name, path, remesh}} entries (or null), "
                          f"got {raw!r}")
    out = [_entry(i, e) for i, e in enumerate(raw)]
    seen = set()
    for i, e in enumerate(out):
        if e.name in seen:
            raise SShaDeError(f"scaling.meshes[{i}].name {e.name!r} repeats an earlier entry's: names must differ")
        seen.add(e.name)
    return out


def _base_entry(values) -> MeshEntry:
    """The one-mesh set of the older configs: ``scaling.base_mesh`` / ``scaling.remesh``."""
    path = values.get("base_mesh", None)
    if not isinstance(path, str) or not path.strip():
        raise SShaDeError("scaling.meshes is null and scaling.base_mesh is not set (set scaling.base_mesh=PATH "
                          "or a list scaling.meshes)")
    remesh = values.get("remesh", True)
    if not isinstance(remesh, bool):
        raise SShaDeError(f"scaling.remesh must be true or false, got {remesh!r}")
    return MeshEntry(Path(path).stem, path, remesh)


def _entry(i: int, e) -> MeshEntry:
    """Entry ``i`` of ``scaling.meshes`` (a plain dict after OmegaConf), checked."""
    where = f"scaling.meshes[{i}]"
    if not isinstance(e, dict):
        raise SShaDeError(f"{where} must be a mapping {{name, path, remesh}}, got {e!r}")
    unknown = sorted(set(map(str, e)) - set(_KEYS))
    if unknown:
        raise SShaDeError(f"{where} has unknown key(s) {', '.join(unknown)}; an entry has exactly "
                          f"{', '.join(_KEYS)}")
    missing = [k for k in _KEYS if k not in e]
    if missing:
        raise SShaDeError(f"{where} lacks {', '.join(missing)}; an entry has exactly {', '.join(_KEYS)}")
    name, path, remesh = e["name"], e["path"], e["remesh"]
    if not isinstance(name, str) or not _NAME.match(name):
        raise SShaDeError(f"{where}.name must be a file-name token (letters, digits, _ . -), got {name!r}")
    if not isinstance(path, str) or not path.strip():
        raise SShaDeError(f"{where}.path must be a mesh file path, got {path!r}")
    if not isinstance(remesh, bool):
        raise SShaDeError(f"{where}.remesh must be true or false, got {remesh!r}")
    return MeshEntry(name, path, remesh)


def cache_name(entry: MeshEntry, size: int) -> str:
    """File name of the mesh built from ``entry`` for target ``size`` in the cache folder:
    ``<name>_remesh_<size>.ply`` or ``<name>_ls3_<size>.ply``, so that two entries (or one
    mesh with and without remeshing) never share a file."""
    return f"{entry.name}_{'remesh' if entry.remesh else 'ls3'}_{int(size)}.ply"

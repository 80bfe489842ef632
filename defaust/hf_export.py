"""DeFAUST cases as Parquet shards in HuggingFace ``datasets``' layout (``python -m defaust
export DIR --to OUT --format hf``, :func:`defaust.export.export`): ``OUT/data/
train-XXXXX-of-YYYYY.parquet``, one row per case (:data:`COLUMNS`: the arrays of
:func:`defaust.export.case_arrays` as nested lists, and the subject's phenotype), shards of
about ``shard_mb`` MiB in case order, written with pyarrow (the ``[hf]`` extra); the same
build and pyarrow give the same bytes. ``datasets.load_dataset("parquet", data_dir=OUT)``
reads them, ``streaming=True`` one row at a time; ``croissant.json`` (Croissant 1.1)
describes them for mlcroissant. docs/defaust.md §6, "Export".
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError
from sshade.files import atomic_write

from .croissant import CROISSANT, shards_metadata
from .dataset import Case
from .store import sha256_bytes

__all__ = ["COLUMNS", "PHENOTYPE_FIELDS", "arrow_schema", "write_shards", "croissant_fields", "write_shards_croissant"]

#: The phenotype's fields (null for a source without one: FAUST, synthetic).
PHENOTYPE_FIELDS = ("gender", "age", "muscle", "weight", "height", "proportions")
#: Each column: (kind, meaning). Kinds: ``str``, ``int``, ``int?`` (nullable), ``xyz``
#: (n, 3) float64 rows, ``xyz?`` (nullable), ``tri`` (m, 3) int64 rows, ``[int]``,
#: ``[float]``, ``[bool]``, ``[str]``, ``phenotype`` (a struct, nullable).
COLUMNS: dict[str, tuple[str, str]] = {
    "name": ("str", "the case, sXX_pYY"), "subject": ("int", "subject id"), "pose": ("int", "target pose id"),
    "pose_name": ("str", "the target pose's name"), "resolution": ("str", "high, low or rN"),
    "source": ("str", "anny, faust or synthetic"), "seed": ("int?", "seed of the case's handle draw"),
    "n_dropped": ("int", "handles dropped by the snap (two on one vertex)"),
    "V": ("xyz", "rest vertices (n, 3), metres"), "F": ("tri", "triangles (m, 3), 0-based"),
    "V_gt": ("xyz?", "true target pose on the same faces (n, 3), metres; null: none"),
    "handles": ("[int]", "handle vertex indices (h,)"), "targets": ("xyz", "handle targets (h, 3), metres"),
    "static": ("[bool]", "static handles (h,)"), "group": ("[int]", "landmark group of each handle (h,)"),
    "landmark_names": ("[str]", "the groups' landmark names (g,)"),
    "snap_distance": ("[float]", "each handle's distance to its vertex (h,), metres"),
    "phenotype": ("phenotype", "ANNY's phenotype controls and description; null: none"),
}


def _pa():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except (ImportError, OSError) as e:
        raise SShaDeError(f"--format hf needs pyarrow ({e}); install the extra: pip install -e .[hf]") from None
    return pa, pq


def arrow_schema():
    """The shards' ``pyarrow.Schema`` (:data:`COLUMNS`)."""
    pa, _ = _pa()
    xyz, tri = pa.list_(pa.list_(pa.float64(), 3)), pa.list_(pa.list_(pa.int64(), 3))
    phen = pa.struct([(k, pa.float64()) for k in PHENOTYPE_FIELDS] + [("description", pa.string())])
    kinds = {"str": pa.string(), "int": pa.int64(), "int?": pa.int64(), "xyz": xyz, "xyz?": xyz, "tri": tri,
             "[int]": pa.list_(pa.int64()), "[float]": pa.list_(pa.float64()), "[bool]": pa.list_(pa.bool_()),
             "[str]": pa.list_(pa.string()), "phenotype": phen}
    return pa.schema([pa.field(k, kinds[kind], nullable=kind.endswith("?") or kind == "phenotype")
                      for k, (kind, _) in COLUMNS.items()])


def _nested(pa, arrays: list, width: int, dtype):
    """A list<list<dtype, width>> column from (k_i, width) arrays (None: a null row)."""
    lengths = [0 if a is None else len(a) for a in arrays]
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    flat = [np.asarray(a, dtype).reshape(-1) for a in arrays if a is not None]
    values = pa.FixedSizeListArray.from_arrays(pa.array(np.concatenate(flat) if flat else np.zeros(0, dtype)), width)
    mask = pa.array([a is None for a in arrays])
    return pa.ListArray.from_arrays(pa.array(offsets), values, mask=mask)


def _table(cases: list[Case], phenotypes: dict):
    pa, _ = _pa()
    schema = arrow_schema()
    cols = {"name": [c.name for c in cases], "subject": [int(c.subject) for c in cases],
            "pose": [int(c.pose) for c in cases], "pose_name": [c.pose_name for c in cases],
            "resolution": [c.resolution for c in cases], "source": [c.source for c in cases],
            "seed": [c.seed for c in cases], "n_dropped": [int(c.n_dropped) for c in cases],
            "handles": [c.handles.tolist() for c in cases], "static": [c.static.tolist() for c in cases],
            "group": [c.group.tolist() for c in cases], "landmark_names": [list(c.landmark_names) for c in cases],
            "snap_distance": [c.snap_distance.tolist() for c in cases],
            "phenotype": [phenotypes.get(int(c.subject)) for c in cases]}
    arrays = []
    for f in schema:
        if f.name in ("V", "V_gt", "targets"):
            arrays.append(_nested(pa, [getattr(c, f.name) for c in cases], 3, np.float64))
        elif f.name == "F":
            arrays.append(_nested(pa, [c.F for c in cases], 3, np.int64))
        else:
            arrays.append(pa.array(cols[f.name], type=f.type))
    return pa.Table.from_arrays(arrays, schema=schema)


def _phenotype(rec) -> dict | None:
    if not isinstance(rec, dict) or not all(isinstance(rec.get(k), (int, float)) for k in PHENOTYPE_FIELDS):
        return None
    return {**{k: float(rec[k]) for k in PHENOTYPE_FIELDS}, "description": str(rec.get("description", ""))}


def write_shards(cases, to: Path, subjects: dict, *, shard_mb: float = 256.0) -> dict[str, str]:
    """Write ``cases`` (read :class:`defaust.dataset.Case` objects, in order) as Parquet
    shards ``to/data/train-XXXXX-of-YYYYY.parquet`` of at most about ``shard_mb`` MiB of
    arrays each (a case larger than that alone in its shard).

    Parameters
    ----------
    cases : sequence of Case. to : the export folder. subjects : the build manifest's
    ``subjects`` (their ``phenotype`` records). shard_mb : float > 0.

    Returns
    -------
    dict, each shard's path relative to ``to`` -> its sha256.

    Raises
    ------
    SShaDeError without pyarrow (the ``[hf]`` extra) or on a bad ``shard_mb``; OSError
    when a file cannot be written.
    """
    _, pq = _pa()
    if not (isinstance(shard_mb, (int, float)) and np.isfinite(shard_mb) and shard_mb > 0):
        raise SShaDeError(f"shard_mb must be a finite number > 0, got {shard_mb!r}")
    phen = {}
    for rec in (subjects or {}).values():
        if isinstance(rec, dict) and isinstance(rec.get("subject"), int):
            phen[int(rec["subject"])] = _phenotype(rec.get("phenotype"))
    shards, cur, size = [], [], 0.0
    for c in cases:
        nbytes = sum(a.nbytes for a in (c.V, c.F, c.targets) if a is not None) + (0 if c.V_gt is None else
                                                                                   c.V_gt.nbytes)
        if cur and size + nbytes > shard_mb * 2**20:
            shards.append(cur)
            cur, size = [], 0.0
        cur.append(c)
        size += nbytes
    if cur:
        shards.append(cur)
    if (to / "data").is_symlink() or ((to / "data").exists() and not (to / "data").is_dir()):
        raise SShaDeError(f"refusing to write the shards into {to / 'data'}: a link or a file, not a folder")
    (to / "data").mkdir(parents=True, exist_ok=True)
    out = {}
    for i, part in enumerate(shards):
        rel = f"data/train-{i:05d}-of-{len(shards):05d}.parquet"
        sink = _pa()[0].BufferOutputStream()
        pq.write_table(_table(part, phen), sink, compression="zstd")
        data = sink.getvalue().to_pybytes()
        with atomic_write(to / rel, "wb") as fh:
            fh.write(data)
        out[rel] = sha256_bytes(data)
    return out


#: Column kind -> Croissant (dataType, arrayShape); the phenotype struct is in the shards only.
_CROISSANT_TYPES = {"str": ("sc:Text", None), "int": ("sc:Integer", None), "int?": ("sc:Integer", None),
                    "xyz": ("sc:Float", "-1,3"), "xyz?": ("sc:Float", "-1,3"), "tri": ("sc:Integer", "-1,3"),
                    "[int]": ("sc:Integer", "-1"), "[float]": ("sc:Float", "-1"), "[bool]": ("sc:Boolean", "-1"),
                    "[str]": ("sc:Text", "-1")}


def croissant_fields() -> list[tuple]:
    """``(column, dataType, description, arrayShape)`` of every column Croissant describes
    (:data:`COLUMNS` but ``phenotype``, a struct)."""
    return [(k, *_CROISSANT_TYPES[kind][:1], what, _CROISSANT_TYPES[kind][1])
            for k, (kind, what) in COLUMNS.items() if kind in _CROISSANT_TYPES]


def write_shards_croissant(to: Path, manifest: dict, *, manifest_sha256: str, resolution: str) -> str:
    """Write ``to/croissant.json`` (:func:`defaust.croissant.shards_metadata`) beside the
    shards; returns its sha256."""
    meta = shards_metadata(manifest, manifest_sha256=manifest_sha256, resolution=resolution,
                           fields=croissant_fields())
    text = json.dumps(meta, indent=1, sort_keys=True) + "\n"
    with atomic_write(to / CROISSANT, "w") as fh:
        fh.write(text)
    return sha256_bytes(text.encode())

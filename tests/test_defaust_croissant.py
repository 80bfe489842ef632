"""defaust.croissant: the builder writes croissant.json beside the manifest; mlcroissant
(the Croissant reference library; mark ``mlcroissant``, the test skips with one line where
it cannot be imported) validates it without errors and iterates its record sets, whose
records equal defaust.load's cases and the build's files; it is deterministic, names the
manifest's sha256, and verify tells one that describes another manifest."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from defaust.croissant import CROISSANT, LICENCES, croissant_metadata, write_croissant
from defaust.dataset import load, verify
from defaust.manifest import BUILDER_VERSION
from defaust.store import sha256_file

from .conftest import ROOT, subprocess_env
from .optional import locate_or_skip, skip_reason

# mlcroissant runs in its own process: importing it sets up absl's logging, whose handler
# keeps the stderr of the moment (here a test's capture, closed after the test), and a
# later test's log line then wrote into a closed file and killed the test process
_PRELUDE = """
import json, sys
try:
    import mlcroissant as mlc
except (ImportError, OSError) as e:  # installed, but does not load: the test skips
    print(json.dumps({"import_error": f"{type(e).__name__}: {(str(e).strip().splitlines() or [''])[0]}"}))
    sys.exit(0)
"""
_VALIDATE = _PRELUDE + """
ds = mlc.Dataset(jsonld=sys.argv[1])  # raises ValidationError on any error
print(json.dumps({"name": ds.metadata.name, "errors": sorted(map(str, ds.metadata.ctx.issues.errors)),
                  "warnings": sorted(map(str, ds.metadata.ctx.issues.warnings))}))
"""


_RECORDS = _PRELUDE + """
ds = mlc.Dataset(jsonld=sys.argv[1])
def plain(v):
    return v.item() if hasattr(v, "item") else v.decode() if isinstance(v, bytes) else v
print(json.dumps({rs: [{k: plain(v) for k, v in r.items()} for r in ds.records(rs)] for rs in ("cases", "files")}))
"""


def _in_mlcroissant(script: str, path) -> dict:
    """The JSON last printed by ``script`` run on the Croissant file ``path`` in its own
    process (mlcroissant is not imported in this one), or skip when it cannot import it."""
    r = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=300,
                       cwd=ROOT, env=subprocess_env())
    assert r.returncode == 0, r.stderr[-3000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    if "import_error" in res:
        pytest.skip(skip_reason("mlcroissant", res["import_error"]))
    return res


def _mlcroissant_records(path) -> dict:
    """``{"cases": [...], "files": [...]}``: the records mlcroissant iterates from the
    Croissant file ``path`` (in its own process, see ``_VALIDATE``), or skip."""
    return _in_mlcroissant(_RECORDS, path)


@pytest.mark.mlcroissant
def test_mlcroissant_records_equal_load(request):
    locate_or_skip("mlcroissant")
    defaust_ci = request.getfixturevalue("defaust_ci")
    rec = _mlcroissant_records(defaust_ci / CROISSANT)
    cases = load(defaust_ci, resolution="low")
    assert [r["cases/name"] for r in rec["cases"]] == list(cases.names)
    for r, c in zip(rec["cases"], cases, strict=True):
        assert (r["cases/subject"], r["cases/pose"], r["cases/pose_name"], r["cases/handle_seed"]) == \
            (c.subject, c.pose, c.pose_name, c.seed)
        assert r["cases/n_handles"] == len(c.handles) + c.n_dropped  # every handle kept at low resolution
        assert cases[r["cases/item"]] is c
        assert defaust_ci / r["cases/rest_low"] == c.rest_path
        for k in ("handles_file", "rest_high", "target_low", "target_high"):
            assert (defaust_ci / r[f"cases/{k}"]).is_file(), k
    files = json.loads((defaust_ci / "manifest.json").read_text())["files"]
    assert [r["files/path"] for r in rec["files"]] == sorted(files)
    for r in rec["files"]:
        assert r["files/sha256"] == files[r["files/path"]] == sha256_file(defaust_ci / r["files/path"])
        assert r["files/subject"] == 0 and r["files/file_set"] in ("rest-meshes", "pose-meshes", "handles")
    assert sum(r["files/file_set"] == "handles" for r in rec["files"]) == len(cases)


@pytest.mark.mlcroissant
def test_builder_writes_croissant_that_mlcroissant_validates(request):
    locate_or_skip("mlcroissant")  # before the build; not imported in this process
    defaust_ci = request.getfixturevalue("defaust_ci")
    p = defaust_ci / CROISSANT
    assert p.is_file()
    assert _in_mlcroissant(_VALIDATE, p) == {"name": "DeFAUST-synthetic", "errors": [], "warnings": []}
    meta = json.loads(p.read_text())
    assert meta["license"] == LICENCES["synthetic"] and meta["version"] == f"1.{BUILDER_VERSION}.0"
    assert meta["distribution"][0]["sha256"] == sha256_file(defaust_ci / "manifest.json")
    assert {d["includes"] for d in meta["distribution"][1:]} == {
        "subject_*/rest_*.ply", "subject_*/pose_*_*.ply", "subject_*/pose_*_handles.npz"}


def test_croissant_is_deterministic_and_rewritten_only_when_it_changes(defaust_ci, tmp_path):
    c = shutil.copytree(defaust_ci, tmp_path / "c")
    before = (c / CROISSANT).stat().st_mtime_ns, (c / CROISSANT).read_bytes()
    write_croissant(c)
    assert ((c / CROISSANT).stat().st_mtime_ns, (c / CROISSANT).read_bytes()) == before


def test_verify_tells_a_croissant_of_another_manifest(defaust_ci, tmp_path):
    c = shutil.copytree(defaust_ci, tmp_path / "c")
    m = json.loads((c / "manifest.json").read_text())
    (c / "manifest.json").write_text(json.dumps(m) + "\n")  # same content, other bytes
    assert verify(c) == [f"{c / CROISSANT}: does not describe this manifest.json (its sha256 differs)"]
    write_croissant(c)
    assert verify(c) == []


def test_every_builder_version_up_to_this_one_has_a_release_date():
    """mlcroissant warns on a dataset without ``datePublished``: each builder version, the
    current one included, names the date it was released (a constant, never the build's)."""
    from defaust.croissant import RELEASED
    assert set(RELEASED) >= set(range(2, BUILDER_VERSION + 1))
    meta = croissant_metadata({"format": "defaust-1", "builder_version": BUILDER_VERSION, "source": "anny"},
                              manifest_sha256="0")
    assert meta["datePublished"] == RELEASED[BUILDER_VERSION]


def test_faust_builds_name_faust_terms_not_a_free_licence():
    meta = croissant_metadata({"format": "defaust-1", "builder_version": 2, "source": "faust"}, manifest_sha256="0")
    assert "no redistribution" in meta["license"] and meta["name"] == "DeFAUST-faust"


_SHARD_RECORDS = _PRELUDE + """
ds = mlc.Dataset(jsonld=sys.argv[1])
def plain(v):
    v = v.tolist() if hasattr(v, "tolist") else v
    return [plain(x) for x in v] if isinstance(v, list) else v.decode() if isinstance(v, bytes) else v
print(json.dumps({"errors": sorted(map(str, ds.metadata.ctx.issues.errors)),
                  "warnings": sorted(map(str, ds.metadata.ctx.issues.warnings)),
                  "cases": [{k.split("/")[1]: plain(v) for k, v in r.items()} for r in ds.records("cases")]}))
"""


@pytest.mark.hf
def test_the_hf_exports_croissant_11_yields_defaust_loads_cases(defaust_ci, tmp_path):
    """``export --format hf`` writes a Croissant 1.1 file with the Responsible-AI fields;
    mlcroissant validates it with no error or warning and reads the Parquet shards into
    records equal to ``defaust.load``'s cases, array for array."""
    import numpy as np

    from defaust.export import export
    from defaust.hf_export import arrow_schema
    from sshade.errors import SShaDeError
    try:
        arrow_schema()
    except SShaDeError as e:
        pytest.skip(skip_reason("pyarrow", str(e)))
    export(defaust_ci, tmp_path / "hf", fmt="hf", resolution="low")
    meta = json.loads((tmp_path / "hf" / CROISSANT).read_text())
    assert meta["conformsTo"] == "http://mlcommons.org/croissant/1.1" and meta["rai:dataCollectionType"]
    got = _in_mlcroissant(_SHARD_RECORDS, tmp_path / "hf" / CROISSANT)
    assert got["errors"] == [] and got["warnings"] == []
    cases = load(defaust_ci, resolution="low")
    assert [r["name"] for r in got["cases"]] == [c.name for c in cases]
    for r, c in zip(got["cases"], cases):
        for k in ("V", "F", "V_gt", "targets", "handles", "static", "group", "snap_distance"):
            np.testing.assert_array_equal(np.asarray(r[k]), getattr(c, k))
        assert (r["subject"], r["pose"], r["resolution"], r["landmark_names"]) == \
            (c.subject, c.pose, "low", list(c.landmark_names))

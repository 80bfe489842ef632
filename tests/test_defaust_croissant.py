"""defaust.croissant: the builder writes croissant.json beside the manifest; mlcroissant
(the Croissant reference library) validates it without errors; it is deterministic,
names the manifest's sha256, and verify tells one that describes another manifest."""
from __future__ import annotations

import json
import shutil

import pytest

from defaust.croissant import CROISSANT, LICENCES, croissant_metadata, write_croissant
from defaust.dataset import verify
from defaust.store import sha256_file


def test_builder_writes_croissant_that_mlcroissant_validates(defaust_ci):
    mlc = pytest.importorskip("mlcroissant")
    p = defaust_ci / CROISSANT
    assert p.is_file()
    ds = mlc.Dataset(jsonld=str(p))  # raises ValidationError on any error
    assert ds.metadata.name == "DeFAUST-synthetic"
    assert not ds.metadata.ctx.issues.errors
    meta = json.loads(p.read_text())
    assert meta["license"] == LICENCES["synthetic"] and meta["version"] == "1.2.0"
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


def test_faust_builds_name_faust_terms_not_a_free_licence():
    meta = croissant_metadata({"format": "defaust-1", "builder_version": 2, "source": "faust"}, manifest_sha256="0")
    assert "no redistribution" in meta["license"] and meta["name"] == "DeFAUST-faust"

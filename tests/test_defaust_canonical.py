"""defaust/canonical.py: a build held against the canonical records. A build equal to a
record is canonical, a part of it canonical for its items; one changed file (its manifest
updated, so it still verifies) or an item of other parameters is named, by ``verify``
too, which exits 0 with the note or 1 under ``--canonical``; the committed records are
well formed and name only complete builds of this builder version."""
from __future__ import annotations

import json
import shutil

import pytest

from defaust import canonical
from defaust.canonical import canonical_record, canonical_records, canonical_status
from defaust.dataset import read_manifest
from defaust.dataset_cli import main as dataset_main
from defaust.manifest import BUILDER_VERSION
from defaust.store import sha256_file


@pytest.fixture()
def ci_record(defaust_ci, tmp_path, monkeypatch):
    """A canonical folder holding the record of the small build ``defaust_ci`` as 'ci'."""
    folder = tmp_path / "canonical"
    folder.mkdir()
    (folder / "ci.json").write_text(json.dumps(canonical_record(read_manifest(defaust_ci))))
    monkeypatch.setattr(canonical, "CANONICAL_DIR", folder)
    return folder


def test_a_build_equal_to_a_record_is_canonical_and_a_part_of_it_canonical_for_its_items(defaust_ci, ci_record):
    m = read_manifest(defaust_ci)
    whole = canonical_status(m)
    assert whole.canonical and whole.name == "ci" and whole.items == whole.of == len(m["items"])
    part = dict(m, items={i: v for i, v in m["items"].items() if not i.endswith("pose_02")})
    st = canonical_status(part)
    assert st.canonical and st.items == st.of - 1 and f"({st.items} of its {st.of} items)" in st.words()


def test_items_a_record_of_the_same_kind_lacks_are_counted_unrecorded_not_canonical(defaust_ci, tmp_path):
    """A record made from part of a build (FAUST subjects that only some users have): the
    whole build is not canonical, its extra items counted and named as unrecorded, the
    others still held byte for byte; a build of other parameters stays 'no item'."""
    m = read_manifest(defaust_ci)
    rec = canonical_record(m)
    lacking = sorted(i for i in rec["items"] if i.endswith("pose_02"))
    rec["items"] = {i: v for i, v in rec["items"].items() if i not in lacking}
    st = canonical_status(m, {"part": rec})
    assert not st.canonical and st.name == "part" and st.unrecorded == len(lacking) > 0
    assert st.difference.startswith(f"no canonical record holds {len(lacking)} of its items ({lacking[0]} first)")
    assert f"Its other {len(m['items']) - len(lacking)} items are the canonical 'part' build's" in st.words()
    changed = json.loads(json.dumps(m))
    kept = sorted(set(m["items"]) - set(lacking))[0]
    changed["items"][kept]["files"] = {k: "0" * 64 for k in changed["items"][kept]["files"]}
    assert "differs from the canonical 'part' build's" in canonical_status(changed, {"part": rec}).difference
    other = dict(json.loads(json.dumps(m)), parameters=dict(m["parameters"], seed=12345))
    st = canonical_status(other, {"part": rec})
    assert st.unrecorded == 0 and f"its item {lacking[0]} is no item of a canonical build" in st.difference


def test_a_changed_file_or_an_item_of_other_parameters_is_named(defaust_ci, ci_record):
    m = read_manifest(defaust_ci)
    item = sorted(m["items"])[1]
    rel = sorted(m["items"][item]["files"])[0]
    changed = json.loads(json.dumps(m))
    changed["items"][item]["files"][rel] = "0" * 64
    st = canonical_status(changed)
    assert not st.canonical and st.difference.startswith(f"{rel} differs from the canonical 'ci' build's")
    other = json.loads(json.dumps(m))
    other["items"][item]["key"] = "f" * 64
    st = canonical_status(other)
    assert not st.canonical and f"its item {item} is no item of a canonical build" in st.difference
    assert "not with rows made on the canonical one" in st.words()


def test_verify_names_a_build_with_one_file_changed_non_canonical_exit_0_or_1_under_canonical(
        defaust_ci, ci_record, tmp_path, capsys):
    build = tmp_path / "b"
    shutil.copytree(defaust_ci, build)
    assert dataset_main(["verify", str(build), "--canonical"]) == 0
    assert "the canonical DeFAUST 'ci'" in capsys.readouterr().out
    m = json.loads((build / "manifest.json").read_text())
    item = sorted(m["items"])[1]
    rel = sorted(m["items"][item]["files"])[0]
    p = build / rel
    p.write_bytes(p.read_bytes() + b"\n")  # one file changed, the manifest made to match it: it still verifies
    m["items"][item]["files"][rel] = m["files"][rel] = sha256_file(p)
    (build / "manifest.json").write_text(json.dumps(m, indent=1, sort_keys=True))
    for croissant_or_sheet in ("croissant.json", "DATASHEET.md"):
        (build / croissant_or_sheet).unlink(missing_ok=True)  # they name the manifest's old sha256
    assert dataset_main(["verify", str(build)]) == 0
    out = capsys.readouterr().out
    assert "every file matches its manifest" in out and f"not the canonical DeFAUST: {rel} differs" in out
    assert dataset_main(["verify", str(build), "--canonical"]) == 1


def test_the_committed_records_are_complete_builds_of_this_builder_version():
    for name, rec in canonical_records().items():
        assert rec["builder_version"] == BUILDER_VERSION, name
        assert rec["items"] and all(len(v["key"]) == 64 for v in rec["items"].values()), name
        assert len({v["key"] for v in rec["items"].values()}) == len(rec["items"]), name


def test_a_malformed_record_is_refused_naming_it(tmp_path):
    (tmp_path / "bad.json").write_text('{"items": {"a": {"key": 1}}}')
    with pytest.raises(Exception, match="bad.json: not a canonical record"):
        canonical_records(tmp_path)


@pytest.mark.slow  # about a minute: one FAUST subject at full resolution
def test_a_faust_build_of_subject_0_under_other_blas_settings_is_the_canonical_faust_record(faust_root, tmp_path):
    """The committed 'faust-default' record (FAUST's subjects 0 and 1, the only ones in
    ../shared/data) is what a build of subject 0 gives under one OpenBLAS thread and the
    Sandybridge kernels, in a folder of another name: ``verify`` calls it canonical for
    its 5 of the record's 10 items."""
    import os
    import subprocess
    import sys

    from .conftest import ROOT
    if not (faust_root / "tr_reg_004.ply").is_file():
        pytest.skip("FAUST subject 0's poses 1-4 not in ../shared/data/faust_reg")
    (tmp_path / "elsewhere").symlink_to(faust_root)
    out = tmp_path / "b"
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OPENBLAS_CORETYPE": "Sandybridge", "OMP_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, "-m", "defaust", "source=faust", f"faust.root={tmp_path / 'elsewhere'}",
                        f"out={out}", "subjects=[0]", "workers=1", "progress=false"], cwd=ROOT, env=env,
                       capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-2000:]
    st = canonical_status(read_manifest(out))
    assert st.canonical and st.name == "faust-default" and (st.items, st.of) == (5, 10), st

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

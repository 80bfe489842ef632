"""eval.datasets.defaust_dataset's build before a run: a run on some subjects
(``dataset.subjects``) builds only those, a later run adds the others
to the same folder and leaves the first ones' files as they were; builder overrides that
name ``subjects`` keep the builder's own plan."""
from __future__ import annotations

import hashlib
import json

import pytest

from eval.datasets.defaust_dataset import (
    DefaustBuildOptions,
    DefaustOptions,
    build_outlook,
    load_defaust,
    prepare_root,
)
from sshade.errors import SShaDeError

CI = ["preset=ci", "source=synthetic", "n_subjects=3", "progress=false", "workers=1"]


def _ds(**kw):
    return DefaustOptions(build=DefaustBuildOptions(enabled=True, overrides=list(CI)), **kw)


def _hashes(root):
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("kw,subjects,cases", [
    ({"subjects": [1]}, 1, [(1, 1), (1, 2), (1, 3), (1, 4)]),
    ({"limit": 5}, 3, [(0, 1), (0, 2), (0, 3), (0, 4), (1, 1)]),  # limit alone: every subject (the loader's rule)
    ({"subjects": [0, 2], "limit": 2}, 2, [(0, 1), (0, 2)]),
    ({}, 3, None),
    ({"subjects": [1], "sample": 2}, 1, None),  # a sample is drawn from the cases of those subjects
])
def test_the_plan_builds_only_the_runs_subjects(tmp_path, kw, subjects, cases):
    out = build_outlook(tmp_path / "new", _ds(**kw))
    assert out["subjects"] == subjects and out["complete"] == 0
    if cases is not None:
        assert out["cases"] == cases


def test_builder_overrides_naming_subjects_are_kept(tmp_path):
    ds = _ds(subjects=[1])
    ds.build.overrides.append("subjects=[0,1,2]")
    assert build_outlook(tmp_path / "new", ds)["subjects"] == 3


@pytest.mark.slow
def test_a_run_on_one_subject_builds_it_and_a_later_run_adds_the_others(tmp_path, caplog):
    root = tmp_path / "defaust"
    with caplog.at_level("INFO", logger="eval"):
        prepare_root(root, _ds(subjects=[1]))
    m = json.loads((root / "manifest.json").read_text())
    assert sorted(m["subjects"]) == ["subject_01"] and m["complete"] is True
    assert m["parameters"]["subjects"] == [1]  # the folder says what it holds
    assert any("the 1 subject(s) this run takes (1) of the 3" in r.getMessage() for r in caplog.records)
    with pytest.raises(SShaDeError, match=r"subject\(s\) 1 \(2 of its 3 not built\)"):  # not taken for the whole
        load_defaust(root)
    first = _hashes(root)
    assert build_outlook(root, _ds(subjects=[1])) is None  # nothing left to build for that run
    prepare_root(root, _ds())
    m = json.loads((root / "manifest.json").read_text())
    assert sorted(m["subjects"]) == ["subject_00", "subject_01", "subject_02"] and m["parameters"]["subjects"] is None
    assert len(load_defaust(root)) == 12  # the whole build now, loaded as such
    after = _hashes(root)
    kept = {f: h for f, h in first.items() if f.startswith("subject_01/")}
    assert kept and all(after[f] == h for f, h in kept.items())  # subject 1's files untouched
    whole = _hashes(root)
    prepare_root(root, _ds(subjects=[1]))  # a run on one subject of a whole build only verifies it
    assert _hashes(root) == whole


@pytest.mark.slow
def test_a_run_with_a_limit_alone_builds_every_subject_and_reads_its_first_cases(tmp_path):
    root = tmp_path / "defaust"
    prepare_root(root, _ds(limit=2))
    m = json.loads((root / "manifest.json").read_text())
    assert sorted(m["subjects"]) == ["subject_00", "subject_01", "subject_02"] and m["parameters"]["subjects"] is None
    assert [c.name for c in load_defaust(root, DefaustOptions(limit=2))] == ["s00_p01", "s00_p02"]


@pytest.mark.slow
def test_a_run_on_a_build_other_than_the_canonical_one_records_and_says_so(defaust_ci, tmp_path):
    """A DeFAUST run records its build held against the canonical records in run.json
    (``dataset_build``); on a build that is not the canonical one (the synthetic ci build)
    its table's title and its leaderboard board say so, naming the first item that differs."""
    import subprocess
    import sys

    from eval.datasets.defaust_dataset import build_provenance
    from eval.leaderboard import collect, leaderboard_rows

    from .conftest import ROOT, subprocess_env
    prov = build_provenance(defaust_ci)
    assert prov["canonical"] is False and "is no item of a canonical build" in prov["difference"]
    out = tmp_path / "runs" / "defaust"
    r = subprocess.run([sys.executable, "-m", "eval", "dataset=defaust", f"dataset.root={defaust_ci}",
                        "dataset.build.enabled=false", "dataset.resolution=low", "dataset.limit=2",
                        "methods=[SShaDe]", "sshade.n_low=300", "sshade.n_samplings=1", f"out_dir={out}"],
                       cwd=ROOT, env=subprocess_env(), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads((out / "run.json").read_text())["dataset_build"] == prov
    assert prov["mark"] in (out / "table.md").read_text().splitlines()[0]
    boards, _ = collect(tmp_path / "runs")
    assert leaderboard_rows(boards)[0] == ["Method", "DeFAUST (not the canonical build)"]
    assert boards[0].data[1] == prov["mark"]

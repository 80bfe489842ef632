"""A user's folder is never written unless they ask: the evaluator reads a DeFAUST it
did not build, the builder refuses a folder holding another build or other files.

Guards against a data loss: ``python -m eval dataset.root=DIR`` on a DeFAUST built from
FAUST scans must not start a synthetic build into DIR, overwriting the user's
``subject_XX`` files and manifest.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from defaust.build import BuildConfig, build_defaust, check_out_folder
from defaust.cli import compose_config, config_from_omegaconf
from eval.config_check import check_config
from sshade.errors import SShaDeError

from .conftest import SHARED_DATA


def _snapshot(root: Path) -> dict[str, tuple[str, int]]:
    """relative path -> (sha256, mtime_ns) of every file under ``root``."""
    return {str(p.relative_to(root)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def faust_build(tmp_path_factory):
    """A small DeFAUST built from the shared FAUST registrations (subject 0, pose 1)."""
    faust = SHARED_DATA / "faust_reg"
    if not (faust / "tr_reg_000.ply").is_file() or not (faust / "tr_reg_001.ply").is_file():
        pytest.skip(f"FAUST registrations not found in {faust}")
    out = tmp_path_factory.mktemp("user") / "defaust_faust"
    cfg = compose_config(["preset=ci", "source=faust", f"faust.root={faust}", f"out={out}", "subjects=[0]",
                          "faust.target_poses=[1]", "progress=false"])
    build_defaust(config_from_omegaconf(cfg))
    return out


def _eval_cfg(overrides):
    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=list(overrides))


def test_evaluator_reads_a_users_faust_build_and_writes_nothing_there(faust_build, tmp_path):
    from eval.app import run
    before = _snapshot(faust_build)
    out = tmp_path / "out"
    cfg = _eval_cfg([f"dataset.root={faust_build}", "dataset.subjects=[0]", "methods=[SShaDe]", "sshade.n_low=300",
                     "sshade.n_samplings=1", "sshade.workers=1", f"out_dir={out}"])
    res = run(check_config(cfg))  # default dataset=defaust, dataset.build.enabled=auto: no build here
    assert res["n_cases"] == 1 and res["n_errors"] == 0
    assert _snapshot(faust_build) == before  # same files, same bytes, not even rewritten
    assert not any(p.name.startswith("subject_01") for p in faust_build.iterdir())


def test_explicit_build_into_a_users_faust_build_is_refused(faust_build, tmp_path):
    from eval.app import run
    before = _snapshot(faust_build)
    cfg = _eval_cfg([f"dataset.root={faust_build}", "dataset.build.enabled=true", "methods=[SShaDe]",
                     f"out_dir={tmp_path / 'out'}"])
    with pytest.raises(SShaDeError, match=r"refusing to build into .*source: 'faust' there, 'anny' asked"):
        run(check_config(cfg))
    # the builder itself refuses too, whatever calls it
    with pytest.raises(SShaDeError, match="python -m eval dataset.root="):
        build_defaust(BuildConfig(out=faust_build, n_subjects=1, vertex_range=(8000, 12000), progress=False))
    assert _snapshot(faust_build) == before
    assert not (tmp_path / "out").exists()


def test_same_settings_resume_and_other_parameters_refused(faust_build):
    before = _snapshot(faust_build)
    base = ["preset=ci", "source=faust", f"faust.root={SHARED_DATA / 'faust_reg'}", f"out={faust_build}",
            "subjects=[0]", "faust.target_poses=[1]", "progress=false"]
    rep = build_defaust(config_from_omegaconf(compose_config(base)))  # the same build: verified, skipped
    assert rep.built == [] and rep.skipped == ["subject_00/rest", "subject_00/pose_01"]
    with pytest.raises(SShaDeError, match=r"seed: 0 there, 1 asked"):
        build_defaust(config_from_omegaconf(compose_config([*base, "seed=1"])))
    with pytest.raises(SShaDeError, match=r"vertex_range"):
        build_defaust(config_from_omegaconf(compose_config([*base, "preset=full"])))
    assert _snapshot(faust_build) == before


def test_non_empty_folder_without_manifest_is_refused(tmp_path):
    d = tmp_path / "mine"
    d.mkdir()
    (d / "notes.txt").write_text("my data")
    (d / "subject_00").mkdir()
    before = _snapshot(d)
    with pytest.raises(SShaDeError, match="not empty and holds no DeFAUST manifest.json"):
        build_defaust(BuildConfig(out=d, n_subjects=1, vertex_range=(8000, 12000), progress=False))
    (d / "manifest.json").write_text("{not json")
    before = _snapshot(d)
    with pytest.raises(SShaDeError, match="unreadable"):
        check_out_folder(d, "synthetic", {})
    (d / "manifest.json").write_text('{"format": "something-else"}')
    before = _snapshot(d)
    with pytest.raises(SShaDeError, match="not a DeFAUST manifest"):
        check_out_folder(d, "synthetic", {})
    assert _snapshot(d) == before
    assert check_out_folder(tmp_path / "new", "synthetic", {}) == {}  # a new folder is fine
    (tmp_path / "empty").mkdir()
    assert check_out_folder(tmp_path / "empty", "synthetic", {}) == {}


def test_a_typo_in_dataset_root_builds_nothing(tmp_path, monkeypatch):
    from eval.app import run
    monkeypatch.chdir(tmp_path)
    cfg = _eval_cfg(["dataset.root=data/defuast", "methods=[SShaDe]", f"out_dir={tmp_path / 'out'}"])
    with pytest.raises(SShaDeError, match="does not exist.*only into the default folder data/defaust"):
        run(check_config(cfg))
    assert not (tmp_path / "data").exists() and not (tmp_path / "out").exists()


def test_build_policy(tmp_path, monkeypatch):
    from eval.datasets.defaust_dataset import DefaustBuildOptions, DefaustOptions
    from eval.datasets.defaust_dataset import build_wanted as _build_wanted
    from eval.run.paths import abs_path
    monkeypatch.chdir(tmp_path)
    default, other = abs_path("data/defaust"), abs_path("elsewhere")

    def ds(enabled):
        return DefaustOptions(build=DefaustBuildOptions(enabled=enabled))

    assert _build_wanted(default, ds(" Auto")) and not _build_wanted(other, ds("auto"))
    assert _build_wanted(other, ds(True))
    assert not _build_wanted(default, ds(False))
    with pytest.raises(SShaDeError, match="dataset.build.enabled must be auto, true or false"):
        ds("yes")


def test_bad_method_parameter_fails_before_any_build(tmp_path, monkeypatch):
    """sshade.n_low=2 is refused before the (default, minutes-long) DeFAUST build starts."""
    from eval.app import run
    monkeypatch.chdir(tmp_path)
    cfg = _eval_cfg(["sshade.n_low=2", f"out_dir={tmp_path / 'out'}"])
    with pytest.raises(SShaDeError, match=r"n_low must be at least 4"):
        run(check_config(cfg))
    assert not (tmp_path / "data").exists() and not (tmp_path / "out").exists()

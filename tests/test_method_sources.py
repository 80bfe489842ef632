"""run.json records each method's source file, its sha256 and its git state: a
plug-in's code is identified even when it lives outside this repository."""
from __future__ import annotations

import hashlib
import importlib
import json
import shutil
import subprocess

import pytest

from eval.config_check import check_config
from eval.run.runinfo import method_sources

_PLUGIN = '''
class Pinned:
    """Moves the handles to their targets, nothing else."""

    name = "Pinned"

    def deform(self, V, F, handles, targets):
        U = V.copy()
        U[handles] = targets
        return U
'''


def _plugin(d, monkeypatch, module="pinned_plugin"):
    (d / f"{module}.py").write_text(_PLUGIN)
    monkeypatch.syspath_prepend(str(d))
    importlib.invalidate_caches()
    return importlib.import_module(module)


def _git(d, *args):
    subprocess.run(["git", "-C", str(d), "-c", "user.name=t", "-c", "user.email=t@t", *args], check=True,
                   capture_output=True)


def test_plugin_outside_the_repository_in_its_own_git_tree(tmp_path, monkeypatch):
    if shutil.which("git") is None:
        pytest.skip("git not installed")
    repo = tmp_path / "mypkg"
    repo.mkdir()
    mod = _plugin(repo, monkeypatch, "pinned_git")
    _git(repo, "init", "-q")
    _git(repo, "add", "pinned_git.py")
    _git(repo, "commit", "-qm", "plug-in")
    f = repo / "pinned_git.py"
    (rec,) = method_sources([mod.Pinned()])
    assert rec["name"] == "Pinned" and rec["class"] == "pinned_git.Pinned"
    assert rec["file"] == str(f.resolve()) and rec["in_repo"] is False
    assert rec["sha256"] == hashlib.sha256(f.read_bytes()).hexdigest()
    assert rec["git"] == {"work_tree": str(repo.resolve()), "tracked": True, "dirty": False}
    f.write_text(_PLUGIN + "# edited\n")
    (rec2,) = method_sources([mod.Pinned()])
    assert rec2["git"]["dirty"] is True and rec2["sha256"] != rec["sha256"]


def test_builtin_method_is_recorded_inside_the_repository():
    from sshade import SShaDe
    (rec,) = method_sources([SShaDe(n_low=100)])
    assert rec["class"] == "sshade.pipeline.SShaDe" and rec["in_repo"] is True
    assert rec["file"].endswith("sshade/pipeline.py") and len(rec["sha256"]) == 64


def test_run_json_lists_the_plugin_source(tmp_path, monkeypatch, shared_data):
    """An evaluator run with a plug-in from a folder outside the repository."""
    root = shared_data / "faust_reg"
    if not (root / "tr_reg_001.ply").is_file():
        pytest.skip("FAUST registrations not found")
    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR, run
    plug = tmp_path / "plug"
    plug.mkdir()
    _plugin(plug, monkeypatch, "pinned_run")
    out = tmp_path / "out"
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=[
            "dataset=faust", f"dataset.root={root}", "dataset.limit=1", "reference.cases=none",
            f"out_dir={out}", "methods=[{_target_:pinned_run.Pinned}]"])
    run(check_config(cfg))
    info = json.loads((out / "run.json").read_text())
    (rec,) = info["method_sources"]
    f = (plug / "pinned_run.py").resolve()
    assert rec["class"] == "pinned_run.Pinned" and rec["file"] == str(f)
    assert rec["sha256"] == hashlib.sha256(f.read_bytes()).hexdigest() and rec["in_repo"] is False

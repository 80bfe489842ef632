"""Packaging: the wheel ships the Hydra configs of ``conf/`` as ``harness/conf/`` and an
install that is not this checkout finds them (:func:`harness.confdir.config_dir`)."""
from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import harness.confdir as confdir
from harness.confdir import config_dir
from sshade.errors import SShaDeError

ROOT = Path(__file__).resolve().parents[1]
# hydra_plugins: the sweep launcher
PACKAGE_ROOTS = ("sshade", "harness", "baselines", "defaust", "eval", "hydra_plugins")
# the configs the commands and the README name, at their place in the wheel
EXPECTED_CONF = ["config.yaml", "dataset/faust.yaml", "dataset/defaust.yaml", "dataset/shapes.yaml",
                 "experiment/ci.yaml", "experiment/main.yaml", "experiment/sweep.yaml",
                 "experiment/sweep_slurm.yaml", "defaust/config.yaml", "defaust/preset/ci.yaml",
                 "defaust/preset/full.yaml", "hydra/launcher/slurm.yaml", "method/ARAP.yaml", "method/Elastic.yaml",
                 "method/ARAP-SR.yaml", "method/SShaDe.yaml", "method/SShaDe+refine.yaml"]
_IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")


# ----------------------------------------------------------------------------- helper


def test_config_dir_source_checkout():
    assert Path(config_dir()) == ROOT / "conf"
    assert Path(config_dir("defaust")) == ROOT / "conf" / "defaust"
    assert (Path(config_dir("hydra/launcher")) / "slurm.yaml").is_file()


def test_config_dir_unknown_sub():
    with pytest.raises(SShaDeError, match="no config folder 'nope'"):
        config_dir("nope")


def test_config_dir_installed_package_data(tmp_path, monkeypatch):
    """Outside a checkout (no conf/ + pyproject.toml beside the packages) the package data
    harness/conf is used."""
    site = tmp_path / "site"
    (site / "harness" / "conf" / "defaust").mkdir(parents=True)
    (site / "harness" / "conf" / "config.yaml").write_text("a: 1\n")
    monkeypatch.setattr(confdir, "_REPO_ROOT", site)
    monkeypatch.setattr(confdir, "_package_conf", lambda: site / "harness" / "conf")
    assert Path(config_dir()) == (site / "harness" / "conf").resolve()
    assert Path(config_dir("defaust")) == (site / "harness" / "conf" / "defaust").resolve()
    # a stray site-packages/conf (another distribution's) is not mistaken for a checkout
    (site / "conf").mkdir()
    (site / "conf" / "config.yaml").write_text("b: 2\n")
    assert Path(config_dir()) == (site / "harness" / "conf").resolve()


def test_config_dir_missing_everywhere(tmp_path, monkeypatch):
    monkeypatch.setattr(confdir, "_REPO_ROOT", tmp_path)
    monkeypatch.setattr(confdir, "_package_conf", lambda: tmp_path / "harness" / "conf")
    with pytest.raises(SShaDeError, match="Hydra configs not found"):
        config_dir()


# ----------------------------------------------------------------------------- wheel


def _can_build_without_isolation() -> bool:
    """setuptools can make a wheel with what is installed (``wheel``, or setuptools >= 70.1)."""
    return any(importlib.util.find_spec(m) is not None
               for m in ("wheel", "setuptools.command.bdist_wheel"))


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """A wheel built from a copy of this checkout (so no build/ is left in the repository)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for f in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / f, src / f)
    for d in (*PACKAGE_ROOTS, "conf"):
        shutil.copytree(ROOT / d, src / d, ignore=_IGNORE)
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp / "dist"), str(src)]
    if _can_build_without_isolation():
        cmd.insert(5, "--no-build-isolation")
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if r.returncode != 0:
        out = r.stdout + r.stderr
        if "--no-build-isolation" not in cmd and ("No matching distribution" in out
                                                  or "Could not find a version" in out):
            pytest.skip("cannot fetch the build requirements (setuptools, wheel) for an isolated build")
        pytest.fail(f"pip wheel failed:\n{out[-4000:]}")
    (whl,) = (tmp / "dist").glob("sshade-*.whl")
    return whl


@pytest.mark.slow
def test_wheel_ships_configs_and_all_modules(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for rel in EXPECTED_CONF:
        assert f"harness/conf/{rel}" in names, f"harness/conf/{rel} missing from {wheel.name}"
    # every config of conf/, and nothing at a top-level conf/
    conf = {p.relative_to(ROOT / "conf").as_posix() for p in (ROOT / "conf").rglob("*.yaml")}
    assert {n[len("harness/conf/"):] for n in names if n.startswith("harness/conf/")} == conf
    assert not any(n.startswith("conf/") for n in names)
    # every module of the packages (catches a subpackage missing from pyproject's list)
    mods = {p.relative_to(ROOT).as_posix() for d in PACKAGE_ROOTS for p in (ROOT / d).rglob("*.py")
            if "__pycache__" not in p.parts}
    assert mods - names == set()


@pytest.mark.slow
def test_installed_wheel_runs_outside_checkout(wheel, tmp_path):
    """Installed in a folder that is not this checkout, the commands find their configs."""
    site = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-index",
                        "--target", str(site), str(wheel)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    env = dict(os.environ, PYTHONPATH=str(site))  # site first: not this checkout's code

    def run(*args):
        p = subprocess.run([sys.executable, *args], cwd=tmp_path, env=env, capture_output=True,
                           text=True, timeout=120)
        assert p.returncode == 0, f"{args}: {p.stdout}{p.stderr}"
        return p.stdout

    out = run("-c", "import sys, harness.confdir as c, harness.method_registry as r; d = c.config_dir(); "
                    "print(r.builtin_methods()); assert 'eval' not in sys.modules; import harness; "
                    "print(harness.__file__); print(d)")
    assert out.splitlines() == ["('ARAP', 'Elastic', 'ARAP-SR', 'Implicit-ARAP', 'SShaDe', 'SShaDe+refine')",
                                str(site / "harness" / "__init__.py"),
                                str((site / "harness" / "conf").resolve())]
    assert "out: " in run("-m", "defaust", "--cfg", "job", "preset=ci", f"out={tmp_path / 'x'}")
    help_ = run("-m", "eval", "--help")
    assert "ci, convergence, export, faust, main," in help_ and "defaust/preset: ci, full" in help_
    run("-m", "eval", "--cfg", "job", "experiment=ci", f"dataset.root={tmp_path}")
    if importlib.util.find_spec("hydra_plugins.hydra_submitit_launcher") is not None:
        cfg = run("-m", "eval", "--cfg", "hydra", "hydra/launcher=slurm", f"dataset.root={tmp_path}")
        assert "array_parallelism: 64" in cfg  # conf/hydra/launcher/slurm.yaml was found
        # and the sweep launcher plugin of the wheel (hydra_plugins/sshade_sweep_launcher)
        assert "_target_: hydra_plugins.sshade_sweep_launcher.SweepSlurmLauncher" in cfg
        out = run("-c", "import hydra_plugins.sshade_sweep_launcher as p; print(p.__file__)")
        assert out.strip() == str(site / "hydra_plugins" / "sshade_sweep_launcher" / "__init__.py")

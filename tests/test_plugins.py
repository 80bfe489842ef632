"""Plug-in methods: an item of ``methods`` that is a ``_target_`` mapping is
built by hydra.utils.instantiate and runs through ``python -m eval`` beside ours; our
methods come from the ``method`` config group; the README's "Add your method" example is
the plug-in of tests/plugin_example.py and runs as printed."""
from __future__ import annotations

import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from eval.app import CONF_DIR
from eval.config_check import check_config, method_definition
from eval.method_config import make_methods
from harness.plugins import build_method
from sshade.arap.problems import box_surface
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env
from .plugin_example import MyMethod


def _readme_block() -> str:
    section = (ROOT / "README.md").read_text().split("## Add your method", 1)[1]
    m = re.search(r"```python\n(.*?)```", section, re.S)
    assert m, "no python block in the README's Add your method section"
    return m.group(1)


def _compose(overrides):
    from hydra import compose, initialize_config_dir
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=["dataset=faust", "dataset.root=x", *overrides])


class Raising:
    """A plug-in that fails with a plain (non-SShaDe) exception."""

    name = "Raising"

    def deform(self, V, F, handles, targets):
        raise RuntimeError("plug-in bug on purpose")


class NoDeform:
    name = "NoDeform"


# ------------------------------------------------------------------ README example

def test_readme_example_is_the_shipped_plugin():
    """The README block is tests/plugin_example.py's code, so the documented command
    with tests.plugin_example.MyMethod runs exactly what the README shows."""
    shipped = (ROOT / "tests" / "plugin_example.py").read_text().split("# --- README example ---\n", 1)[1]
    assert _readme_block() == shipped


def test_readme_example_runs_and_deforms():
    ns: dict = {}
    exec(compile(_readme_block(), "README.md", "exec"), ns)  # noqa: S102 -- our own README
    V, F = box_surface((2.0, 1.0, 1.0), 0.25)
    handles = np.flatnonzero(V[:, 0] > 2.0 - 1e-9)
    targets = V[handles] + [0.0, 0.0, 0.3]
    m = ns["MyMethod"](name="Mine", iterations=20)
    Vd = m.deform(V, F, handles, targets)
    assert m.name == "Mine" and m.info["iterations"] == 20
    np.testing.assert_allclose(Vd[handles], targets, atol=1e-12)
    lift = Vd[:, 2] - V[:, 2]
    # the displacement spreads from the handles and fades with distance from them
    assert lift.min() >= -1e-12 and lift.max() <= 0.3 + 1e-12
    near, far = V[:, 0] > 1.5, V[:, 0] < 0.5
    assert lift[near].mean() > lift[far].mean() >= 0


# ------------------------------------------------------------------ end to end

@pytest.mark.slow
def test_plugin_runs_through_python_m_eval(tmp_path, shared_data):
    """The README's command: its module saved as mymethod.py in the folder the command
    runs from, next to a method of ours; its row is in table.md, its info in cases.csv."""
    root = shared_data / "faust_reg"
    if not (root / "tr_reg_000.ply").is_file() or not (root / "tr_reg_001.ply").is_file():
        pytest.skip(f"FAUST subject 0 rest + pose 1 not found in {root}")
    (tmp_path / "mymethod.py").write_text(_readme_block())
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={root}", "dataset.limit=1",
                        "methods=[Elastic,{_target_:mymethod.MyMethod,name:Mine,iterations:20}]",
                        "arap.tol=1e-3", "reference.cases=none", f"out_dir={out}"],
                       cwd=tmp_path, env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    md = (out / "table.md").read_text()
    assert "| Mine |" in md and "| Elastic |" in md
    cases = pd.read_csv(out / "cases.csv", keep_default_na=False).set_index("method")
    assert cases.loc["Mine", "error"] == "" and float(cases.loc["Mine", "iterations"]) == 20
    assert float(cases.loc["Mine", "moved"]) > 0  # a numeric info entry of the plug-in
    assert float(cases.loc["Mine", "handle_err_pct"]) < 1e-9


def test_plugin_exception_is_recorded_and_run_goes_on(tmp_path, shared_data, monkeypatch):
    """A plug-in raising a plain exception gets `Type: message` in `error`; ours still run."""
    root = shared_data / "faust_reg"
    if not (root / "tr_reg_001.ply").is_file():
        pytest.skip("FAUST registrations not found")
    from eval.app import run
    cfg = _compose([f"dataset.root={root}", "dataset.limit=1", "reference.cases=none", f"out_dir={tmp_path}",
                    "methods=[{_target_:tests.test_plugins.Raising},{_target_:tests.plugin_example.MyMethod}]"])
    res = run(check_config(cfg))
    assert res["n_errors"] == 1
    cases = pd.read_csv(tmp_path / "cases.csv", keep_default_na=False).set_index("method")
    assert cases.loc["Raising", "error"] == "RuntimeError: plug-in bug on purpose"
    assert cases.loc["Mine", "error"] == ""


# ------------------------------------------------------------------ building methods

def test_method_group_is_composed_and_follows_the_shared_sections():
    cfg = _compose(["sshade.n_low=321", "arap.tol=1e-3", "method.Elastic.max_iter=7"])
    assert set(cfg.method) == {"ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "SShaDe", "SShaDe_refine"}
    assert cfg.method.SShaDe._target_ == "sshade.SShaDe" and cfg.method.SShaDe.n_low == 321
    cfg = _compose(["sshade.n_low=321", "arap.tol=1e-3", "method.Elastic.max_iter=7", "method.SShaDe.n_samplings=2",
                    "methods=[ARAP,Elastic,ARAP-SR,SShaDe,SShaDe+refine]"])
    ms = {m.name: m for m in make_methods(check_config(cfg).methods)}
    assert ms["ARAP"].tol == 1e-3 and ms["ARAP"].max_iter is None
    assert ms["Elastic"].max_iter == 7  # set on the method only
    assert ms["ARAP-SR"].max_iter == 10000  # arap.max_iter null -> the converged protocol's cap
    assert ms["SShaDe"].params["n_low"] == 321 and ms["SShaDe"].params["n_samplings"] == 2
    assert ms["SShaDe"].params["tol"] == 1e-3  # arap.tol, no sshade.tol given
    assert ms["SShaDe+refine"].params["n_samplings"] == 5


def test_plain_dict_config_reads_the_method_files():
    spec = method_definition({"arap": {"tol": 2e-3}, "sshade": {"n_low": 50, "tol": 5e-4}}, "sshade")
    assert spec["_target_"] == "sshade.SShaDe" and spec["n_low"] == 50 and spec["tol"] == 5e-4
    assert spec["protocol"] == "converged" and spec["n_samplings"] == 5  # defaults of conf/config.yaml
    assert method_definition({}, "ARAP-SR")["alpha"] == 0.01


def test_plugin_mapping_with_a_name_for_one_of_our_classes():
    mine = {"_target_": "sshade.SShaDe", "name": "SShaDe-500", "n_low": 500}
    ms = make_methods(check_config({"methods": ["SShaDe", mine]}).methods)
    assert [m.name for m in ms] == ["SShaDe", "SShaDe-500"] and ms[1].params["n_low"] == 500
    m = build_method({"_target_": "tests.plugin_example.MyMethod", "name": "Mine", "iterations": 3})
    assert isinstance(m, MyMethod) and m.name == "Mine" and m.iterations == 3


@pytest.mark.parametrize("item, message", [
    ({"iterations": 3}, "needs _target_"),
    ({"_target_": "no_such_pkg.Method"}, "cannot import _target_ 'no_such_pkg.Method'"),
    ({"_target_": "tests.plugin_example.Nope"}, "has no attribute 'Nope'"),
    ({"_target_": "tests.plugin_example.MyMethod", "bogus": 1}, "unexpected keyword argument 'bogus'"),
    ({"_target_": "tests.test_plugins.NoDeform"}, "no callable deform"),
    ({"_target_": "builtins.dict"}, "without a `name`"),
    ({"_target_": "sshade.SShaDe", "n_low": 2}, "n_low must be at least 4"),
    ("Nope", "unknown method 'Nope'"),
])
def test_bad_plugin_is_one_clear_error_at_build_time(item, message):
    with pytest.raises(SShaDeError, match=re.escape(message)) as e:
        make_methods(check_config({"methods": ["ARAP", item]}).methods)
    assert "\n" not in str(e.value)


def test_repeated_plugin_name_is_refused():
    with pytest.raises(SShaDeError, match="listed twice"):
        make_methods(check_config({"methods": [{"_target_": "tests.plugin_example.MyMethod"},
                                  {"_target_": "tests.plugin_example.MyMethod", "iterations": 5}]}).methods)


def test_two_method_names_of_one_file_name_are_refused_before_any_work():
    # "M a" and "M_a" would both store runs/<case>/M_a.json, one overwriting the other's records
    with pytest.raises(SShaDeError, match=r"would share the file name 'M_a'"):
        make_methods(check_config({"methods": [{"_target_": "tests.plugin_example.MyMethod", "name": "M a"},
                                               {"_target_": "tests.plugin_example.MyMethod", "name": "m_A"}]}).methods)


def test_bad_plugin_on_the_command_line_exits_2_with_one_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path}",
                        "methods=[{_target_:tests.test_plugins.NoDeform}]", f"out_dir={tmp_path / 'out'}"],
                       cwd=ROOT, env=subprocess_env(), capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [r.stderr.strip()] and "no callable deform" in r.stderr

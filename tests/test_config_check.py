"""eval/config_check.py: the checks every run shares; each dataset and experiment kind
brings its own (registered with it), so this module names none of them."""
from __future__ import annotations

import ast

import pytest
from omegaconf import OmegaConf

from eval.config_check import check_config
from eval.datasets import dataset_names
from eval.experiments import experiment_options, experiments
from eval.present.meshview import DEFAULT_MAX_FACES, DEFAULT_VIEW_CASES
from sshade.errors import SShaDeError

from .conftest import ROOT


def test_config_check_names_no_dataset_and_no_experiment():
    """No string of eval/config_check.py (docstrings aside) is a registered dataset's
    name or an experiment kind: their checks are theirs."""
    tree = ast.parse((ROOT / "eval" / "config_check.py").read_text())
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    assert not strings & (set(dataset_names()) | set(experiments()) - {"cases"})


def test_every_experiment_but_the_cases_one_reads_options_of_its_own():
    assert {k for k in experiments() if experiment_options(k) is None} <= {"cases"}


def test_the_registered_reader_is_what_check_config_runs(monkeypatch):
    """check_config reads the experiment kind's options with its registered reader,
    whatever it is, and hands them to the run in ``experiment.options``."""
    import eval.experiments.experiment_registry as reg
    cfg = OmegaConf.create({"experiment": {"kind": "tosca"}, "tosca": {"min_vertices": "abc"}})
    monkeypatch.setitem(reg._OPTIONS, "tosca", reg.OptionsReader("tosca", lambda v: ("read", v["min_vertices"])))
    assert check_config(cfg).experiment.options == ("read", "abc")  # the stand-in accepted what the real one refuses
    monkeypatch.undo()
    with pytest.raises(SShaDeError, match=r"tosca\.min_vertices"):
        check_config(cfg)


def test_check_config_makes_the_typed_run():
    """The door's output: frozen objects, each section typed (eval/run/spec.py)."""
    import dataclasses

    from eval.run.spec import EvalSpec
    spec = check_config(OmegaConf.create({"methods": ["ARAP", {"_target_": "tests.plugin_example.MyMethod"}],
                                          "timeout_s": 5, "jobs": "auto", "reference": {"cases": "2"},
                                          "report": {"enabled": False}, "compare_with": "results/x"}))
    assert isinstance(spec, EvalSpec) and spec.experiment.kind == "cases" and spec.dataset is None
    assert [m.name for m in spec.methods] == ["ARAP", None] and spec.methods[0].definition["_target_"]
    assert spec.guard.timeout_s == 5.0 and spec.jobs is None and spec.reference.cases == 2
    assert spec.report.views == 0 and spec.output.compare_with == ("results/x",)
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.jobs = 2


def test_report_defaults_are_the_config_files():
    """The code's defaults for a config without report keys (eval/present/meshview.py) are the
    values conf/config.yaml writes."""
    rep = OmegaConf.load(ROOT / "conf" / "config.yaml").report
    assert (rep.view_cases, rep.max_faces) == (DEFAULT_VIEW_CASES, DEFAULT_MAX_FACES)

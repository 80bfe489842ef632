"""eval/config_check.py: the checks every run shares; each dataset and experiment kind
brings its own (registered with it), so this module names none of them."""
from __future__ import annotations

import ast

import pytest
from omegaconf import OmegaConf

from eval.config_check import check_config
from eval.datasets import dataset_names
from eval.experiments import experiment_check, experiments
from eval.present.meshview import DEFAULT_MAX_FACES, DEFAULT_VIEW_CASES
from sshade.errors import SShaDeError

from .conftest import ROOT


def test_config_check_names_no_dataset_and_no_experiment():
    """No string of eval/config_check.py (docstrings aside) is a registered dataset's
    name or an experiment kind: their checks are theirs."""
    tree = ast.parse((ROOT / "eval" / "config_check.py").read_text())
    strings = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)}
    assert not strings & (set(dataset_names()) | set(experiments()) - {"cases"})


def test_every_experiment_but_the_cases_one_registers_a_check():
    assert {k for k in experiments() if experiment_check(k) is None} <= {"cases", "animation"}


def test_a_registered_check_is_what_check_config_runs(monkeypatch):
    """check_config calls the experiment kind's registered check, whatever it is."""
    seen = []
    import eval.experiments.experiment_registry as reg
    monkeypatch.setitem(reg._CHECKS, "tosca", lambda cfg: seen.append(cfg.tosca.min_vertices))
    check_config(OmegaConf.create({"experiment": {"kind": "tosca"}, "tosca": {"min_vertices": "abc"}}))
    assert seen == ["abc"]  # the stand-in accepted what the real check refuses
    monkeypatch.undo()
    with pytest.raises(SShaDeError, match=r"tosca\.min_vertices"):
        check_config(OmegaConf.create({"experiment": {"kind": "tosca"}, "tosca": {"min_vertices": "abc"}}))


def test_report_defaults_are_the_config_files():
    """The code's defaults for a config without report keys (eval/present/meshview.py) are the
    values conf/config.yaml writes."""
    rep = OmegaConf.load(ROOT / "conf" / "config.yaml").report
    assert (rep.view_cases, rep.max_faces) == (DEFAULT_VIEW_CASES, DEFAULT_MAX_FACES)

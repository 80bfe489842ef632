"""Every experiment reads SShaDe's parameters from one place, the method config
``method.SShaDe`` (default: the ``sshade`` section), checked at the door into
``EvalSpec.sshade`` (an ``SShaDeParams``), so ``sshade.*`` overrides reach each of them; no
experiment keeps a private copy (``tosca.n_low``, ...) or a wrapper of its own. Cheap: the
configs are composed and checked at the door, nothing runs."""
from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from eval.app import CONF_DIR
from eval.config_check import check_config
from eval.experiments import animation, convergence, experiments, pose_transfer, tosca
from eval.experiments.cases import cases_experiment as cases
from eval.experiments.scaling import scaling_experiment as scaling
from eval.method_config import make_methods

#: experiment (conf/experiment/NAME.yaml) -> its experiment module.
EXPERIMENTS = {"main": cases, "ci": cases, "faust": cases, "shapes": cases, "scaling": scaling, "tosca": tosca,
               "pose_transfer": pose_transfer, "convergence": convergence, "animation": animation, "score": cases}
#: experiment kinds that run no method, so read no SShaDe parameter (export: writes the cases' files).
NO_METHOD = {"export"}

#: The defaults the committed tables used (results/*/run.json) and the paper's.
DEFAULT_N_LOW = {"main": "auto", "ci": "auto", "faust": "auto", "shapes": "auto", "scaling": 6000, "tosca": 6000,
                 "pose_transfer": 1000, "convergence": "auto", "animation": "auto", "score": "auto"}
DEFAULT_N_SAMPLINGS = {"ci": 2, "tosca": 10}


def _compose(overrides):
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=list(overrides))


def _spec(overrides):
    """The checked config of ``overrides`` (:func:`eval.config_check.check_config`)."""
    return check_config(_compose(overrides))


def test_every_experiment_kind_is_covered():
    kinds = {str(OmegaConf.select(_compose([f"experiment={e}"]), "experiment.kind", default="cases"))
             for e in EXPERIMENTS}
    assert kinds == set(experiments()) - NO_METHOD


@pytest.mark.parametrize("exp", sorted(EXPERIMENTS))
def test_defaults_unchanged(exp):
    p = _spec([f"experiment={exp}"]).sshade
    assert p["n_low"] == DEFAULT_N_LOW[exp]
    assert p["n_samplings"] == DEFAULT_N_SAMPLINGS.get(exp, 5) and p["seed"] == 0


OVERRIDES = {"sshade.n_low": 123, "sshade.n_samplings": 3, "sshade.seed": 7, "sshade.workers": 1,
             "sshade.gradient": "raw"}


@pytest.mark.parametrize("exp", sorted(EXPERIMENTS))
def test_sshade_overrides_reach_every_experiment(exp):
    p = _spec([f"experiment={exp}", *(f"{k}={v}" for k, v in OVERRIDES.items())]).sshade
    for k, v in OVERRIDES.items():
        assert p[k.split(".", 1)[1]] == v, (exp, k, p)
    # method.SShaDe.* (the method's own key) is the same place
    p = _spec([f"experiment={exp}", "method.SShaDe.n_low=321"]).sshade
    assert p["n_low"] == 321


@pytest.mark.parametrize("exp", ["main", "ci", "shapes"])
def test_cases_experiment_builds_sshade_with_the_overrides(exp):
    """The cases experiment's SShaDe row is the method make_methods builds."""
    cfg = _compose([f"experiment={exp}", "methods=[SShaDe]", "sshade.n_low=123", "sshade.n_samplings=3"])
    (m,) = make_methods(check_config(cfg).methods)
    assert m.params["n_low"] == 123 and m.params["n_samplings"] == 3


def test_arap_stopping_rule_reaches_scaling_and_convergence():
    """SShaDe's low-res ARAP stopping rule: sshade.tol, else arap.tol (conf/method/SShaDe.yaml)."""
    for exp in ("scaling", "convergence"):
        assert _spec([f"experiment={exp}", "arap.tol=1e-3"]).sshade["tol"] == 1e-3
        assert _spec([f"experiment={exp}", "+sshade.tol=2e-3"]).sshade["tol"] == 2e-3
    ep = scaling.elastic_params(_spec(["experiment=scaling", "arap.protocol=paper", "arap.max_iter=50"]))
    assert ep["protocol"] == "paper" and ep["max_iter"] == 50


def test_convergence_sampling_counts_follow_n_samplings():
    spec = _spec(["experiment=convergence", "sshade.n_samplings=7"])
    opts = spec.experiment.options
    assert convergence.sampling_counts(opts, spec.sshade) == [1, 7] and opts.sshade.refine_k == 7
    spec = _spec(["experiment=convergence"])
    assert convergence.sampling_counts(spec.experiment.options, spec.sshade) == [1, 5]
    spec = _spec(["experiment=convergence", "convergence.sshade.k=[2,3]"])
    assert convergence.sampling_counts(spec.experiment.options, spec.sshade) == [2, 3]


@pytest.mark.parametrize("exp,key", [("scaling", "scaling.n_low"), ("tosca", "tosca.n_low"),
                                     ("pose_transfer", "pose_transfer.n_low"),
                                     ("convergence", "convergence.sshade.n_low")])
def test_no_private_copy_left(exp, key):
    """The former private copies are gone: setting one is an error, not silently ignored."""
    cfg = _compose([f"experiment={exp}"])
    assert OmegaConf.select(cfg, key, default="absent") == "absent"
    with pytest.raises(Exception, match="n_low"):
        _compose([f"experiment={exp}", f"{key}=500"])


def test_the_door_checks_sshades_parameters_once_into_one_object():
    """EvalSpec.sshade is SShaDe's checked parameters (SShaDeParams), made once at the door;
    no experiment module keeps a one-line wrapper returning them as a dict; a bad value of
    the method's own key is one error naming it."""
    from sshade.errors import SShaDeError
    from sshade.params import SShaDeParams
    assert type(_spec(["experiment=tosca"]).sshade) is SShaDeParams
    for mod in (cases, scaling, tosca, pose_transfer, convergence, animation):
        assert not hasattr(mod, "sshade_params"), mod.__name__
    with pytest.raises(SShaDeError, match=r"^method\.SShaDe\.n_samplings"):
        _spec(["method.SShaDe.n_samplings=0"])

"""The evaluator's Hydra entry point: ``python -m eval [overrides]``.
Floor 5 of eval/ (the commands, tests/test_layering.py); notes: docs/implementation.md.

Usage (from the repository root)::

    python -m eval dataset=faust dataset.root=../shared/data/faust_reg
    python -m eval experiment=ci dataset.root=DIR             # 2 cases, small settings
    python -m eval dataset.root=DIR methods=[ARAP,Elastic] out_dir=outputs/run
    python -m eval experiment=tosca                           # another experiment kind

Exit status: 0 on success (even if some method failed on some case), 2 on a
configuration or input error (one ``error: ...`` line on stderr)."""
from __future__ import annotations

import sys

from eval.config_check import check_config, check_values
from eval.config_schema import store_schemas
from eval.datasets import datasets
from eval.exchange.scored import ScoreConfig
from eval.experiments import experiments, find_experiment
from eval.experiments.cases.cases_experiment import run
from eval.report import safe_report
from eval.run.run_folder import claimed_run
from eval.run.spec import EvalSpec
from harness.checks import check_bool, config_value
from harness.command import hydra_main, run_command
from harness.confdir import config_dir
from sshade.errors import SShaDeError

__all__ = ["CONF_DIR", "run", "run_experiment", "run_spec", "main"]

CONF_DIR = config_dir()  # conf/ of a source checkout, else the installed package data
#: the modules that type a section of their own, imported before the config's types are
#: stored: every dataset's (:func:`eval.datasets.datasets`), every experiment kind's
#: (:func:`eval.experiments.experiments`) and ``score``'s
_SECTION_OWNERS = (*datasets().values(), *experiments().values(), ScoreConfig)
store_schemas()  # the config's types (eval/config_schema.py), before Hydra composes it


def run_experiment(cfg, *, fresh: bool = False):
    """Check the composed config ``cfg`` (:func:`eval.config_check.check_config`: every
    value, before any work, also for sweep jobs and the Python API) and run its
    experiment (:func:`run_spec`); ``fresh``: ``out_dir`` is the default dated name,
    which gets a suffix rather than being reused.

    Raises
    ------
    SShaDeError for a bad config value or an unknown ``experiment.kind`` (before any
    work), :class:`eval.run.outdir.OutputDirError` for a folder it may not write into.
    """
    return run_spec(check_config(cfg), fresh=fresh)


def run_spec(spec: EvalSpec, *, fresh: bool = False):
    """Run the checked config ``spec``: dispatch on ``experiment.kind`` through the
    experiment registry (:func:`eval.experiments.experiments`: one module per experiment),
    in its claimed output folder ``output.out_dir`` (:func:`eval.run.run_folder.claimed_run`:
    new, empty, or an earlier evaluator output, else refused before any work), which
    gets its browser report ``index.html`` at the end (:func:`eval.report.safe_report`,
    unless ``report.enabled`` is false).

    Raises
    ------
    :class:`eval.run.outdir.OutputDirError` for a folder it may not write into; whatever
    the experiment raises.
    """
    run_fn = find_experiment(spec.experiment.kind)
    with claimed_run(spec.output, record=spec.composed, fresh=fresh) as claim:
        if claim is not None:
            spec = spec.with_out_dir(claim.path)
        out = run_fn(spec)
        if spec.report.enabled:  # index.html, after the tables (eval/report.py; never fails the run)
            safe_report(spec.output.out_dir)
        return out


def _pin_out_dir(cfg) -> bool:
    """Pin ``out_dir`` once. In a multirun (``python -m eval -m``) it is the job's folder
    Hydra made (``hydra.sweep.dir/subdir``); in a single run it is ``out_dir`` resolved
    once (a ``${now:...}`` in it cannot name two folders). Returns True when ``out_dir``
    is the config's default (not given on the command line): a fresh name."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from omegaconf import open_dict
    if not HydraConfig.initialized():
        return False
    hc = HydraConfig.get()
    with open_dict(cfg):
        if hc.mode == RunMode.MULTIRUN and hc.runtime.output_dir:
            cfg.out_dir = str(hc.runtime.output_dir)
            return False
        cfg.out_dir = str(cfg.out_dir)
    given = {str(o).lstrip("+~").split("=", 1)[0] for o in hc.overrides.task}
    return "out_dir" not in given


def _refuse_fresh_resume(cfg, fresh: bool) -> None:
    """``resume=true`` continues the run of a folder named by ``out_dir=``; with the
    default dated ``out_dir`` (``fresh``) there is none to continue: SShaDeError."""
    if fresh and check_bool(config_value(cfg, "resume", False), "resume"):
        raise SShaDeError("resume=true needs the folder of the run to continue: pass out_dir=DIR, the folder "
                          "to resume (the default out_dir is a new folder)")


def _main(cfg) -> None:
    """Hydra task of ``python -m eval``: run the experiment; a bad config or input (e.g.
    ``resume=true`` without ``out_dir``), an OSError (``error: ...``, status 2) or Ctrl-C
    (``interrupted``, 130) ends the process through :func:`harness.command.run_command`."""
    fresh = _pin_out_dir(cfg)

    def work():
        _refuse_fresh_resume(cfg, fresh)  # before the folder is claimed: nothing is made
        return run_experiment(cfg, fresh=fresh)
    rc = run_command(work, where=cfg.get("out_dir"))
    if rc:
        raise SystemExit(rc)


def main() -> None:
    """Console entry point (``python -m eval``): Hydra parses the overrides.

    The command line is composed (Hydra refuses a value of the wrong type or an unknown
    key: eval/config_schema.py) and its values checked (:func:`eval.config_check.check_values`)
    before Hydra starts the run, the rest of the door (:func:`eval.config_check.check_config`,
    which resolves the whole config, ``${hydra:...}`` included) once it has, before the run
    folder is claimed; a refusal gives one ``error: ...`` line and exit status 2, Ctrl-C
    ``interrupted`` and 130 (:func:`harness.command.hydra_main`).
    """
    argv = sys.argv[1:]
    if any(a in ("-m", "--multirun") for a in argv) and not any("hydra.callbacks.sweep_aggregate" in a for a in argv):
        # a multirun claims its hydra.sweep.dir like python -m eval.sweeps does
        # (eval.sweeps.sweep_command.claim_sweep_dir)
        argv = [*argv, "++hydra.callbacks.sweep_aggregate._target_=eval.sweeps.sweep_command.AggregateSweepCallback"]
    hydra_main(_main, CONF_DIR, argv=argv, check=check_values)

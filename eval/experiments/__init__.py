"""The evaluator's experiments (``experiment.kind``), one module or package each, registered
by kind (:mod:`eval.experiments.experiment_registry`; :func:`eval.app.run_experiment` dispatches):
``cases`` (the default: every method on every case), ``scaling``, ``animation``, ``tosca``
(paper §4.2), ``pose_transfer`` (paper §4.3), ``convergence``; one module or package of
:mod:`eval.experiments` each, of the same name.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/experiments.md."""
from __future__ import annotations

from eval.experiments.experiment_registry import (
    OptionsReader,
    experiment_options,
    experiments,
    find_experiment,
    register_experiment,
)

__all__ = ["experiments", "find_experiment", "register_experiment", "experiment_options", "OptionsReader"]

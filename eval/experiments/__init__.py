"""The evaluator's experiments (``experiment.kind``), one module or package each, registered
by kind (:mod:`eval.experiments.experiment_registry`; :func:`eval.app.run_experiment` dispatches):

- ``cases`` (:mod:`eval.experiments.cases`): every method on every case of the
  configured dataset (FAUST, DeFAUST, shapes), metrics and tables; the default.
- ``scaling`` (:mod:`eval.experiments.scaling`): SShaDe against full-resolution Elastic
  on a set of meshes (one clean, two hard) at 200k and 1M vertices.
- ``animation`` (:mod:`eval.experiments.animation`): DeFAUST cases as frames from rest
  to target pose, per-frame time, error and jitter.
- ``tosca`` (:mod:`eval.experiments.tosca`): paper §4.2, non-rigid isometric deformations.
- ``pose_transfer`` (:mod:`eval.experiments.pose_transfer`): paper §4.3 on FAUST.
- ``convergence`` (:mod:`eval.experiments.convergence`): time to accuracy of the ARAP solvers.

Every experiment reads SShaDe's parameters from the method config ``method.SShaDe``
(default: the ``sshade`` section; :func:`eval.experiments.common.sshade_spec`), so
``sshade.n_low=500`` reaches each of them; each module's ``sshade_params(cfg)`` returns
the parameters it passes on.
"""
from __future__ import annotations

from eval.experiments.experiment_registry import experiment_check, experiments, find_experiment, register_experiment

__all__ = ["experiments", "find_experiment", "register_experiment", "experiment_check"]

"""The evaluator's experiments (``experiment.kind``), one module or package each, registered
by kind (:mod:`eval.experiments.experiment_registry`; :func:`eval.app.run_experiment` dispatches):
``cases`` (the default: every method on every case), ``scaling``, ``animation``, ``tosca``
(paper §4.2), ``pose_transfer`` (paper §4.3), ``convergence``; one module or package of
:mod:`eval.experiments` each, of the same name.
Floor 4 of eval/ (eval/experiments/, tests/test_layering.py); notes: docs/implementation.md."""
import lazy_loader

# bound on first use (SPEC 1): importing one experiment's module runs no registry, so a
# row's code identity holds only what its code reaches (docs/implementation.md)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "experiment_registry": ["OptionsReader", "experiment_options", "experiments", "find_experiment",
                            "register_experiment"],
})

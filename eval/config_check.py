"""Every number (and flag) the evaluator's config holds, checked in one place before any work.

On the evaluator's top floor beside :mod:`eval.app`, since it asks the datasets, the
experiment kinds, the case jobs and the report's views for their own checks and defaults.

:func:`check_config` reads each value with :func:`harness.checks.config_number` /
:func:`harness.checks.config_bool`, which raise :class:`~sshade.errors.SShaDeError` naming
the key and the value, so that
``arap.max_iter=inf``, ``dataset.limit=abc`` or ``reference.time_budget_s=junk`` give one
``error: ...`` line and exit status 2 before a folder is made or a method runs
(:func:`eval.app.main` calls it on the composed config before Hydra starts the run, and
:func:`eval.app.run_experiment` again, for sweep jobs and the Python API).
"""
from __future__ import annotations

from baselines.arap_sr_solver import ALPHA_SCALINGS
from eval.datasets import find_dataset
from eval.experiments import experiment_check
from eval.experiments.cases.case_jobs import check_jobs
from eval.present.meshview import DEFAULT_MAX_FACES, DEFAULT_VIEW_CASES
from eval.run.subset import check_baseline_cases, check_method_cases
from harness.checks import config_bool, config_number, config_value
from sshade.errors import SShaDeError
from sshade.pipeline import check_params

__all__ = ["check_config"]

_ABSENT = object()   # a default that tells an absent key apart from null


def _check_dataset(cfg) -> None:
    """The keys every dataset shares, then the dataset's own check (its registration,
    :class:`eval.datasets.dataset_registry.Dataset`)."""
    ds = config_value(cfg, "dataset", None)
    if ds is None:
        return
    config_number(cfg, "dataset.limit", min=1, allow_none=True, default=None)
    check_baseline_cases(config_value(cfg, "dataset.baseline_cases", None))
    check_method_cases(config_value(cfg, "method_cases", None))
    found = find_dataset(str(ds.get("name", "")))
    if found is not None and found.check is not None:
        found.check(cfg)


def _check_sshade(cfg) -> None:
    """``sshade.*`` through :func:`sshade.pipeline.check_params` (with the ``arap.*``
    fallbacks SShaDe's config uses), each error naming its config key."""
    sc = config_value(cfg, "sshade", None)
    if sc is None:
        return
    kw = {}
    for k in ("n_low", "n_samplings", "seed", "workers", "gradient", "anchor", "warm_start",
              "tol", "max_iter", "protocol", "etol", "gtol"):
        v = config_value(cfg, f"sshade.{k}", _ABSENT)
        if v is _ABSENT and k in ("tol", "max_iter", "protocol", "etol", "gtol"):
            v = config_value(cfg, f"arap.{k}", _ABSENT)  # conf/method/SShaDe.yaml: sshade.* else arap.*
        if v is not _ABSENT:
            kw[k] = v
    try:
        check_params(**kw)
    except SShaDeError as e:
        raise SShaDeError(str(e).replace("SShaDe: ", "sshade.", 1)) from None


def check_config(cfg) -> None:
    """Check every number and flag of an evaluator config before any work.

    Covers ``arap.*``, ``arap_sr.alpha``, ``sshade.*`` (:func:`sshade.pipeline.check_params`),
    the dataset's ``limit``, ``baseline_cases`` and ``method_cases`` and then its own
    check (registered with it, :func:`eval.datasets.register_dataset`), ``figures.enabled``
    / ``max_cases``, ``report.*``, ``reference.max_iter`` / ``time_budget_s``, ``jobs`` and
    the experiment kind's own check (registered with it,
    :func:`eval.experiments.register_experiment`). Absent keys are left to their readers'
    defaults.

    Raises
    ------
    SShaDeError naming the first bad key and its value.
    """
    if config_value(cfg, "arap", None) is not None:
        config_number(cfg, "arap.tol", kind=float, min=0, default=1e-4)
        if config_number(cfg, "arap.tol", kind=float, default=1e-4) <= 0:
            raise SShaDeError(f"arap.tol must be a finite number > 0, got {config_value(cfg, 'arap.tol')!r}")
        config_number(cfg, "arap.max_iter", min=1, allow_none=True, default=None)
        for k in ("etol", "gtol"):
            config_number(cfg, f"arap.{k}", kind=float, min=0, allow_none=True, default=None)
    config_number(cfg, "arap_sr.alpha", kind=float, min=0, default=0.01)
    scaling = config_value(cfg, "arap_sr.alpha_scaling", "valence")
    if scaling not in ALPHA_SCALINGS:
        raise SShaDeError(f"arap_sr.alpha_scaling must be one of {list(ALPHA_SCALINGS)}, got {scaling!r}")
    _check_sshade(cfg)
    _check_dataset(cfg)
    if config_value(cfg, "figures", None) is not None:
        config_bool(cfg, "figures.enabled", default=False)
    config_bool(cfg, "resume", default=False)
    check_jobs(config_value(cfg, "jobs", "auto"))
    if config_value(cfg, "report", None) is not None:
        config_bool(cfg, "report.enabled", default=True)
        config_number(cfg, "report.view_cases", min=0, allow_none=True, default=DEFAULT_VIEW_CASES)
        config_number(cfg, "report.max_faces", min=100, max=2_000_000, default=DEFAULT_MAX_FACES)
    if config_value(cfg, "store", None) is not None:
        config_bool(cfg, "store.meshes", default=False)
        config_number(cfg, "figures.max_cases", min=0, allow_none=True, default=None)
    if config_value(cfg, "reference", None) is not None:
        config_number(cfg, "reference.max_iter", min=1, default=50000)
        tb = config_number(cfg, "reference.time_budget_s", kind=float, min=0, allow_none=True, default=None)
        if tb is not None and tb <= 0:
            raise SShaDeError(f"reference.time_budget_s must be a finite number > 0 (or null), got {tb!r}")
    check = experiment_check(str(config_value(cfg, "experiment.kind", "cases")))
    if check is not None:
        check(cfg)

"""Every number (and flag) the evaluator's config holds, checked in one place before any work.

:func:`check_config` reads each value with :func:`sshade.checks.config_number` /
:func:`sshade.checks.config_bool`, which raise :class:`~sshade.errors.SShaDeError` naming the key and the value, so that
``arap.max_iter=inf``, ``dataset.limit=abc`` or ``reference.time_budget_s=junk`` give one
``error: ...`` line and exit status 2 before a folder is made or a method runs
(:func:`eval.app.main` calls it on the composed config before Hydra starts the run, and
:func:`eval.app.run_experiment` again, for sweep jobs and the Python API).
"""
from __future__ import annotations

from baselines.arap_sr_solver import ALPHA_SCALINGS
from sshade.checks import config_bool, config_int_list, config_number, config_value
from sshade.deform import check_params
from sshade.errors import SShaDeError

from .experiments.scaling_set import mesh_entries
from .subset import check_baseline_cases, check_method_cases

__all__ = ["check_config", "check_jobs"]

MAX_SEED = 2**63 - 1  # int64: seeds are recorded in CSV/JSON and passed to numpy
_ABSENT = object()   # a default that tells an absent key apart from null

#: dataset.name -> (key, kind, min, allow_none) of its numbers (eval.datasets.load_cases).
_DATASET_NUMBERS = {
    "faust": [("n_per_landmark", int, 1, False), ("neighbourhood", int, 1, False),
              ("static_threshold", float, 0, False), ("seed", int, 0, False)],
    "defaust": [],
    "shapes": [("n_per_group", int, 1, False), ("region_radius", float, 0, False),
               ("rotate_deg", float, None, False), ("translate", float, None, False), ("seed", int, 0, False)],
}

#: experiment.kind -> (section, [(key, kind, min, allow_none)]) of the other experiments.
_EXPERIMENT_NUMBERS = {
    "scaling": ("scaling", [("n_low", int, 4, False), ("n_samplings", int, 1, False), ("seed", int, 0, False),
                            ("workers", int, 1, True), ("tol", float, 0, False), ("max_iter", int, 1, True),
                            ("n_per_group", int, 1, False), ("region_radius", float, 0, False),
                            ("rotate_deg", float, None, False), ("translate", float, None, False),
                            ("elastic_budget_s", float, 0, False), ("elastic_max_vertices", int, 1, True),
                            ("first_call_timeout_s", float, 0, False), ("repeat", int, 1, False)]),
    "tosca": ("tosca", [("n_low", int, 4, False), ("n_samplings", int, 1, False), ("seed", int, 0, False),
                        ("min_vertices", int, 0, True), ("workers", int, 1, True)]),
    "pose_transfer": ("pose_transfer", [("n_low", int, 4, False), ("n_samplings", int, 1, False),
                                        ("seed", int, 0, False), ("workers", int, 1, True)]),
    "convergence": ("convergence", [("plane.lift", float, None, False), ("plane.n_target", int, 4, False),
                                    ("dataset_case", int, 0, False), ("time_budget_s", float, 0, False),
                                    ("stop_pct", float, 0, False), ("target_pct", float, 0, False),
                                    ("seed", int, 0, False), ("sshade.refine_k", int, 1, False),
                                    ("sshade.workers", int, 1, True)]),
}


def _check_list(cfg, checks, prefix: str) -> None:
    for key, kind, lo, none in checks:
        k = f"{prefix}.{key}"
        if config_value(cfg, k, _ABSENT) is _ABSENT:
            continue  # absent: the reader's default applies
        config_number(cfg, k, kind=kind, min=lo, max=MAX_SEED if key.endswith("seed") else None, allow_none=none)


def _check_dataset(cfg) -> None:
    ds = config_value(cfg, "dataset", None)
    if ds is None:
        return
    name = str(ds.get("name", "faust"))
    _check_list(cfg, _DATASET_NUMBERS.get(name, []), "dataset")
    for k in ("limit",):
        config_number(cfg, f"dataset.{k}", min=1, allow_none=True, default=None)
    check_baseline_cases(config_value(cfg, "dataset.baseline_cases", None))
    check_method_cases(config_value(cfg, "method_cases", None))
    for k in ("subjects", "poses"):
        if name != "shapes":
            config_int_list(cfg, f"dataset.{k}")
    if name == "shapes" and config_value(cfg, "dataset.vertex_range", None) is not None:
        vr = config_int_list(cfg, "dataset.vertex_range", min=4)
        if len(vr) != 2 or vr[0] > vr[1]:
            raise SShaDeError(f"dataset.vertex_range must be [lo, hi] with 4 <= lo <= hi, got {vr}")


def _check_sshade(cfg) -> None:
    """``sshade.*`` through :func:`sshade.deform.check_params` (with the ``arap.*``
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


def check_jobs(value) -> int | None:
    """``jobs`` (:mod:`eval.experiments.cases_jobs`) checked: an integer from 1 to 1024, or
    None for ``auto`` / null.

    Raises
    ------
    SShaDeError for any other value.

    >>> check_jobs("auto"), check_jobs(2)
    (None, 2)
    """
    if value is None or (isinstance(value, str) and value.strip().lower() == "auto"):
        return None
    if isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= 1024:
        return value
    raise SShaDeError(f"jobs must be an integer from 1 to 1024 or auto, got {value!r}")


def check_config(cfg) -> None:
    """Check every number and flag of an evaluator config before any work.

    Covers ``arap.*``, ``arap_sr.alpha``, ``sshade.*`` (:func:`sshade.deform.check_params`),
    the dataset's numbers (``limit``, ``baseline_cases``, ``seed``, handle parameters,
    subject/pose lists, ``vertex_range``), ``figures.enabled`` / ``max_cases``, ``report.*``,
    ``reference.max_iter`` / ``time_budget_s``, ``jobs`` and the section of the experiment kind
    (``scaling``, with its ``meshes`` entries, :func:`eval.experiments.scaling_set.mesh_entries`;
    ``tosca``, ``pose_transfer``, ``convergence``). Absent keys are left to
    their readers' defaults.

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
        config_number(cfg, "report.view_cases", min=0, allow_none=True, default=2)
        config_number(cfg, "report.max_faces", min=100, max=2_000_000, default=30000)
    if config_value(cfg, "store", None) is not None:
        config_bool(cfg, "store.meshes", default=False)
        config_number(cfg, "figures.max_cases", min=0, allow_none=True, default=None)
    if config_value(cfg, "reference", None) is not None:
        config_number(cfg, "reference.max_iter", min=1, default=50000)
        tb = config_number(cfg, "reference.time_budget_s", kind=float, min=0, allow_none=True, default=None)
        if tb is not None and tb <= 0:
            raise SShaDeError(f"reference.time_budget_s must be a finite number > 0 (or null), got {tb!r}")
    kind = str(config_value(cfg, "experiment.kind", "cases"))
    if kind in _EXPERIMENT_NUMBERS:
        section, checks = _EXPERIMENT_NUMBERS[kind]
        _check_list(cfg, checks, section)
    if kind == "convergence":
        config_int_list(cfg, "convergence.sshade.k", min=1, max=10_000)
    if kind == "scaling":
        config_int_list(cfg, "scaling.sizes", min=4)
        config_bool(cfg, "scaling.first_call", default=True)
        config_bool(cfg, "scaling.elastic", default=True)
        mesh_entries(cfg)  # every scaling.meshes entry's keys, before any mesh is built
    if kind in ("tosca", "pose_transfer"):
        config_int_list(cfg, f"{kind}.poses")

"""Every number (and flag) the evaluator's config holds, checked in one place before any work.

:func:`check_config` reads each value with :func:`config_number` / :func:`config_bool`
and raises :class:`~sshade.errors.SShaDeError` naming the key and the value, so that
``arap.max_iter=inf``, ``dataset.limit=abc`` or ``reference.time_budget_s=junk`` give one
``error: ...`` line and exit status 2 before a folder is made or a method runs
(:func:`eval.app.main` calls it on the composed config before Hydra starts the run, and
:func:`eval.app.run_experiment` again, for sweep jobs and the Python API).
"""
from __future__ import annotations

import math

from sshade.errors import SShaDeError

__all__ = ["config_number", "config_bool", "config_int_list", "check_config", "MAX_INT"]

MAX_INT = 2**31 - 1   # counts and iteration caps: int32 (numba kernels, libigl)
MAX_SEED = 2**63 - 1  # int64: seeds are recorded in CSV/JSON and passed to numpy
_MISSING = object()  # "no default": an absent key is an error
_ABSENT = object()   # a default that tells an absent key apart from null


def _get(cfg, key: str, default=_MISSING):
    """``cfg``'s value at the dotted ``key`` (``default`` when absent)."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException
    try:
        v = OmegaConf.select(cfg, key, default=_MISSING, throw_on_missing=True)
    except OmegaConfBaseException as e:
        raise SShaDeError(f"{key}: {' '.join(str(e).split())}") from None
    if v is _MISSING:
        if default is _MISSING:
            raise SShaDeError(f"{key} is not set")
        return default
    return v


def _describe(kind, lo, hi, allow_none) -> str:
    s = "an integer" if kind is int else "a finite number"
    if lo is not None and hi is not None:
        s += f" in [{lo}, {hi}]"
    elif lo is not None:
        s += f" >= {lo}"
    elif hi is not None:
        s += f" <= {hi}"
    return s + (" (or null)" if allow_none else "")


def config_number(cfg, key: str, *, kind=int, min=None, max=None, allow_none: bool = False,  # noqa: A002
                  default=_MISSING):
    """The number at ``key`` of an OmegaConf config, checked.

    Parameters
    ----------
    cfg : DictConfig (or anything ``OmegaConf.select`` reads).
    key : dotted key, e.g. ``"dataset.limit"``.
    kind : ``int`` or ``float``. An int may be written as an integral float (``1e3``);
        a bool, NaN, inf, a string or a value beyond ``max`` is refused.
    min, max : inclusive bounds (ints default to at most :data:`MAX_INT`).
    allow_none : accept ``null`` (returned as None).
    default : returned when the key is absent (else an absent key is an error).

    Returns
    -------
    int, float or None.

    Raises
    ------
    SShaDeError ``"<key> must be an integer >= 1 (or null), got 'abc'"``.

    Examples
    --------
    >>> from omegaconf import OmegaConf
    >>> config_number(OmegaConf.create({"d": {"limit": 4}}), "d.limit", min=1)
    4
    """
    v = _get(cfg, key, default)
    if v is None and allow_none:
        return None
    hi = MAX_INT if (kind is int and max is None) else max
    bad = SShaDeError(f"{key} must be {_describe(kind, min, max if kind is float else hi, allow_none)}, got {v!r}")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise bad
    if not math.isfinite(v):
        raise bad
    if kind is int:
        if v != int(v):
            raise bad
        v = int(v)
    else:
        v = float(v)
    if (min is not None and v < min) or (hi is not None and v > hi):
        raise bad
    return v


def config_bool(cfg, key: str, *, default=_MISSING) -> bool:
    """The flag at ``key`` (YAML ``true``/``false`` only; ``maybe`` or ``1`` is refused).

    Raises
    ------
    SShaDeError naming the key and the value.
    """
    v = _get(cfg, key, default)
    if not isinstance(v, bool):
        raise SShaDeError(f"{key} must be true or false, got {v!r}")
    return v


def config_int_list(cfg, key: str, *, min=0, max=MAX_INT, allow_none: bool = True):  # noqa: A002
    """A list of integers (or one integer) at ``key``, e.g. ``dataset.subjects``; None when
    null and allowed. Raises SShaDeError naming the key and the bad element."""
    from omegaconf import OmegaConf
    v = _get(cfg, key, None)
    if v is None:
        if allow_none:
            return None
        raise SShaDeError(f"{key} must be a list of integers, got null")
    items = OmegaConf.to_container(v) if OmegaConf.is_config(v) else v
    items = list(items) if isinstance(items, (list, tuple)) else [items]
    out = []
    for x in items:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or x != int(x) \
                or not min <= x <= max:
            raise SShaDeError(f"{key} must be a list of integers in [{min}, {max}], got {x!r} in {items!r}")
        out.append(int(x))
    return out


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
                            ("elastic_budget_s", float, 0, False), ("elastic_max_vertices", int, 1, True)]),
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
        if _get(cfg, k, _ABSENT) is _ABSENT:
            continue  # absent: the reader's default applies
        config_number(cfg, k, kind=kind, min=lo, max=MAX_SEED if key.endswith("seed") else None, allow_none=none)


def _check_dataset(cfg) -> None:
    ds = _get(cfg, "dataset", None)
    if ds is None:
        return
    name = str(ds.get("name", "faust"))
    _check_list(cfg, _DATASET_NUMBERS.get(name, []), "dataset")
    for k in ("limit",):
        config_number(cfg, f"dataset.{k}", min=1, allow_none=True, default=None)
    config_number(cfg, "dataset.baseline_cases", min=0, allow_none=True, default=None)
    for k in ("subjects", "poses"):
        if name != "shapes":
            config_int_list(cfg, f"dataset.{k}")
    if name == "shapes" and _get(cfg, "dataset.vertex_range", None) is not None:
        vr = config_int_list(cfg, "dataset.vertex_range", min=4)
        if len(vr) != 2 or vr[0] > vr[1]:
            raise SShaDeError(f"dataset.vertex_range must be [lo, hi] with 4 <= lo <= hi, got {vr}")


def _check_sshade(cfg) -> None:
    """``sshade.*`` through :func:`sshade.deform.check_params` (with the ``arap.*``
    fallbacks SShaDe's config uses), each error naming its config key."""
    from sshade.deform import check_params
    sc = _get(cfg, "sshade", None)
    if sc is None:
        return
    kw = {}
    for k in ("n_low", "n_samplings", "seed", "workers", "gradient", "warm_start",
              "tol", "max_iter", "protocol", "etol", "gtol"):
        v = _get(cfg, f"sshade.{k}", _ABSENT)
        if v is _ABSENT and k in ("tol", "max_iter", "protocol", "etol", "gtol"):
            v = _get(cfg, f"arap.{k}", _ABSENT)  # conf/method/SShaDe.yaml: sshade.* else arap.*
        if v is not _ABSENT:
            kw[k] = v
    try:
        check_params(**kw)
    except SShaDeError as e:
        raise SShaDeError(str(e).replace("SShaDe: ", "sshade.", 1)) from None


def check_config(cfg) -> None:
    """Check every number and flag of an evaluator config before any work.

    Covers ``arap.*``, ``arap_sr.alpha``, ``sshade.*`` (:func:`sshade.deform.check_params`),
    the dataset's numbers (``limit``, ``baseline_cases``, ``seed``, handle parameters,
    subject/pose lists, ``vertex_range``), ``figures.enabled`` / ``max_cases``,
    ``reference.max_iter`` / ``time_budget_s`` and the section of the experiment kind
    (``scaling``, ``tosca``, ``pose_transfer``, ``convergence``). Absent keys are left to
    their readers' defaults.

    Raises
    ------
    SShaDeError naming the first bad key and its value.
    """
    if _get(cfg, "arap", None) is not None:
        config_number(cfg, "arap.tol", kind=float, min=0, default=1e-4)
        if config_number(cfg, "arap.tol", kind=float, default=1e-4) <= 0:
            raise SShaDeError(f"arap.tol must be a finite number > 0, got {_get(cfg, 'arap.tol')!r}")
        config_number(cfg, "arap.max_iter", min=1, allow_none=True, default=None)
        for k in ("etol", "gtol"):
            config_number(cfg, f"arap.{k}", kind=float, min=0, allow_none=True, default=None)
    config_number(cfg, "arap_sr.alpha", kind=float, min=0, default=0.01)
    _check_sshade(cfg)
    _check_dataset(cfg)
    if _get(cfg, "figures", None) is not None:
        config_bool(cfg, "figures.enabled", default=False)
        config_number(cfg, "figures.max_cases", min=0, allow_none=True, default=None)
    if _get(cfg, "reference", None) is not None:
        config_number(cfg, "reference.max_iter", min=1, default=50000)
        tb = config_number(cfg, "reference.time_budget_s", kind=float, min=0, allow_none=True, default=None)
        if tb is not None and tb <= 0:
            raise SShaDeError(f"reference.time_budget_s must be a finite number > 0 (or null), got {tb!r}")
    kind = str(_get(cfg, "experiment.kind", "cases"))
    if kind in _EXPERIMENT_NUMBERS:
        section, checks = _EXPERIMENT_NUMBERS[kind]
        _check_list(cfg, checks, section)
    if kind == "convergence":
        config_int_list(cfg, "convergence.sshade.k", min=1, max=10_000)
    if kind == "scaling":
        config_int_list(cfg, "scaling.sizes", min=4)
    if kind in ("tosca", "pose_transfer"):
        config_int_list(cfg, f"{kind}.poses")

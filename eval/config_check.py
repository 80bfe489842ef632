"""The evaluator's door: the composed config checked once, before any work, and made into
the typed run (:class:`eval.run.spec.EvalSpec`) that everything below takes instead.
On the evaluator's top floor beside :mod:`eval.app`: it asks the datasets, the experiment
kinds, the case jobs and the report's views for their own checks and defaults.

Hydra has refused a value of the wrong type or an unknown key (eval/config_schema.py);
:func:`check_config` checks what a type cannot say (ranges, words, integer lists, the
methods' names), each refusal an :class:`~sshade.errors.SShaDeError` naming the key and the
value (``arap.tol=nan``, ``dataset.limit=0``): one ``error: ...`` line, exit status 2, before
a folder is made or a method runs. :func:`eval.app.main` calls it on the composed config
before Hydra starts the run, :func:`eval.app.run_experiment` again (sweep jobs, Python API)."""
from __future__ import annotations

import copy
from collections.abc import Mapping

from eval.config_schema import typed_object
from eval.datasets import dataset_named
from eval.experiments import experiment_options, experiments, find_experiment
from eval.experiments.cases.case_jobs import check_jobs
from eval.experiments.cases.pair import guard_options
from eval.method_config import arap_params, check_alpha, method_entries
from eval.run.run_folder import overwrite_flag
from eval.run.spec import (
    DatasetSpec,
    EvalSpec,
    ExperimentSpec,
    FigureOptions,
    OutputOptions,
    ReferenceOptions,
    ReportOptions,
)
from eval.run.subset import check_method_cases
from harness.checks import check_bool, check_number, config_value
from harness.method_registry import (
    SECTIONS,
    builtin_methods,
    canonical_name,
    file_spec,
    method_key,
    method_meta,
    strip_meta,
)
from harness.plugins import as_dict
from sshade.arap import ALPHA_SCALINGS, DEFAULT_ALPHA
from sshade.errors import SShaDeError
from sshade.params import SShaDeParams
from sshade.pipeline import SShaDe, check_params

__all__ = ["check_config", "check_values", "method_definition", "plain"]

_ABSENT = object()   # a default that tells an absent key apart from null


def _check_sshade(cfg) -> None:
    """``sshade.*`` through :func:`sshade.pipeline.check_params` (with the ``arap.*``
    fallbacks SShaDe's config uses), each error naming its config key."""
    sc = config_value(cfg, "sshade", None)
    if sc is None:
        return
    kw = {}
    for k in ("n_low", "n_samplings", "seed", "workers", "gradient", "anchor", "warm_start", "energy",
              "transfer", "average",
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


def check_values(cfg) -> None:
    """Check every number and flag of an evaluator config (the checks a type cannot say).

    Covers ``arap.*``, ``arap_sr.alpha``, ``sshade.*`` (:func:`sshade.pipeline.check_params`),
    ``method_cases``, the ``dataset`` section (its dataset's options object, registered with
    it: :func:`eval.datasets.register_dataset`), ``figures.enabled`` / ``max_cases``,
    ``report.*``, ``reference.max_iter`` / ``time_budget_s`` and ``jobs``. Absent keys are
    left to their readers' defaults.

    Raises
    ------
    SShaDeError naming the first bad key and its value.
    """
    if config_value(cfg, "arap", None) is not None:
        tol = config_value(cfg, "arap.tol", 1e-4)
        if check_number(tol, "arap.tol", kind=float, min=0) <= 0:
            raise SShaDeError(f"arap.tol must be a finite number > 0, got {tol!r}")
        check_number(config_value(cfg, "arap.max_iter", None), "arap.max_iter", min=1, allow_none=True)
        for k in ("etol", "gtol"):
            check_number(config_value(cfg, f"arap.{k}", None), f"arap.{k}", kind=float, min=0, allow_none=True)
    check_number(config_value(cfg, "arap_sr.alpha", DEFAULT_ALPHA), "arap_sr.alpha", kind=float, min=0)
    scaling = config_value(cfg, "arap_sr.alpha_scaling", "valence")
    if scaling not in ALPHA_SCALINGS:
        raise SShaDeError(f"arap_sr.alpha_scaling must be one of {list(ALPHA_SCALINGS)}, got {scaling!r}")
    _check_sshade(cfg)
    check_method_cases(config_value(cfg, "method_cases", None))
    resolved = plain(cfg)
    _dataset(resolved)
    check_bool(config_value(cfg, "resume", False), "resume")
    check_jobs(config_value(cfg, "jobs", "auto"))
    if config_value(cfg, "store", None) is not None:
        check_bool(config_value(cfg, "store.meshes", False), "store.meshes")
    _run_sections(resolved)


def check_config(cfg) -> EvalSpec:
    """The composed config checked (:func:`check_values`, then the experiment kind's own
    options, the methods' names, the guard, the references, the output) and made into
    the typed run.

    Parameters
    ----------
    cfg : the composed config (an OmegaConf DictConfig; a plain mapping works too, its
        absent keys taking their readers' defaults).

    Returns
    -------
    :class:`eval.run.spec.EvalSpec`.

    Raises
    ------
    SShaDeError naming the first bad key and its value, or an unknown ``experiment.kind``
    or method name; OmegaConf's error for a value that does not resolve.
    """
    check_values(cfg)
    resolved, composed = plain(cfg), plain(cfg, resolve=False)
    experiment = _experiment(resolved)
    definitions = {name: method_definition(cfg, name) for name in builtin_methods()}
    methods = method_entries(resolved["methods"], definitions) if "methods" in resolved else ()
    _check_shared_sections(resolved, methods)
    return EvalSpec(experiment=experiment, dataset=_dataset(resolved), methods=methods, definitions=definitions,
                    sshade=_sshade_params(definitions[SShaDe.name]),
                    guard=guard_options(**{k: resolved[k] for k in ("timeout_s", "handle_error_max_pct")
                                           if k in resolved}),
                    **_run_sections(resolved),
                    output=_output(cfg), jobs=check_jobs(resolved.get("jobs", "auto")),
                    method_cases=resolved.get("method_cases"), resolved=resolved, composed=composed)


def _sshade_params(definition) -> SShaDeParams:
    """SShaDe's parameters of its resolved definition ``method.SShaDe`` (``_target_`` and
    ``name`` left out), checked; SShaDeError naming the key ``method.SShaDe.<key>``."""
    try:
        return check_params(**{k: v for k, v in definition.items() if k not in ("_target_", "name")})
    except SShaDeError as e:
        raise SShaDeError(str(e).replace("SShaDe: ", "method.SShaDe.", 1)) from None


def _check_shared_sections(resolved: dict, methods) -> None:
    """With one of our methods listed, the sections their files default to, under their
    own names: ``arap`` (:func:`eval.method_config.arap_params`) and, for ARAP-SR's checks,
    ``arap_sr.alpha``."""
    ours = [m.name for m in methods if m.name is not None]
    if not ours:
        return
    arap_params(resolved.get("arap") or {})
    if any(method_meta(n)["checks"] == "arap_sr" for n in ours):
        alpha = (resolved.get("arap_sr") or {}).get("alpha")
        check_alpha(DEFAULT_ALPHA if alpha is None else alpha, "arap_sr.alpha")


def plain(cfg, *, resolve: bool = True) -> dict:
    """``cfg`` (a config or a plain mapping) as plain dicts and lists, its interpolations
    resolved unless ``resolve`` is false (a missing value stays ``???``)."""
    from omegaconf import OmegaConf
    if OmegaConf.is_config(cfg):
        return OmegaConf.to_container(cfg, resolve=resolve)
    return copy.deepcopy(dict(cfg))


def _experiment(resolved: dict) -> ExperimentSpec:
    """``experiment.name`` and ``experiment.kind`` (a registered kind), with the kind's own
    options read from its section (:func:`eval.experiments.register_experiment`)."""
    exp = resolved.get("experiment") or {}
    kind = str(exp.get("kind", "cases"))
    if find_experiment(kind) is None:
        raise SShaDeError(f"unknown experiment.kind {kind!r}; choose among {sorted(experiments())}")
    reader = experiment_options(kind)
    options = None if reader is None else reader.read(resolved.get(reader.section))
    return ExperimentSpec(name=str(exp.get("name") or ""), kind=kind, options=options)


def _dataset(resolved: dict) -> DatasetSpec | None:
    """The ``dataset`` section as its dataset's options object (the dataclass registered
    with ``dataset.name``, :func:`eval.datasets.register_dataset`), made and checked by
    :func:`eval.config_schema.typed_object`; a ``root`` not set (``???``, FAUST's default)
    is None there, refused only where it is read (:func:`eval.datasets.dataset_root`). None without a
    section; SShaDeError naming the key for a bad value, or an unknown dataset."""
    ds = resolved.get("dataset")
    if ds is None:
        return None
    if not isinstance(ds, Mapping):
        raise SShaDeError(f"dataset must be a section of keys, got {ds!r}")
    options = dataset_named(str(ds.get("name", ""))).options
    values = {**ds, "root": None} if ds.get("root", options.root) == "???" else ds  # absent: its default
    return DatasetSpec(options=typed_object(options, values, "dataset"))


#: The sections typed by the run's own objects (:mod:`eval.run.spec`), checked when made.
_RUN_SECTIONS = {"reference": ReferenceOptions, "report": ReportOptions, "figures": FigureOptions}


def _run_sections(resolved: dict) -> dict:
    """``{name: object}`` of each section of :data:`_RUN_SECTIONS` in ``resolved``, its
    schema's instance (:func:`eval.config_schema.typed_object`), every default without it."""
    return {name: typed_object(schema, resolved.get(name), name) for name, schema in _RUN_SECTIONS.items()}


def _output(cfg) -> OutputOptions:
    """Where the run of ``cfg`` writes: ``out_dir``, ``overwrite``, ``resume``,
    ``store.meshes`` and ``compare_with`` (a folder or a list of folders), checked.

    Raises
    ------
    SShaDeError on a flag that is not true or false, or a ``compare_with`` entry that is
    not a folder name.
    """
    from omegaconf import OmegaConf
    items = config_value(cfg, "compare_with", None)
    items = OmegaConf.to_container(items, resolve=True) if OmegaConf.is_config(items) else items
    items = [] if items is None else list(items) if isinstance(items, (list, tuple)) else [items]
    for it in items:
        if not isinstance(it, str) or not it.strip():
            raise SShaDeError(f"compare_with must be a list of run folders, got {it!r}")
    out_dir = config_value(cfg, "out_dir", "")
    return OutputOptions(out_dir=str(out_dir or ""), overwrite=overwrite_flag(config_value(cfg, "overwrite", False)),
                         resume=overwrite_flag(config_value(cfg, "resume", False)),
                         store_meshes=check_bool(config_value(cfg, "store.meshes", False), "store.meshes"),
                         compare_with=tuple(items))


def method_definition(cfg, name: str) -> dict:
    """The resolved definition (``_target_`` and parameters) of our method ``name``.

    ``cfg.method.<key>`` when the config has it (composed from ``conf/method/`` by
    ``conf/config.yaml``), else ``conf/method/<name>.yaml`` resolved against ``cfg``'s
    ``arap`` / ``arap_sr`` / ``sshade`` sections merged over the defaults of
    ``conf/config.yaml`` (:func:`harness.method_registry.file_spec`; so a plain dict config
    works, and so does a method file that the defaults list does not name). Without the
    file's ``order`` (:data:`harness.method_registry.META_KEYS`).

    Raises
    ------
    SShaDeError on an unknown name or a definition that does not resolve.

    Examples
    --------
    >>> method_definition({"arap": {"tol": 1e-3}}, "elastic")["tol"]
    0.001
    """
    from omegaconf.errors import OmegaConfBaseException
    name = canonical_name(name)
    section = (cfg.get("method", None) or {}).get(method_key(name), None)
    if section is None:
        return file_spec(name, {k: cfg.get(k, None) for k in SECTIONS})
    try:
        return strip_meta(as_dict(section))
    except OmegaConfBaseException as e:
        raise SShaDeError(f"method.{method_key(name)}: bad definition ({e})") from None

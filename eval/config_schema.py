"""The types of the evaluator's Hydra config, registered with Hydra's ConfigStore.
Floor 1 of eval/ (tests/test_layering.py); the checks a type cannot say: eval/config_check.py.

``conf/config.yaml`` starts its defaults list with ``config_schema`` (:func:`top_schema`;
``reference``, ``report``, ``figures`` typed by :mod:`eval.run.spec`'s objects); each file
of ``conf/dataset/`` extends the options dataclass its dataset module registers
(``schema/dataset/<name>``, :func:`register_dataset_schema`), each experiment with a section
of its own the dataclass its module registers (:func:`section_reader`), each method file
``schema/method/<name>``. Composition refuses a wrong type or an unknown key with
Hydra's own message; the door makes each section's object with ``OmegaConf.to_object``
(:func:`typed_object`), which runs its checks. A key of several types (``sshade.n_low``:
``auto`` or an integer) is ``Any`` (OmegaConf has no unions), typed at the door."""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field, make_dataclass
from typing import Any, Dict, List, Optional  # OmegaConf 2.3 reads typing's generics

from omegaconf import MISSING, OmegaConf

from baselines.coarse_start import COARSE_N_LOW
from eval.run.spec import FigureOptions, ReferenceOptions, ReportOptions
from harness.method_registry import builtin_methods, method_file, method_key
from sshade.arap import DEFAULT_ALPHA
from sshade.errors import SShaDeError

__all__ = ["ArapSchema", "ArapSRSchema", "SShaDeSchema", "StoreSchema", "ExperimentSchema", "TopSchema",
           "register_dataset_schema", "dataset_schemas", "register_section", "section_reader", "section_schemas",
           "typed_object", "typed_section", "ClusterSchema", "method_schemas", "top_schema", "store_schemas"]


# ----------------------------------------------------------------------------- conf/config.yaml
@dataclass
class ArapSchema:
    """``arap``: the full-resolution baselines' protocol and stopping rule."""

    protocol: str = "converged"
    tol: float = 1.0e-4
    max_iter: Optional[int] = None
    etol: Optional[float] = None
    gtol: Optional[float] = None
    coarse_n_low: int = COARSE_N_LOW


@dataclass
class ArapSRSchema:
    """``arap_sr``: ARAP-SR's smoothness weight."""

    alpha: float = DEFAULT_ALPHA
    alpha_scaling: str = "valence"


@dataclass
class SShaDeSchema:
    """``sshade``: SShaDe's parameters (``n_low``: ``auto`` or an integer). The optional
    ``tol``, ``max_iter``, ``protocol``, ``etol``, ``gtol`` are added with ``+sshade.KEY=``."""

    n_low: Any = "auto"
    n_samplings: int = 5
    seed: int = 0
    workers: Optional[int] = None
    gradient: str = "normalized"
    anchor: str = "projection"
    energy: str = "spokes_and_rims"
    transfer: str = "vertex"
    average: str = "uniform"
    warm_start: bool = True


@dataclass
class StoreSchema:
    """``store``: what the result store keeps beside each row."""

    meshes: bool = False


@dataclass
class ExperimentSchema:
    """``experiment``: its name; ``kind`` (default ``cases``) is added by the experiments
    that have one and checked against the registered kinds."""

    name: str = MISSING


@dataclass
class TopSchema:
    """The top level of ``conf/config.yaml``, in its order. ``methods`` (a list, or one
    name), ``jobs`` (``auto`` or an integer) and ``compare_with`` (a folder or a list) hold
    several types; ``method_cases`` is null or a mapping (a null typed mapping takes no
    override in OmegaConf 2.3); ``dataset`` is typed by its own dataset's options. The sections
    typed by :mod:`eval.run.spec`'s objects have no default here (``???``: conf/config.yaml
    sets them), so that building this schema does not make (and check) one."""

    methods: Any = MISSING
    timeout_s: Optional[float] = None
    handle_error_max_pct: Optional[float] = 1.0
    figures: FigureOptions = MISSING
    report: ReportOptions = MISSING
    arap: ArapSchema = field(default_factory=ArapSchema)
    method_cases: Any = None
    jobs: Any = "auto"
    reference: ReferenceOptions = MISSING
    arap_sr: ArapSRSchema = field(default_factory=ArapSRSchema)
    sshade: SShaDeSchema = field(default_factory=SShaDeSchema)
    out_dir: str = MISSING
    overwrite: bool = False
    compare_with: Any = None
    resume: bool = False
    store: StoreSchema = field(default_factory=StoreSchema)
    dataset: Any = None
    experiment: ExperimentSchema = field(default_factory=ExperimentSchema)


# ----------------------------------------------------------------------------- conf/dataset/
#: ``schema/dataset/<name>``: the type each file of ``conf/dataset/`` extends, the options
#: dataclass its dataset module registers (:func:`eval.datasets.register_dataset`).
_DATASETS: dict[str, type] = {}


def register_dataset_schema(name: str, schema: type) -> type:
    """Register dataclass ``schema`` as the type of dataset ``name``'s section (stored as
    ``schema/dataset/<name>`` by :func:`store_schemas`); called by
    :func:`eval.datasets.register_dataset`. Returns ``schema``. ValueError for a second
    class under one name (a programming error)."""
    old = _DATASETS.setdefault(str(name), schema)
    if old is not schema:
        raise ValueError(f"dataset {name!r} already typed by {old.__qualname__}")
    return schema


def dataset_schemas() -> dict[str, type]:
    """``{name: schema}`` of every registered dataset (the dataset modules imported first:
    :func:`eval.datasets.datasets`)."""
    return dict(sorted(_DATASETS.items()))


# ----------------------------------------------------------------------------- conf/experiment/
#: ``schema/experiment/<section>``: the type of each top-level section an experiment adds,
#: registered by the module that reads it (:func:`register_section`).
_SECTIONS: dict[str, type] = {}


def register_section(name: str, schema: type) -> type:
    """Register dataclass ``schema`` as the type of the top-level section ``name`` (stored as
    ``schema/experiment/<name>`` by :func:`store_schemas`); called by the module that owns
    the section, whose options are then the schema's own instance (:func:`typed_section`).
    Returns ``schema``. ValueError for a second class under one name (a programming error)."""
    old = _SECTIONS.setdefault(str(name), schema)
    if old is not schema:
        raise ValueError(f"config section {name!r} already typed by {old.__qualname__}")
    return schema


def section_reader(name: str, schema: type, *, absent: str = ""):
    """Register ``schema`` as section ``name``'s type (:func:`register_section`) and return
    its reader for :func:`eval.experiments.register_experiment`: ``read(values)`` is
    :func:`typed_section` of the section (``absent``: what to do without one)."""
    register_section(name, schema)
    return functools.partial(typed_section, name, absent=absent)


def section_schemas() -> dict[str, type]:
    """``{section: schema}`` of every registered section (the modules that register them
    imported first: :func:`eval.experiments.experiments` and :mod:`eval.exchange.scored`)."""
    return dict(sorted(_SECTIONS.items()))


def typed_object(schema: type, values, where: str):
    """``schema``'s instance from ``values`` (plain values of the section ``where``; None:
    every default): merged into the schema and made by ``OmegaConf.to_object``, which runs
    the schema's own checks (its ``__post_init__``: ranges, words, lists) and normalises.

    Raises
    ------
    SShaDeError, one line naming the key: a section that is not a mapping, an unknown key, a
    value of the wrong type, a required key not set (the schema's ``REQUIRED`` says what to
    pass), or the schema's own refusal.
    """
    from collections.abc import Mapping

    from omegaconf.errors import ConfigKeyError, MissingMandatoryValue, ValidationError

    if values is not None and not (isinstance(values, Mapping) or OmegaConf.is_dict(values)):
        raise SShaDeError(f"{where} must be a section of keys, got {values!r}")
    try:
        return OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(schema), values or {}))
    except MissingMandatoryValue as e:
        key = f"{where}.{e.full_key}"
        what = getattr(schema, "REQUIRED", {}).get(str(e.full_key), "VALUE")
        raise SShaDeError(f"{key} is not set: pass {key}={what}") from None
    except ConfigKeyError as e:
        raise SShaDeError(f"{where}.{e.full_key}: unknown key (the keys: {', '.join(schema.__dataclass_fields__)})") \
            from None
    except ValidationError as e:
        key = f"{where}.{e.full_key}" if e.full_key else where
        raise SShaDeError(f"{key}: {str(e).splitlines()[0]}") from None


def typed_section(name: str, values, *, absent: str = ""):
    """Registered section ``name``'s options (:func:`typed_object` of its schema);
    SShaDeError when the config has no such section (``absent`` says what to do)."""
    if values is None:
        raise SShaDeError(f"no `{name}` section in the config; {absent}".rstrip("; "))
    return typed_object(_SECTIONS[name], values, name)


# ----------------------------------------------------------------------------- conf/cluster/
@dataclass
class ClusterSchema:
    """``cluster`` (``cluster=slurm``, ``conf/cluster/slurm.yaml``, which holds every value):
    the ``cases`` experiment's pairs as a job array (eval/experiments/cases/case_array.py)."""

    executor: str = MISSING
    partition: Optional[str] = MISSING
    account: Optional[str] = MISSING
    qos: Optional[str] = MISSING
    timeout_min: int = MISSING
    cpus_per_task: int = MISSING
    mem_gb: Optional[float] = MISSING
    array_parallelism: int = MISSING
    setup: Optional[List[str]] = MISSING
    additional_parameters: Dict[str, Any] = MISSING
    folder: str = MISSING
    poll_s: float = MISSING
    grace_polls: int = MISSING
    unreachable_s: float = MISSING


# ----------------------------------------------------------------------------- conf/method/
#: The keys of a method file the evaluator reads, typed; its parameters are the class's
#: own (``Any``: any type, checked when it is built).
_METHOD_TYPES = {"_target_": str, "order": int, "harness": Dict[str, Any]}


def _method_schema(name: str) -> type:
    """The schema of ``conf/method/<name>.yaml``: its keys and no other, those of
    :data:`_METHOD_TYPES` typed, every parameter ``Any``."""
    cls_name = "MethodSchema_" + re.sub(r"\W", "_", method_key(name))
    spec = [(str(k), _METHOD_TYPES.get(str(k), Any), field(default=MISSING))
            for k in OmegaConf.load(method_file(name)).keys()]
    cls = make_dataclass(cls_name, spec, namespace={"__module__": __name__})
    globals()[cls_name] = cls  # pickled by reference (a sweep's jobs get their config pickled)
    return cls


_METHOD_SCHEMAS = {name: _method_schema(name) for name in builtin_methods()}


def method_schemas() -> dict[str, type]:
    """``{name: schema}`` of every built-in method file (``schema/method/<name>``)."""
    return dict(_METHOD_SCHEMAS)


# ----------------------------------------------------------------------------- the store
def _open(node, opened=()):
    """``node`` (a structured config) as an open mapping of its typed nodes: each key keeps
    its type, and keys may be added; so do the sections named in ``opened``."""
    return OmegaConf.create({k: _open(node[k]) if k in opened else node._get_node(k) for k in node})


def top_schema():
    """``config_schema``: :class:`TopSchema` as an open mapping of typed nodes
    (:func:`_open`, its ``experiment`` too), so that an experiment may add a top-level
    section of its own (typed by its own schema) while every key of ``conf/config.yaml``
    keeps its type."""
    return _open(OmegaConf.structured(TopSchema), opened=("experiment",))


def store_schemas() -> None:
    """Register every schema with Hydra's ConfigStore (again is harmless); the datasets'
    (:func:`dataset_schemas`) and the experiment sections' (:func:`section_schemas`) once
    their modules are imported."""
    from hydra.core.config_store import ConfigStore
    cs = ConfigStore.instance()
    cs.store(name="config_schema", node=top_schema())
    for name, cls in _DATASETS.items():
        cs.store(group="schema/dataset", name=name, node=cls)
    for name, cls in _SECTIONS.items():
        cs.store(group="schema/experiment", name=name, node=cls)
    cs.store(group="schema/cluster", name="slurm", node=ClusterSchema)
    for name, cls in _METHOD_SCHEMAS.items():
        cs.store(group="schema/method", name=name, node=cls)



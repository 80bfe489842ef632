"""The evaluator's datasets by name (``dataset.name``): each dataset module of
:mod:`eval.datasets` registers itself with :func:`register_dataset`, its loader and its
options dataclass (the type of its config section, registered with it as
``schema/dataset/<name>``, :func:`eval.config_schema.register_dataset_schema`); the registry
finds those modules on its own (every module of the package, :func:`datasets`), so a new
dataset is one module calling :func:`register_dataset` plus one ``conf/dataset/NAME.yaml``.
Floor 2 of eval/ (eval/datasets/, tests/test_layering.py)."""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from eval.config_schema import register_dataset_schema
from eval.registry_base import Registry

__all__ = ["Dataset", "register_dataset", "datasets", "find_dataset"]



@dataclass(frozen=True)
class Dataset:
    """One registered dataset.

    Attributes
    ----------
    name : ``dataset.name`` in the config (``conf/dataset/<name>.yaml``).
    load : ``load(root: Path, options) -> list[DeformationCase]``, ``options`` an instance
        of :attr:`options`; raises SShaDeError.
    options : the dataclass of its section (a subclass of
        :class:`eval.datasets.dataset_options.DatasetOptions`): every ``dataset.<key>``
        (:attr:`keys`) with its type and default, its ``__post_init__`` checking the values
        (SShaDeError naming ``dataset.<key>``); made at the door
        (:attr:`eval.run.spec.DatasetSpec.options`).
    prepare : optional ``prepare(root: Path, options) -> None`` run on the resolved root
        before it is checked (e.g. the DeFAUST build).
    root_hint : text added to the "does not exist" error of ``dataset.root``.
    seeds : optional ``seeds(root: Path) -> dict``, extra seeds recorded in ``run.json``.
    provenance : optional ``provenance(root: Path) -> dict``: what the data read is,
        recorded in ``run.json`` as ``dataset_build`` (a DeFAUST build: whether it is the
        canonical one, :func:`eval.datasets.defaust_dataset.build_provenance`).
    outlook : optional ``outlook(root: Path, options) -> dict | None``: what ``prepare`` is
        about to do, found cheaply (no work), for the evaluator's plan (:mod:`eval.run.plan`):
        None when it has nothing long to do, else a dict (e.g.
        :func:`eval.datasets.defaust_dataset.build_outlook`).
    """

    name: str
    load: Callable
    options: type
    prepare: Callable | None = None
    root_hint: str = ""
    seeds: Callable | None = None
    outlook: Callable | None = None
    provenance: Callable | None = None

    @property
    def keys(self) -> tuple[str, ...]:
        """Its ``dataset.<key>`` config keys: the fields of :attr:`options`, in order."""
        return tuple(f.name for f in dataclasses.fields(self.options))


_REGISTRY = Registry(__package__, "dataset", skip=("dataset_registry", "deformation_case"))


def register_dataset(name: str, load: Callable, *, options: type, prepare=None, root_hint: str = "",
                     seeds=None, outlook=None, provenance=None) -> Dataset:
    """Register dataset ``name`` (fields of :class:`Dataset`), and its ``options`` as the
    type of ``conf/dataset/<name>.yaml`` (``schema/dataset/<name>``,
    :func:`eval.config_schema.register_dataset_schema`); called at the bottom of a dataset
    module. Registering a name twice with another loader or options raises ValueError (a
    programming error, not a user's)."""
    d = Dataset(name=str(name), load=load, options=options, prepare=prepare, root_hint=root_hint, seeds=seeds,
                outlook=outlook, provenance=provenance)
    _REGISTRY.add(d.name, d, same=lambda old, new: old.load is new.load and old.options is new.options)
    register_dataset_schema(d.name, options)
    return d


def datasets() -> dict[str, Dataset]:
    """Every registered dataset, name -> :class:`Dataset`, sorted by name."""
    return _REGISTRY.all()


def find_dataset(name) -> Dataset | None:
    """The dataset registered as ``name``, or None."""
    return _REGISTRY.find(name)

"""The evaluator's datasets by name (``dataset.name``): each dataset module of
:mod:`eval.datasets` registers itself with :func:`register_dataset`; the registry finds
those modules on its own (every module of the package, :func:`datasets`), so a new
dataset is one module calling :func:`register_dataset` plus one ``conf/dataset/NAME.yaml``.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from eval.registry_base import Registry

__all__ = ["Dataset", "register_dataset", "datasets", "find_dataset"]



@dataclass(frozen=True)
class Dataset:
    """One registered dataset.

    Attributes
    ----------
    name : ``dataset.name`` in the config (``conf/dataset/<name>.yaml``).
    load : ``load(root: Path, **options) -> list[DeformationCase]``; raises SShaDeError.
    keys : the ``dataset.<key>`` config keys passed to ``load`` (when present), as lists /
        mappings for list-valued keys.
    path_keys : those of ``keys`` that are paths, resolved against the launch directory.
    prepare : optional ``prepare(root: Path, section) -> None`` run on the resolved root
        before it is checked (e.g. the DeFAUST build), ``section`` the ``dataset`` section
        (plain values, :attr:`eval.run.spec.DatasetSpec.section`).
    root_hint : text added to the "does not exist" error of ``dataset.root``.
    seeds : optional ``seeds(root: Path) -> dict``, extra seeds recorded in ``run.json``.
    provenance : optional ``provenance(root: Path) -> dict``: what the data read is,
        recorded in ``run.json`` as ``dataset_build`` (a DeFAUST build: whether it is the
        canonical one, :func:`eval.datasets.defaust_dataset.build_provenance`).
    outlook : optional ``outlook(root: Path, section) -> dict | None``: what ``prepare`` is
        about to do, found cheaply (no work), for the evaluator's plan (:mod:`eval.run.plan`):
        None when it has nothing long to do, else a dict (e.g.
        :func:`eval.datasets.defaust_dataset.build_outlook`).
    check : optional ``check(section) -> None``: the dataset's own values of its section
        (plain values) checked before any work (:func:`eval.config_check.check_config`);
        raises SShaDeError naming the key (``dataset.<key>``).
    """

    name: str
    load: Callable
    keys: tuple[str, ...]
    path_keys: tuple[str, ...] = ()
    prepare: Callable | None = None
    root_hint: str = ""
    seeds: Callable | None = None
    outlook: Callable | None = None
    check: Callable | None = None
    provenance: Callable | None = None


_REGISTRY = Registry(__package__, "dataset", skip=("dataset_registry", "deformation_case"))


def register_dataset(name: str, load: Callable, *, keys, path_keys=(), prepare=None, root_hint: str = "",
                     seeds=None, outlook=None, check=None, provenance=None) -> Dataset:
    """Register dataset ``name`` (fields of :class:`Dataset`); called at the bottom of a
    dataset module. Registering a name twice with another loader raises ValueError (a
    programming error, not a user's)."""
    d = Dataset(name=str(name), load=load, keys=tuple(keys), path_keys=tuple(path_keys), prepare=prepare,
                root_hint=root_hint, seeds=seeds, outlook=outlook, check=check, provenance=provenance)
    return _REGISTRY.add(d.name, d, same=lambda old, new: old.load is new.load)


def datasets() -> dict[str, Dataset]:
    """Every registered dataset, name -> :class:`Dataset`, sorted by name."""
    return _REGISTRY.all()


def find_dataset(name) -> Dataset | None:
    """The dataset registered as ``name``, or None."""
    return _REGISTRY.find(name)

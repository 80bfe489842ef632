"""The evaluator's experiments by kind (``experiment.kind``, default ``cases``): each
experiment module of :mod:`eval.experiments` registers its run function with
:func:`register_experiment`; the registry finds those modules on its own (every module
of the package, :func:`experiments`), so a new experiment is one module calling
:func:`register_experiment` plus one ``conf/experiment/NAME.yaml`` setting
``experiment.kind``."""
from __future__ import annotations

from collections.abc import Callable

from ..registry import Registry

__all__ = ["register_experiment", "experiments", "find_experiment"]

_REGISTRY = Registry(__package__, "experiment kind", skip=("registry", "common", "cases_plan"))


def register_experiment(kind: str, run: Callable) -> Callable:
    """Register ``run(cfg) -> dict`` as experiment ``kind``; called at the bottom of an
    experiment module. Returns ``run``. Registering a kind twice with another function
    raises ValueError (a programming error, not a user's)."""
    return _REGISTRY.add(kind, run, same=lambda old, new: old is new)


def experiments() -> dict[str, Callable]:
    """Every registered experiment, kind -> run function, sorted by kind."""
    return _REGISTRY.all()


def find_experiment(kind) -> Callable | None:
    """The run function registered as ``kind``, or None."""
    return _REGISTRY.find(kind)

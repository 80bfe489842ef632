"""The evaluator's experiments by kind (``experiment.kind``, default ``cases``): each
experiment module of :mod:`eval.experiments` registers its run function with
:func:`register_experiment`; the registry finds those modules on its own (every module
of the package, :func:`experiments`), so a new experiment is one module calling
:func:`register_experiment` plus one ``conf/experiment/NAME.yaml`` setting
``experiment.kind``."""
from __future__ import annotations

from collections.abc import Callable

from eval.registry_base import Registry

__all__ = ["register_experiment", "experiments", "find_experiment", "experiment_check"]

_REGISTRY = Registry(__package__, "experiment kind", skip=("experiment_registry", "common"))
_CHECKS: dict[str, Callable] = {}


def register_experiment(kind: str, run: Callable, *, check: Callable | None = None) -> Callable:
    """Register ``run(cfg) -> dict`` as experiment ``kind``, with ``check(cfg) -> None``,
    its own config values checked before any work (raises SShaDeError naming the key;
    :func:`eval.config_check.check_config`); called at the bottom of an experiment module.
    Returns ``run``. Registering a kind twice with another function raises ValueError (a
    programming error, not a user's)."""
    out = _REGISTRY.add(kind, run, same=lambda old, new: old is new)
    if check is not None:
        _CHECKS[kind] = check
    return out


def experiments() -> dict[str, Callable]:
    """Every registered experiment, kind -> run function, sorted by kind."""
    return _REGISTRY.all()


def find_experiment(kind) -> Callable | None:
    """The run function registered as ``kind``, or None."""
    return _REGISTRY.find(kind)


def experiment_check(kind) -> Callable | None:
    """The config check registered with experiment ``kind``, or None (none, or no such kind)."""
    return _CHECKS.get(kind) if find_experiment(kind) is not None else None

"""The evaluator's experiments by kind (``experiment.kind``, default ``cases``): each
experiment module of :mod:`eval.experiments` registers its run function with
:func:`register_experiment`; the registry finds those modules on its own (every module
of the package, :func:`experiments`), so a new experiment is one module calling
:func:`register_experiment` plus one ``conf/experiment/NAME.yaml`` setting
``experiment.kind``."""
from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable

__all__ = ["register_experiment", "experiments", "find_experiment"]

#: Modules of the package that are not experiments.
_NOT_EXPERIMENTS = ("registry", "common")

_REGISTRY: dict[str, Callable] = {}
_discovered = False


def register_experiment(kind: str, run: Callable) -> Callable:
    """Register ``run(cfg) -> dict`` as experiment ``kind``; called at the bottom of an
    experiment module. Returns ``run``. Registering a kind twice with another function
    raises ValueError (a programming error, not a user's)."""
    old = _REGISTRY.get(kind)
    if old is not None and old is not run:
        raise ValueError(f"experiment kind {kind!r} registered twice ({old.__module__} and {run.__module__})")
    _REGISTRY[str(kind)] = run
    return run


def _discover() -> None:
    """Import every module of :mod:`eval.experiments` once (each registers itself)."""
    global _discovered
    if _discovered:
        return
    pkg = importlib.import_module(__package__)
    for m in pkgutil.iter_modules(pkg.__path__):
        if not m.name.startswith("_") and m.name not in _NOT_EXPERIMENTS and not m.ispkg:
            importlib.import_module(f"{__package__}.{m.name}")
    _discovered = True


def experiments() -> dict[str, Callable]:
    """Every registered experiment, kind -> run function, sorted by kind."""
    _discover()
    return dict(sorted(_REGISTRY.items()))


def find_experiment(kind) -> Callable | None:
    """The run function registered as ``kind``, or None."""
    return experiments().get(str(kind))

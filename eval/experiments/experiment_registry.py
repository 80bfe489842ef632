"""The evaluator's experiments by kind (``experiment.kind``, default ``cases``): each
experiment module of :mod:`eval.experiments` registers its run function with
:func:`register_experiment`; the registry finds those modules on its own (every module
of the package, :func:`experiments`), so a new experiment is one module calling
:func:`register_experiment` plus one ``conf/experiment/NAME.yaml`` setting
``experiment.kind``."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from eval.registry_base import Registry

__all__ = ["OptionsReader", "register_experiment", "experiments", "find_experiment", "experiment_options"]

_REGISTRY = Registry(__package__, "experiment kind", skip=("experiment_registry", "common"))


@dataclass(frozen=True)
class OptionsReader:
    """How an experiment kind reads its own options: ``read(values)`` makes its typed
    options (raising SShaDeError naming the key) of ``values``, the plain values of the
    config's top-level section ``section`` (None when the config has none)."""

    section: str
    read: Callable


_OPTIONS: dict[str, OptionsReader] = {}


def register_experiment(kind: str, run: Callable, *, section: str | None = None,
                        options: Callable | None = None) -> Callable:
    """Register ``run(spec) -> dict`` as experiment ``kind`` (``spec``: the checked run,
    :class:`eval.run.spec.EvalSpec`, its ``experiment.options`` what ``options`` made),
    with ``options(values)``, its own options read from the config's section ``section``
    before any work (:class:`OptionsReader`; :func:`eval.config_check.check_config`);
    called at the bottom of an experiment module. Returns ``run``. Registering a kind
    twice with another function raises ValueError (a programming error, not a user's)."""
    out = _REGISTRY.add(kind, run, same=lambda old, new: old is new)
    if options is not None:
        _OPTIONS[kind] = OptionsReader(section=str(section or kind), read=options)
    return out


def experiments() -> dict[str, Callable]:
    """Every registered experiment, kind -> run function, sorted by kind."""
    return _REGISTRY.all()


def find_experiment(kind) -> Callable | None:
    """The run function registered as ``kind``, or None."""
    return _REGISTRY.find(kind)


def experiment_options(kind) -> OptionsReader | None:
    """How experiment ``kind`` reads its options, or None (none, or no such kind)."""
    return _OPTIONS.get(kind) if find_experiment(kind) is not None else None

"""One registry of named plug-ins of the evaluator, found without a list: the datasets
(:mod:`eval.datasets.dataset_registry`) and the experiments (:mod:`eval.experiments.experiment_registry`)
are each a :class:`Registry` over their package, so a new dataset or experiment is one
module that registers itself plus one config file."""
from __future__ import annotations

import importlib
import pkgutil

__all__ = ["Registry"]


class Registry:
    """Named items registered by the modules of one package.

    Parameters
    ----------
    package : str, the package whose modules register items (e.g. ``eval.datasets``).
    what : str, what an item is, for messages (``dataset``, ``experiment kind``).
    skip : names of the package's modules that register nothing (the registry itself, ...).
    """

    def __init__(self, package: str, what: str, skip=()):
        self.package, self.what, self.skip = package, what, tuple(skip)
        self._items: dict = {}
        self._discovered = False

    def add(self, name: str, item, *, same) -> object:
        """Register ``item`` as ``name`` (called at the bottom of a module); returns it.
        ``same(old, item)`` tells a repeated registration of the same thing (a module
        imported twice) from two different ones, which raises ValueError (a programming
        error, not a user's)."""
        old = self._items.get(str(name))
        if old is not None and not same(old, item):
            raise ValueError(f"{self.what} {name!r} registered twice")
        self._items[str(name)] = item
        return item

    def _discover(self) -> None:
        """Import every module of the package and of its subpackages once (each registers its items)."""
        if self._discovered:
            return
        pkg = importlib.import_module(self.package)
        for m in pkgutil.walk_packages(pkg.__path__, f"{self.package}."):
            last = m.name.rpartition(".")[2]
            if not last.startswith("_") and last not in self.skip and not m.ispkg:
                importlib.import_module(m.name)
        self._discovered = True

    def all(self) -> dict:
        """Every registered item, name -> item, sorted by name."""
        self._discover()
        return dict(sorted(self._items.items()))

    def find(self, name):
        """The item registered as ``name``, or None."""
        return self.all().get(str(name))

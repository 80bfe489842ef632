"""The ``dataset`` section at work: a dataset's cases loaded by name with collision-free
names (:func:`load_cases`), its root resolved after its ``prepare`` step
(:func:`dataset_root`) and what that step is about to do (:func:`dataset_outlook`).
Floor 2 of eval/ (eval/datasets/, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

import dataclasses
import hashlib
import itertools
from pathlib import Path

from eval.datasets.dataset_registry import Dataset, datasets, find_dataset
from eval.datasets.deformation_case import DeformationCase
from eval.run.names import safe_name
from eval.run.paths import abs_path
from eval.run.spec import DatasetSpec
from sshade.errors import SShaDeError

__all__ = ["load_cases", "dataset_names", "dataset_named", "unique_case_names", "dataset_root", "dataset_outlook"]


def dataset_names() -> list[str]:
    """Names of the registered datasets, sorted."""
    return list(datasets())


def dataset_named(name: str) -> Dataset:
    """The registered dataset ``name``; SShaDeError naming the known ones when there is none."""
    d = find_dataset(name)
    if d is None:
        raise SShaDeError(f"unknown dataset {name!r}; available: {dataset_names()}")
    return d


def load_cases(name: str, root, options=None, **changes) -> list[DeformationCase]:
    """Cases of dataset ``name`` (one of :func:`dataset_names`) found under ``root``.

    ``options`` is the dataset's options object (its registered dataclass, e.g.
    :class:`eval.datasets.faust.FaustOptions`; None: its defaults), with ``changes``
    (``limit=2``) made by :func:`dataclasses.replace` (checked again); the loader gets it
    (e.g. :func:`eval.datasets.faust.faust_cases`). The names are made collision-free
    (:func:`unique_case_names`), so every case has files of its own (``runs/<case>/``,
    ``report/<case>.js``, ``figures/<case>.png``).

    Raises
    ------
    SShaDeError on an unknown dataset name, a bad option or whatever the loader raises.
    """
    d = dataset_named(name)
    opts = d.options() if options is None else options
    return unique_case_names(d.load(root, dataclasses.replace(opts, **changes) if changes else opts))


def _source_of(case, index: int) -> str:
    """The text a case's name hash is made of: its source file when it has one, else
    its name and its position in the list."""
    for attr in ("path", "target_path", "source", "rest_path"):
        v = getattr(case, attr, None)
        if v not in (None, ""):
            return str(v)
    return f"{case.name}#{index}"


def unique_case_names(cases: list) -> list:
    """``cases`` (in place, and returned) with collision-free names: every case whose
    file name (:func:`eval.run.names.safe_name`, compared without case, as on a
    case-insensitive file system) is shared with another case gets ``-`` and 8 hex
    digits of the SHA-256 of its source path appended (and its position in ``cases``
    when that name is taken too, e.g. two cases of one source; the prefix cut so that
    the whole name stays within ``safe_name``'s 120 characters); a ``subject`` equal to
    the old name follows it. Names already unique are kept. E.g. ``bunny.off`` and
    ``bunny.obj`` (both ``bunny``) become ``bunny-1a2b3c4d`` and ``bunny-5e6f7a8b``;
    ``a b`` and ``a_b`` (both ``a_b`` on disk) get one hash each.
    """
    def key(name) -> str:
        return safe_name(name).casefold()

    count: dict[str, int] = {}
    for c in cases:
        count[key(c.name)] = count.get(key(c.name), 0) + 1
    taken = {key(c.name) for c in cases}
    for i, c in enumerate(cases):
        if count[key(c.name)] < 2:
            continue
        old = str(c.name)
        digest = hashlib.sha256(_source_of(c, i).encode()).hexdigest()[:8]
        for j in itertools.count():  # the digest, then with the case's position, until the name is free
            h = digest if j == 0 else f"{digest}-{i}" if j == 1 else f"{digest}-{i}-{j}"
            new = f"{old[:120 - len(h) - 1]}-{h}"
            if key(new) not in taken:
                break
        taken.add(key(new))
        c.name = new
        if isinstance(getattr(c, "subject", None), str) and c.subject == old:
            c.subject = new
    return cases


def dataset_root(ds: DatasetSpec | None) -> Path:
    """``ds.root`` resolved against the launch directory, after the dataset's ``prepare``
    step (the DeFAUST build into its default folder).

    Raises
    ------
    SShaDeError when no dataset is configured, ``dataset.root`` is unset or is not a folder.
    """
    if ds is None:
        raise SShaDeError("no dataset configured; pass dataset=faust dataset.root=DIR")
    if ds.root in (None, "", "???"):
        raise SShaDeError("dataset.root is not set: pass dataset.root=DIR, a folder with FAUST "
                          "registrations tr_reg_XYZ.ply (e.g. dataset.root=../shared/data/faust_reg)")
    root = abs_path(ds.root)
    d = find_dataset(ds.name)
    if d is not None and d.prepare is not None:
        d.prepare(root, ds.options)
    if not root.is_dir():
        hint = d.root_hint if d is not None else ""
        raise SShaDeError(f"dataset.root does not exist or is not a folder: {root}{hint}")
    return root


def dataset_outlook(ds: DatasetSpec | None) -> dict | None:
    """What the dataset's ``prepare`` step (:func:`dataset_root`) is about to do, found
    without doing it (its registered ``outlook``, e.g. the DeFAUST build still to run:
    :func:`eval.datasets.defaust_dataset.build_outlook`); None when there is nothing long to do,
    no ``outlook``, or no usable ``dataset.root`` (:func:`dataset_root` then says why).

    Raises
    ------
    SShaDeError from the ``outlook`` (e.g. a bad ``dataset.build`` setting).
    """
    if ds is None or ds.root in (None, "", "???"):
        return None
    d = find_dataset(ds.name)
    if d is None or d.outlook is None:
        return None
    return d.outlook(abs_path(ds.root), ds.options)

"""Datasets of deformation cases for the evaluator.

- :mod:`eval.datasets.faust`: FAUST registrations -> DeFAUST-style cases
  (:func:`~eval.datasets.faust.faust_cases`).
- ``defaust``: a DeFAUST build (``python -m defaust``), read by
  :func:`defaust.dataset.load_defaust` at high or low resolution.
- :mod:`eval.datasets.shapes`: single shapes (Stanford models) with a fixed user-defined
  edit (:func:`~eval.datasets.shapes.shape_cases`; paper §4.1, Fig. arap-examples).

:func:`load_cases` dispatches on ``dataset.name`` from the Hydra config.
"""
from __future__ import annotations

from sshade.errors import SShaDeError

from .faust import FAUST_LANDMARKS, Case, discover_faust, faust_cases

__all__ = ["Case", "FAUST_LANDMARKS", "discover_faust", "faust_cases", "load_cases", "DATASETS"]

DATASETS = ("faust", "defaust", "shapes")


def load_cases(name: str, root, **kw) -> list[Case]:
    """Cases of dataset ``name`` (one of :data:`DATASETS`) found under ``root``.

    Keyword arguments go to the dataset's builder (e.g. :func:`faust_cases`).

    Raises
    ------
    SShaDeError on an unknown dataset name or whatever the builder raises.
    """
    if name == "faust":
        return faust_cases(root, **kw)
    if name == "defaust":
        from defaust.dataset import load_defaust
        return load_defaust(root, **kw)
    if name == "shapes":
        from .shapes import shape_cases
        return shape_cases(root, **kw)
    raise SShaDeError(f"unknown dataset {name!r}; available: {list(DATASETS)}")

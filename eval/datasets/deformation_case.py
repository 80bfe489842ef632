"""The case every evaluator dataset yields (:mod:`eval.datasets`): one rest mesh, its
handles and their targets, and the true deformed shape when the dataset has one; and
what a method may learn of it (:class:`CaseLabel`: never the true shape)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["DeformationCase", "CaseLabel", "case_label"]


@dataclass
class DeformationCase:
    """What every evaluator dataset yields: one rest mesh, its handles and targets.

    Attributes
    ----------
    name : str, the case's name in tables and figure files.
    subject, pose : subject id (int; a shape name for single shapes) and target pose.
    V : (n, 3) float64 rest mesh vertices. F : (m, 3) int64 faces.
    handles : (h,) int64 unique handle vertex indices into ``V``.
    targets : (h, 3) float64 handle target positions (units of ``V``).
    static : (h,) bool, the handle's group stays at its rest position.
    V_gt : (n, 3) float64 true target pose on the same mesh, or None (no ground truth).
    group : (h,) int64 handle group of each handle, or None.
    """

    name: str
    subject: int
    pose: int
    V: np.ndarray
    F: np.ndarray
    handles: np.ndarray
    targets: np.ndarray
    static: np.ndarray
    V_gt: np.ndarray | None
    group: np.ndarray = field(repr=False, default=None)


@dataclass(frozen=True)
class CaseLabel:
    """What the evaluator tells a case-aware method of the case it runs: a method that
    has a ``case`` attribute gets it set to this before each ``deform`` call
    (:func:`eval.experiments.cases.pair.run_pair`). The true shape is not in it.

    Attributes
    ----------
    name : str, the case's name (as in tables and run folders).
    subject, pose : its subject and target pose.
    static : (h,) bool, the handles whose group stays at its rest position.
    group : (h,) int64 handle groups, or None.
    """

    name: str
    subject: object
    pose: object
    static: np.ndarray = field(repr=False)
    group: np.ndarray | None = field(repr=False, default=None)


def case_label(case) -> CaseLabel:
    """What a case-aware method is told of ``case`` (any evaluator case: ``name``,
    ``subject``, ``pose``, ``static`` (h,) and an optional ``group`` (h,)), copied."""
    group = getattr(case, "group", None)
    return CaseLabel(name=str(case.name), subject=case.subject, pose=case.pose, static=np.array(case.static, bool),
                     group=None if group is None else np.array(group, np.int64))

"""The case every evaluator dataset yields (:mod:`eval.datasets`): one rest mesh, its
handles and their targets, and the true deformed shape when the dataset has one."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["DeformationCase"]


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

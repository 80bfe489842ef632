"""The result of an ARAP solve (:func:`sshade.arap.local_global.arap_deform`,
:func:`sshade.arap.solver.solve_arap`, the ARAP-SR baseline)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ArapResult"]


@dataclass
class ArapResult:
    """Result of an ARAP solve (:func:`sshade.arap.local_global.arap_deform`,
    :func:`sshade.arap.solver.solve_arap`).

    Attributes
    ----------
    V : (n, 3) float64 deformed vertex positions.
    iterations : int, local/global iterations run.
    converged : bool, the protocol's stopping criterion was met before ``max_iter``.
    last_move : float, largest vertex move of the last iteration (mesh units).
    precompute_s, solve_s : float, seconds in precomputation and in the iterations.
    info : dict, per-solver details (:func:`sshade.arap.solver.solve_arap` lists its keys).
    """

    V: np.ndarray
    iterations: int
    converged: bool
    last_move: float
    precompute_s: float
    solve_s: float
    info: dict = field(default_factory=dict)

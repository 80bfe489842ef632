"""Full-resolution ARAP baselines (paper §4.1): ARAP (spokes) and Elastic (spokes and rims)."""
from __future__ import annotations

import numpy as np

from sshade.arap import arap_deform
from sshade.validate import validate_handles, validate_mesh

__all__ = ["FullResArap", "ARAP", "Elastic"]


class FullResArap:
    """libigl ARAP on the full-resolution mesh, run to convergence.

    Parameters
    ----------
    energy : ``"spokes"`` or ``"spokes_and_rims"``.
    tol : float, relative move tolerance (fraction of the bounding-box diagonal).
    max_iter : int, iteration cap (paper: 1000).
    name : str, the table row label.

    Examples
    --------
    >>> m = Elastic()  # doctest: +SKIP
    >>> Vd = m.deform(V, F, handles, targets)  # doctest: +SKIP
    >>> m.info["iterations"]  # doctest: +SKIP
    """

    def __init__(self, energy: str, *, tol: float = 1e-4, max_iter: int = 1000, name: str | None = None):
        self.energy = energy
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        self.name = name or energy
        self.info: dict = {}

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` so ``V[handles]`` reach ``targets``; returns (n, 3) float64.

        Raises ``SShaDeError`` on invalid mesh or handles.
        """
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        res = arap_deform(V, F, handles, targets, energy=self.energy, tol=self.tol, max_iter=self.max_iter)
        self.info = {"iterations": res.iterations, "converged": res.converged,
                     "precompute_s": res.precompute_s, "solve_s": res.solve_s,
                     "s_per_iter": res.solve_s / max(res.iterations, 1)}
        return res.V


class ARAP(FullResArap):
    """ARAP, spokes energy (Sorkine & Alexa 2007), full resolution."""

    def __init__(self, *, tol: float = 1e-4, max_iter: int = 1000):
        super().__init__("spokes", tol=tol, max_iter=max_iter, name="ARAP")


class Elastic(FullResArap):
    """Elastic = spokes-and-rims ARAP (Chao et al. 2010), full resolution."""

    def __init__(self, *, tol: float = 1e-4, max_iter: int = 1000):
        super().__init__("spokes_and_rims", tol=tol, max_iter=max_iter, name="Elastic")

"""Full-resolution ARAP baselines (paper §4.1): ARAP (spokes) and Elastic (spokes and rims)."""
from __future__ import annotations

import numpy as np

from sshade.arap import arap_deform, make_criterion
from sshade.validate import validate_handles, validate_mesh

__all__ = ["FullResArap", "ARAP", "Elastic"]


class FullResArap:
    """ARAP on the full-resolution mesh, under one of the protocols of
    :func:`sshade.arap.arap_deform`.

    Parameters
    ----------
    energy : ``"spokes"`` or ``"spokes_and_rims"``.
    tol : float, ``"paper"`` protocol: move tolerance (fraction of the bounding-box
        diagonal).
    max_iter : int or None, iteration cap (None: the protocol's default; paper: 1000).
    name : str, the table row label.
    protocol : ``"converged"`` (default: L-BFGS-accelerated local/global to the
        energy-and-gradient criterion) or ``"paper"`` (libigl, paper §4.1 move rule).
    etol, gtol : floats or None, the ``"converged"`` criterion
        (:class:`sshade.arap.criterion.Criterion`; None: its defaults).

    Examples
    --------
    >>> m = Elastic()  # doctest: +SKIP
    >>> Vd = m.deform(V, F, handles, targets)  # doctest: +SKIP
    >>> m.info["iterations"]  # doctest: +SKIP
    """

    def __init__(self, energy: str, *, tol: float = 1e-4, max_iter: int | None = None, name: str | None = None,
                 protocol: str = "converged", etol: float | None = None, gtol: float | None = None):
        from sshade.arap import PROTOCOLS
        from sshade.errors import SShaDeError
        if protocol not in PROTOCOLS:
            raise SShaDeError(f"{name or energy}: unknown protocol {protocol!r}; use one of {PROTOCOLS}")
        self.energy = energy
        self.tol = float(tol)
        self.max_iter = None if max_iter is None else int(max_iter)
        self.name = name or energy
        self.protocol = protocol
        self.criterion = make_criterion(etol, gtol)
        self.info: dict = {}

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` so ``V[handles]`` reach ``targets``; returns (n, 3) float64.

        Raises ``SShaDeError`` on invalid mesh or handles.
        """
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        res = arap_deform(V, F, handles, targets, energy=self.energy, tol=self.tol, max_iter=self.max_iter,
                          protocol=self.protocol, criterion=self.criterion)
        self.info = {"iterations": res.iterations, "converged": res.converged, "protocol": self.protocol,
                     "status": res.info.get("status"), "precompute_s": res.precompute_s, "solve_s": res.solve_s,
                     "s_per_iter": res.solve_s / max(res.iterations, 1)}
        for k in ("energy", "gnorm", "rel_decrease", "n_fallback", "linear_solver"):
            if k in res.info:
                self.info[k] = res.info[k]
        return res.V

    def warmup(self, n_vertices: int | None = None) -> float:
        """Compile (or load from numba's cache) the kernels :meth:`deform` runs for this
        energy and protocol (parallel variants too when an ``n_vertices`` mesh uses them),
        outside any timed call (:func:`sshade.warmup.warm_fullres`). Returns the seconds
        spent (0.0 when warm)."""
        from sshade.warmup import warm_fullres
        return warm_fullres(self.energy, self.protocol, n_vertices)


class ARAP(FullResArap):
    """ARAP, spokes energy (Sorkine & Alexa 2007), full resolution."""

    def __init__(self, *, tol: float = 1e-4, max_iter: int | None = None, protocol: str = "converged",
                 etol: float | None = None, gtol: float | None = None):
        super().__init__("spokes", tol=tol, max_iter=max_iter, name="ARAP", protocol=protocol, etol=etol, gtol=gtol)


class Elastic(FullResArap):
    """Elastic = spokes-and-rims ARAP (Chao et al. 2010), full resolution."""

    def __init__(self, *, tol: float = 1e-4, max_iter: int | None = None, protocol: str = "converged",
                 etol: float | None = None, gtol: float | None = None):
        super().__init__("spokes_and_rims", tol=tol, max_iter=max_iter, name="Elastic", protocol=protocol,
                         etol=etol, gtol=gtol)

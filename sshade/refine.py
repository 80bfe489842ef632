"""SShaDe + refine: SShaDe's result as the start of a converged full-resolution
spokes-and-rims solve.

SShaDe (paper §3) gives a deformation close to the full-resolution ARAP minimiser in a
fraction of its time; the L-BFGS-accelerated local/global of
:func:`sshade.arap.solver.solve_arap` started there needs fewer iterations than from
the rigid fit of the handles. This method measures how many (``refine_iterations``
against a full-resolution Elastic row's ``iterations``), and gives the converged
full-resolution answer when SShaDe's approximation is not enough.
"""
from __future__ import annotations

import time
from collections.abc import Mapping

import numpy as np

from .arap import ArapOptions, make_criterion, solve_arap
from .mesh.validate import validate_handles, validate_mesh
from .params import SShaDeParams, check_params, effective_params
from .pipeline import deform_with, warm_sshade
from .warmup import warm_fullres

__all__ = ["SShaDeRefine"]


class SShaDeRefine:
    """SShaDe, then the converged full-resolution spokes-and-rims ARAP from its result.

    Parameters
    ----------
    refine_etol, refine_gtol : float or None, the refinement's criterion
        (:class:`sshade.arap.criterion.Criterion`; None: its defaults).
    refine_max_iter : int, cap on the refinement's iterations.
    params, **sshade : SShaDe's, as :func:`sshade.deform` (:class:`sshade.params.SShaDeParams`:
        n_low, n_samplings, seed, workers, protocol, ...), checked at construction
        (:func:`sshade.params.check_params`).

    After :meth:`deform`, ``info`` holds SShaDe's info plus ``sshade_s`` (its wall time),
    ``refine_s``, ``refine_iterations``, ``iterations`` (= refine_iterations),
    ``converged`` and ``status`` of the refinement, ``protocol`` ``"converged"``.

    Raises
    ------
    SShaDeError on a bad parameter (at construction) or bad input (in :meth:`deform`).

    Examples
    --------
    Example::

        m = SShaDeRefine(n_low=6000, n_samplings=5)
        Vd = m.deform(V, F, handles, targets); m.info["refine_iterations"]
    """

    name = "SShaDe+refine"
    energy = "spokes_and_rims"

    def __init__(self, params: SShaDeParams | Mapping | None = None, *, refine_etol: float | None = None,
                 refine_gtol: float | None = None, refine_max_iter: int = 10000, **sshade):
        self.params = check_params(params, **sshade)
        self.criterion = make_criterion(refine_etol, refine_gtol)
        self.refine_max_iter = int(refine_max_iter)
        self.info: dict = {}

    @classmethod
    def from_params(cls, params: SShaDeParams, **refine) -> SShaDeRefine:
        """The method with SShaDe's checked ``params`` (:func:`sshade.params.check_params`)
        and the refinement's keyword parameters ``refine`` (as the constructor's)."""
        return cls(params, **refine)

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` (n, 3) / (m, 3) so ``V[handles]`` reach ``targets`` (h, 3);
        returns (n, 3) float64."""
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        t0 = time.perf_counter()
        Vs, info = deform_with(V, F, handles, targets, self.params, return_info=True)
        t1 = time.perf_counter()
        res = solve_arap(V, F, handles, targets, ArapOptions(energy=self.energy, criterion=self.criterion,
                                                             max_iter=self.refine_max_iter), U0=Vs)
        t2 = time.perf_counter()
        info = {k: v for k, v in info.items() if k not in ("samplings",)}
        info.update(sshade_s=t1 - t0, refine_s=t2 - t1, refine_iterations=res.iterations,
                    sshade_iterations=info.get("iterations"), iterations=res.iterations,
                    converged=res.converged, status=res.info.get("status"), protocol="converged",
                    energy=res.info.get("energy"), gnorm=res.info.get("gnorm"))
        self.info = info
        return res.V

    def effective_params(self) -> dict:
        """The parameters :meth:`deform` runs with: SShaDe's, every default resolved
        (:func:`sshade.pipeline.effective_params`), and the refinement's (``refine_energy``,
        ``refine_etol``, ``refine_gtol``, ``refine_max_iter``)."""
        return {**effective_params(self.params), "refine_energy": self.energy, "refine_etol": self.criterion.etol,
                "refine_gtol": self.criterion.gtol, "refine_max_iter": self.refine_max_iter}

    def warmup(self, n_vertices: int | None = None) -> float:
        """Compile (or load from numba's cache) the kernels of SShaDe and of the converged
        full-resolution spokes-and-rims solve (parallel variants too when an ``n_vertices``
        mesh uses them), outside any timed call (:mod:`sshade.warmup`). Returns the
        seconds spent (0.0 when warm)."""
        return warm_sshade(self.params) + warm_fullres(self.energy, "converged", n_vertices)

"""A coarse-to-fine start for converged ARAP-SR (issue 21): solve the same energy on a
low-resolution remesh (SShaDe's, :func:`sshade.remesh.remesh`, the handles kept as
vertices), give every full-resolution vertex the rotation of its low-res Voronoi region,
and start the full-resolution solve (:func:`baselines.arap_sr_solver.solve_arap_sr`)
from those rotations and their global step.

Why: the smoothness term couples the rotations of neighbouring vertices; a Gauss-Seidel
sweep spreads a change by about one ring, so the smooth (low-frequency) part of the
rotation field is what takes the iterations at full resolution. Both terms of the energy
approximate resolution-independent integrals (the ARAP term an area integral, the
uniform edge sum of ``||R_s - R_d||^2`` a Dirichlet energy of the rotation field on a
regular triangulation), so the low-res minimiser with the same ``alpha`` carries that
smooth part. The result is still certified by the full-resolution criterion: the start
changes the time to converge, not what "converged" means.
"""
from __future__ import annotations

import time

import numpy as np

from sshade.arap import Criterion
from sshade.remesh import remesh

from .arap_sr_solver import solve_arap_sr

__all__ = ["coarse_start", "COARSE_MIN_RATIO"]

#: a coarse start is used only when the mesh has at least this many times ``n_low`` vertices
COARSE_MIN_RATIO = 4


def coarse_start(V, F, handles, targets, *, alpha: float, n_low: int = 6000, seed: int = 0,
                 criterion: Criterion | None = None) -> tuple[np.ndarray, dict]:
    """Start rotations for :func:`solve_arap_sr` from a low-resolution solve.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64, a validated single-component manifold mesh.
    handles : (h,) int64 unique; targets : (h, 3) float64.
    alpha : float >= 0, the energy's smoothness weight (the same at both resolutions).
    n_low : int >= 4, farthest-point samples of the remesh (the handles are added).
    seed : int, the remesh's first sample. criterion : the low-res solve's (default
        :data:`sshade.arap.DEFAULT_CRITERION`).

    Returns
    -------
    R0 : (n, 3, 3) float64 rotations (vertex ``i`` gets its region's ``R``).
    info : dict ``coarse_n``, ``coarse_iterations``, ``coarse_status``, ``remesh_s``,
        ``coarse_s`` (seconds).

    Raises
    ------
    SShaDeError from the remesh or the low-res solve (bad mesh, handles, options).
    """
    t0 = time.perf_counter()
    rm = remesh(V, F, int(n_low), seed=seed, required=handles)
    t1 = time.perf_counter()
    res = solve_arap_sr(V[rm.seeds], rm.F, rm.label[handles], targets, alpha=alpha, criterion=criterion)
    R0 = np.ascontiguousarray(res.info["R"][rm.label])
    info = {"coarse_n": int(len(rm.seeds)), "coarse_iterations": int(res.iterations),
            "coarse_status": str(res.info["status"]), "remesh_s": t1 - t0, "coarse_s": time.perf_counter() - t1}
    return R0, info

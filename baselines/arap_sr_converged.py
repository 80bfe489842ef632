"""The converged protocol of ARAP-SR (:mod:`baselines.arap_sr`): Gauss-Seidel local steps and
Anderson acceleration to the energy-and-gradient criterion
(:func:`sshade.arap.sr_solver.solve_arap_sr`), from the rigid fit of the handles or a
coarse start (:mod:`baselines.coarse_start`), and its warm-up. Named by
:data:`baselines.arap_sr.PROTOCOL_MODULES`; docs/protocols.md.
"""
from __future__ import annotations

import numpy as np

from sshade.arap import SR_ENERGY, ArapOptions, solve_arap_sr
from sshade.warmup import WARMED, uses_parallel_kernels, warm_once, warm_parallel_kernels

from .coarse_start import start_rotations

__all__ = ["solve", "warmup"]


def solve(method, V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray):
    """Run ``method`` (a :class:`baselines.arap_sr.ARAPSR` of this protocol) on the checked
    mesh in its unit frame: ``V`` (n, 3) float64, ``F`` (m, 3) int64, ``handles`` (h,) int64,
    ``targets`` (h, 3) float64, from the start of ``method.start``
    (:func:`baselines.coarse_start.start_rotations`).

    Returns
    -------
    :class:`sshade.arap.ArapResult`; a coarse start's seconds count in its ``precompute_s``
    and its numbers (``coarse_n``, ``coarse_iterations``, ``coarse_s``) go to its ``info``.
    """
    R0, cinfo = start_rotations(method.start, V, F, handles, targets, energy=SR_ENERGY, alpha=method.alpha,
                                alpha_scaling=method.alpha_scaling,
                                coarse_n_low=method.coarse_n_low, criterion=method.criterion)
    options = ArapOptions(alpha=method.alpha, alpha_scaling=method.alpha_scaling, criterion=method.criterion,
                          max_iter=method.max_iter)
    res = solve_arap_sr(V, F, handles, targets, options, R0=R0)
    if cinfo:
        res.precompute_s += cinfo["remesh_s"] + cinfo["coarse_s"]
        res.info.update(cinfo)
    return res


def warmup(method, n_vertices: int | None = None) -> float:
    """Warm ``method``'s solve on :func:`sshade.warmup_base.tiny_problem` (libigl, the linear
    solver, the polar and energy kernels, mesh validation, and the remesh when its start is
    not ``"rigid"``), once per process, and the parallel kernels when an ``n_vertices`` mesh
    runs them (:func:`sshade.arap.threads.uses_parallel_kernels`). Returns the seconds spent."""
    coarse = method.start != "rigid"
    s = warm_once(WARMED, ("arap_sr", "converged", coarse),
                  lambda V, F, h, T: type(method)(alpha=method.alpha, alpha_scaling=method.alpha_scaling, max_iter=5,
                                                  start="coarse" if coarse else "rigid",
                                                  coarse_n_low=40).deform(V, F, h, T))
    if uses_parallel_kernels(n_vertices):
        s += warm_once(WARMED, ("arap_sr", "parallel"), lambda *_: warm_parallel_kernels(smooth_rotations=True))
    return s

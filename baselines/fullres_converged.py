"""The converged protocol of the full-resolution ARAP baselines (:mod:`baselines.fullres_arap`):
the L-BFGS-accelerated local/global solve to the energy-and-gradient criterion
(:func:`sshade.arap.arap_deform`, :func:`sshade.arap.solver.solve_arap`), from the rigid fit
of the handles or a coarse start (:mod:`baselines.coarse_start`), and its warm-up.
Named by :data:`baselines.fullres_arap.PROTOCOL_MODULES`; docs/protocols.md.
"""
from __future__ import annotations

import numpy as np

from sshade.arap import arap_deform
from sshade.warmup import WARMED, warm_fullres, warm_once

from .coarse_start import coarse_start, start_rotations, uses_coarse

__all__ = ["solve", "warmup"]


def solve(method, V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray) -> tuple:
    """Run ``method`` (a :class:`baselines.fullres_arap.FullResArap` of this protocol) on
    the checked mesh in its unit frame: ``V`` (n, 3) float64, ``F`` (m, 3) int64,
    ``handles`` (h,) int64, ``targets`` (h, 3) float64.

    Returns
    -------
    ``(ArapResult, info)``: the solve (the coarse start's seconds counted in its
    ``precompute_s``) and the start's info (``coarse_n``, ``coarse_iterations``,
    ``coarse_s``; empty for the rigid start).
    """
    R0, cinfo = start_rotations(method.start, V, F, handles, targets, energy=method.energy,
                                coarse_n_low=method.coarse_n_low, criterion=method.criterion)
    res = arap_deform(V, F, handles, targets, method.arap_options(), R0=R0)
    if cinfo:  # the coarse start's seconds count as set-up
        res.precompute_s += cinfo["remesh_s"] + cinfo["coarse_s"]
    return res, cinfo


def warmup(method, n_vertices: int | None = None) -> float:
    """Warm ``method``'s solve (:func:`sshade.warmup.warm_fullres`, parallel kernels too
    when an ``n_vertices`` mesh uses them) and, when its start is coarse on such a mesh
    (``n_vertices`` None: whenever the start is not ``"rigid"``), the remesh and low-res
    solve of the coarse start. Returns the seconds spent (0.0 when warm)."""
    s = warm_fullres(method.energy, "converged", n_vertices)
    if method.start != "rigid" and (
            n_vertices is None or uses_coarse(method.start, int(n_vertices), method.coarse_n_low)):
        s += warm_once(WARMED, ("coarse_start", method.energy),
                       lambda V, F, h, T: coarse_start(V, F, h, T, energy=method.energy, n_low=40))
    return s

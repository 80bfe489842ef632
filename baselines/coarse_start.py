"""A coarse-to-fine start for the converged protocol of the full-resolution baselines
(ARAP, Elastic, ARAP-SR): the same energy solved on a low-resolution remesh
(:func:`sshade.remesh.remesh`, the handles kept as vertices), every full-resolution vertex
given the rotation of its low-res Voronoi region, and the full-resolution solve started
from those rotations (``R0`` of :func:`sshade.arap.solve_arap` /
:func:`sshade.arap.solve_arap_sr`). :func:`check_start` checks the
``start`` / ``coarse_n_low`` options, :func:`start_rotations` applies them (``"auto"``:
coarse on meshes of at least :data:`COARSE_MIN_RATIO` x ``coarse_n_low`` vertices, rigid
where the coarse start fails), :func:`coarse_start` is the start itself. Why it works and
what it saves: docs/implementation.md, "Implementation notes: baselines/coarse_start.py".
"""
from __future__ import annotations

import time

import numpy as np

from sshade.arap import DEFORM_ENERGIES, SR_ENERGY, ArapOptions, Criterion, build_operators, solve_arap, solve_arap_sr
from sshade.errors import SShaDeError
from sshade.remesh import remesh

from .starts import STARTS, check_start

__all__ = ["coarse_start", "start_rotations", "check_start", "uses_coarse", "STARTS", "COARSE_MIN_RATIO",
           "COARSE_N_LOW", "COARSE_MAX_ITER"]

#: ``"auto"`` starts coarse only when the mesh has at least this many times ``n_low`` vertices
COARSE_MIN_RATIO = 4
#: the low-resolution size of the coarse start (``coarse_n_low``) by default: SShaDe's
#: paper size (§4.1), the one home of this default (method YAMLs held to it by a test)
COARSE_N_LOW = 6000
#: the iteration cap of the coarse start's low-res ARAP and Elastic solve (ARAP-SR's: the
#: converged protocol's, :data:`sshade.arap.DEFAULT_MAX_ITER`)
COARSE_MAX_ITER = 5000


def uses_coarse(start: str, n_vertices: int, coarse_n_low: int) -> bool:
    """Whether ``start`` begins with a coarse solve on an ``n_vertices`` mesh."""
    return start == "coarse" or (start == "auto" and n_vertices >= COARSE_MIN_RATIO * coarse_n_low)


def start_rotations(start: str, V, F, handles, targets, *, energy: str, coarse_n_low: int, alpha: float = 0.0,
                    criterion: Criterion | None = None,
                    alpha_scaling: str = "valence") -> tuple[np.ndarray | None, dict]:
    """The start rotations of the converged protocol under ``start``
    (:func:`check_start`): ``(R0, info)`` from :func:`coarse_start` when
    :func:`uses_coarse`, else ``(None, {})`` (the rigid fit). With ``"auto"`` a remesh or
    low-res solve that fails (SShaDeError) falls back to the rigid start; with
    ``"coarse"`` the error propagates."""
    if not uses_coarse(start, len(V), coarse_n_low):
        return None, {}
    try:
        return coarse_start(V, F, handles, targets, energy=energy, alpha=alpha, n_low=coarse_n_low,
                            criterion=criterion, alpha_scaling=alpha_scaling)
    except SShaDeError:  # "auto" is best effort: the rigid start
        if start == "coarse":
            raise
        return None, {}


def coarse_start(V, F, handles, targets, *, energy: str, alpha: float = 0.0, n_low: int = COARSE_N_LOW, seed: int = 0,
                 criterion: Criterion | None = None, alpha_scaling: str = "valence") -> tuple[np.ndarray, dict]:
    """Start rotations for a full-resolution solve from a low-resolution solve of the same
    energy.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64, a validated single-component manifold mesh.
    handles : (h,) int64 unique; targets : (h, 3) float64.
    energy : ``"spokes"`` or ``"spokes_and_rims"`` (:func:`sshade.arap.solve_arap`), or
        :data:`sshade.arap.SR_ENERGY` (ARAP-SR, :func:`sshade.arap.solve_arap_sr`).
    alpha : float >= 0, ARAP-SR's smoothness weight (the same at both resolutions).
    alpha_scaling : ARAP-SR's definition of alpha
        (:data:`sshade.arap.ALPHA_SCALINGS`).
    n_low : int >= 4, farthest-point samples of the remesh (the handles are added).
    seed : int, the remesh's first sample. criterion : the low-res solve's (default
        :data:`sshade.arap.DEFAULT_CRITERION`; ARAP and Elastic capped at
        :data:`COARSE_MAX_ITER` iterations, ARAP-SR at the converged protocol's).

    Returns
    -------
    R0 : (n, 3, 3) float64 rotations (vertex ``i`` gets its region's ``R``).
    info : dict ``coarse_n``, ``coarse_iterations``, ``coarse_status``, ``remesh_s``,
        ``coarse_s`` (seconds).

    Raises
    ------
    SShaDeError from the remesh or the low-res solve (bad mesh, handles, options), or an
    unknown ``energy``.

    Examples
    --------
    Example::

        R0, info = coarse_start(V, F, handles, targets, energy="spokes", n_low=COARSE_N_LOW)
        res = solve_arap(V, F, handles, targets, ArapOptions(energy="spokes"), R0=R0)
    """
    if energy not in DEFORM_ENERGIES:
        raise SShaDeError(f"coarse start: unknown energy {energy!r}; use one of {DEFORM_ENERGIES}")
    t0 = time.perf_counter()
    rm = remesh(V, F, int(n_low), seed=seed, required=handles)
    t1 = time.perf_counter()
    Vl, hl = V[rm.seeds], rm.label[handles]
    if energy == SR_ENERGY:
        res = solve_arap_sr(Vl, rm.F, hl, targets, ArapOptions(alpha=alpha, alpha_scaling=alpha_scaling,
                                                               criterion=criterion))
        R = res.info["R"]
    else:
        ops = build_operators(Vl, rm.F, energy)
        options = ArapOptions(energy=energy, criterion=criterion, max_iter=COARSE_MAX_ITER)
        res = solve_arap(Vl, rm.F, hl, targets, options, operators=ops)
        R = ops.rotations(res.V)
    R0 = np.ascontiguousarray(R[rm.label])
    info = {"coarse_n": int(len(rm.seeds)), "coarse_iterations": int(res.iterations),
            "coarse_status": str(res.info["status"]), "remesh_s": t1 - t0, "coarse_s": time.perf_counter() - t1}
    return R0, info

"""ARAP-SR under the paper's protocol (paper §4.1, Table 1): Open3D's plain Smoothed-ARAP
iteration, every rotation at once from the previous ones (a Jacobi local step,
:meth:`sshade.arap.smooth_rotations.SRProblem.sweep`) then the global step, stopped by the
relative energy change or the largest vertex move, the stop then told converged or stalled
by the gradient norm. It imports nothing of the converged solvers
(:mod:`sshade.arap.sr_solver`, :mod:`sshade.arap.solver`, the accelerators), so a change to
them leaves these rows' code identity as it was (eval.run.code_identity).
"""
from __future__ import annotations

import time

import numpy as np

from ..errors import SShaDeError
from .operators import bbox_diag
from .options import ArapOptions
from .result import ArapResult
from .rigid import rigid_fit
from .smooth_rotations import SRProblem, check_sr_options

__all__ = ["arap_sr_deform"]


def arap_sr_deform(V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray,
                   options: ArapOptions | None = None, *, U0: np.ndarray | None = None,
                   problem: SRProblem | None = None) -> ArapResult:
    """ARAP with smooth rotations under the paper protocol (§4.1; the converged protocol
    is :func:`sshade.arap.sr_solver.solve_arap_sr`).

    From ``U0`` (default the rigid fit of the handles), each iteration takes every rotation
    at once from the previous ones (Jacobi local step, :meth:`SRProblem.sweep`), then
    the global step, until ``options.stop`` fires: ``"energy"`` (default; the relative
    change of ``E`` over one iteration below ``criterion.etol``) or ``"move"`` (the largest
    vertex move of one iteration below ``tol * bbox_diag``). ``status`` is then
    ``"converged"`` when the gradient norm is below ``criterion.gtol`` (and, for the energy
    stop, the relative decrease below ``criterion.etol``), else ``"stalled"``;
    ``"max_iter"`` / ``"time_budget"`` at the caps.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64 (validated). handles : (h,) int64;
    targets : (h, 3) float64.
    options : :class:`sshade.arap.options.ArapOptions` or None (its defaults). Read:
        ``alpha`` (rotation-smoothness weight times the surface area A, so it is
        scale-free; 0 gives plain ARAP, spokes), ``alpha_scaling``, ``stop``, ``tol``
        (the move rule's, a fraction of the bounding-box diagonal), ``criterion``,
        ``max_iter`` (None: the paper protocol's 1000), ``time_budget_s``,
        ``linear_solver``, ``energy`` (the default or ``"arap_sr"``), ``protocol`` (either:
        this is the paper protocol). The others must keep their defaults.
    U0 : (n, 3) float64 or None, start (handle rows set to ``targets``); the first local
        step takes the rigid fit's rotation as every vertex's previous one.
    problem : :class:`SRProblem` or None, prebuilt for the same inputs, ``alpha`` and
        ``alpha_scaling``.

    Returns
    -------
    :class:`sshade.arap.ArapResult`; ``info``: ``status``, ``stop``, ``energy`` (``E``,
    mesh units^2), ``gnorm``, ``rel_decrease``, ``alpha``, ``alpha_scaling``, ``R``
    ((n, 3, 3) the final rotations).

    Raises
    ------
    SShaDeError on bad options (an option not read set, another energy), a ``problem`` of
    another alpha, a bad ``U0``.

    Examples
    --------
    Example::

        res = arap_sr_deform(V, F, handles, targets, ArapOptions(stop="move"))
    """
    o = check_sr_options(options, "arap_sr_deform", problem)
    stop, crit = o.stop, o.criterion
    V = np.ascontiguousarray(V, np.float64)
    diag = bbox_diag(V)
    R0, t0_ = rigid_fit(V[handles], targets)
    info = {"alpha": o.alpha, "alpha_scaling": o.alpha_scaling, "stop": stop}
    if float(np.abs(V[handles] @ R0.T + t0_ - targets).max()) <= 1e-12 * diag:
        return ArapResult(V=V @ R0.T + t0_, iterations=0, converged=True, last_move=0.0, precompute_s=0.0,
                          solve_s=0.0, info=dict(info, rigid=True, status="rigid"))
    t0 = time.perf_counter()
    pb = SRProblem(V, F, handles, targets, o.alpha, o.linear_solver, o.alpha_scaling) if problem is None \
        else problem
    t1 = time.perf_counter()
    U = V @ R0.T + t0_ if U0 is None else np.array(U0, np.float64)
    if U.shape != (pb.n, 3) or not np.isfinite(U).all():
        raise SShaDeError(f"U0 must be a finite ({pb.n}, 3) array")
    U[pb.h] = pb.T
    state = (U, *pb.work_step(U, pb.to_work(np.broadcast_to(R0, (pb.n, 3, 3))), jacobi=True))
    (U, Rw, E), it, move, rel, status = _paper_iterations(pb, state, stop, o.tol * diag, crit,
                                                          o.iteration_cap("paper"), o.time_budget_s)
    t2 = time.perf_counter()
    gn = pb.gnorm(U, None, pb.work_rhs(Rw))
    if status == "rule":
        status = "converged" if gn < crit.gtol and (stop == "move" or abs(rel) < crit.etol) else "stalled"
    info.update(status=status, energy=E, gnorm=gn, rel_decrease=rel)
    return ArapResult(V=U, iterations=it, converged=status == "converged", last_move=move, precompute_s=t1 - t0,
                      solve_s=t2 - t1, info=dict(info, R=pb.from_work(Rw)))


def _paper_iterations(pb: SRProblem, state, stop, thresh, crit, max_iter, time_budget_s):
    """The iterations of :func:`arap_sr_deform` from ``state = (U, R, E)`` (``R`` the
    local step at ``U`` in the iterations' numbering, :meth:`SRProblem.to_work`; ``E`` its
    energy): ``((U, R, E), iterations, last_move, rel_decrease, status)`` with status
    ``"rule"`` (the stop rule fired), ``"max_iter"`` or ``"time_budget"``."""
    t0 = time.perf_counter()
    (U, R, E), it, rel, Up = state, 0, np.inf, None

    def moved():  # the largest vertex move of the last iteration (inf before the first)
        return np.inf if Up is None else float(np.sqrt(((U - Up) ** 2).sum(1).max()))
    while True:
        if it >= max_iter:
            return (U, R, E), it, moved(), rel, "max_iter"
        if time_budget_s is not None and time.perf_counter() - t0 > time_budget_s:
            return (U, R, E), it, moved(), rel, "time_budget"
        Un = pb.global_step(U, None, pb.work_rhs(R))
        R, En = pb.work_step(Un, R.copy(), jacobi=True)
        rel = (E - En) / abs(En) if En != 0 else 0.0
        Up, U, E, it = U, Un, En, it + 1
        if (moved() < thresh) if stop == "move" else (abs(rel) < crit.etol):
            return (U, R, E), it, moved(), rel, "rule"

"""ARAP-SR run to a certified convergence (the converged protocol): from the rigid fit of
the handles (or given rotations), Gauss-Seidel local steps over a vertex colouring
(:class:`sshade.arap.smooth_rotations.SRProblem`) and global steps, accelerated by Anderson on
the joint state, stopped by the energy-and-gradient criterion
(:class:`sshade.arap.criterion.Criterion`). Derivation and measurements:
docs/implementation.md, "Implementation notes: sshade/arap/smooth_rotations.py".
"""
from __future__ import annotations

import time

import numpy as np

from ..errors import SShaDeError
from .accelerate import Anderson
from .options import SR_ENERGY, ArapOptions
from .result import ArapResult
from .rigid import rigid_fit
from .smooth_rotations import SRProblem, check_sr_options

__all__ = ["solve_arap_sr", "SR_ACCELERATIONS"]

#: the iterations of :func:`solve_arap_sr` (``accelerate``, ``"auto"`` resolved)
SR_ACCELERATIONS = ("anderson", "none")

clock = time.perf_counter


def solve_arap_sr(V, F, handles, targets, options: ArapOptions | None = None, *, U0: np.ndarray | None = None,
                  R0: np.ndarray | None = None, problem: SRProblem | None = None) -> ArapResult:
    """ARAP-SR run to a certified convergence, the converged protocol (docs/implementation.md,
    "Implementation notes: sshade/arap/smooth_rotations.py").

    Parameters
    ----------
    V : (n, 3) float64 rest positions (mesh units); F : (m, 3) int faces.
    handles : (h,) int unique vertex indices; targets : (h, 3) float64.
    options : :class:`sshade.arap.options.ArapOptions` or None (its defaults). Read:
        ``alpha`` (smoothness weight times the surface area; 0: ARAP spokes),
        ``alpha_scaling`` (module docstring), ``criterion``, ``max_iter`` (None: 10000),
        ``accelerate`` (``"auto"`` or ``"anderson"``: Anderson; ``"none"``: plain block
        descent), ``history`` (Anderson's window, None: 5), ``time_budget_s``,
        ``linear_solver``, ``jacobi`` (Jacobi local step instead of Gauss-Seidel,
        measurements only: the energy may then increase; steps are not safeguarded),
        ``reset_on_reject`` (forget Anderson's history after a rejected candidate),
        ``energy`` (the default or ``"arap_sr"``). The others must keep their defaults.
    U0 : (n, 3) float64 or None, start (default: the rigid fit of the handles, rotations
        that fit's rotation; with ``R0``: the global step of ``R0``); handle rows are set
        to ``targets``.
    R0 : (n, 3, 3) float64 or None, start rotations (default: the rigid fit's), e.g.
        those of a solve on a low-resolution remesh; one sweep at ``U0`` follows.
    problem : :class:`SRProblem` or None, prebuilt for the same inputs, ``alpha``,
        ``alpha_scaling`` and linear solver.

    Returns
    -------
    :class:`sshade.arap.ArapResult` with ``info``: ``energy`` (``E(U, R)``, mesh
    units^2), ``gnorm``, ``rel_decrease``, ``energy_history`` (accepted states, starting
    at ``U0`` after one local step), ``status`` (``"converged"``, ``"max_iter"``,
    ``"time_budget"``, ``"stalled"``: no decrease in float64, ``"rigid"``),
    ``n_fallback`` (rejected Anderson candidates), ``n_sweeps``, ``n_colours``, ``alpha``,
    ``alpha_scaling``, ``R`` ((n, 3, 3) the final rotations).

    Raises
    ------
    SShaDeError on bad inputs (:class:`SRProblem`), ``U0`` / ``R0``, options (``accelerate``
    ``"lbfgs"``, an option not read set, another energy) or a ``problem`` of another alpha.
    """
    t0 = clock()
    o = check_sr_options(options, "solve_arap_sr", problem)
    accelerate = o.acceleration(SR_ENERGY)
    if accelerate not in SR_ACCELERATIONS:
        raise SShaDeError(f"solve_arap_sr: accelerate must be 'auto' or one of {SR_ACCELERATIONS}, got "
                          f"{o.accelerate!r} (ARAP-SR has no L-BFGS)")
    crit = o.criterion
    pb = problem if problem is not None else SRProblem(V, F, handles, targets, o.alpha, o.linear_solver,
                                                       o.alpha_scaling)
    Rr, tr_ = rigid_fit(pb.ops.V[pb.h], pb.T)
    if R0 is None:
        R = np.broadcast_to(Rr, (pb.n, 3, 3)).copy()
    else:
        R = np.array(R0, np.float64)
        if R.shape != (pb.n, 3, 3) or not np.isfinite(R).all():
            raise SShaDeError(f"R0 must be a finite ({pb.n}, 3, 3) array")
    U = (pb.ops.V @ Rr.T + tr_ if R0 is None else pb.global_step(pb.ops.V, R)) if U0 is None \
        else np.array(U0, np.float64)
    if U.shape != (pb.n, 3) or not np.isfinite(U).all():
        raise SShaDeError(f"U0 must be a finite ({pb.n}, 3) array")
    U[pb.h] = pb.T
    t1 = clock()
    info = {"alpha": pb.alpha, "alpha_scaling": pb.alpha_scaling, "etol": crit.etol, "gtol": crit.gtol,
            "accelerate": accelerate,
            "n_colours": len(pb.classes), "n_fallback": 0, "n_sweeps": 1, "linear_solver": pb.solver.backend}
    opts = {"m": o.window(accelerate), "jacobi": o.jacobi, "reset": o.reset_on_reject}
    Rw, E = pb.work_step(U, pb.to_work(R), o.jacobi)
    U, Rw, it, status = _iterate(pb, (U, Rw, E), crit, o.iteration_cap("converged"), accelerate, o.time_budget_s,
                                 opts, info)
    t2 = clock()
    return ArapResult(V=U, iterations=it, converged=status in ("converged", "rigid"), last_move=info.pop("move"),
                      precompute_s=t1 - t0, solve_s=t2 - t1, info=dict(info, status=status, R=pb.from_work(Rw)))


def _iterate(pb: SRProblem, state, crit, max_iter, accelerate, time_budget_s, opts, info):
    """The iterations of :func:`solve_arap_sr` from ``state = (U, R, E)`` (``R`` the local
    step at ``U`` in the iterations' numbering, :meth:`SRProblem.to_work`; ``E`` its
    energy; ``opts``: ``m``, ``jacobi``, ``reset``): returns ``(U, R, iterations,
    status)``, fills ``info``. ``K(R)`` of the accepted state is computed once, for the
    gradient test and the next global step."""
    t0 = clock()
    jacobi = opts["jacobi"]
    zero_E = 1e-12 * 2.0 * pb.ops.rest_term
    # numpy passes: the serial loop kernels of sshade.arap were measured slower on this 12 n-long state
    acc = Anderson(opts["m"], 3 * len(pb.free) + 9 * pb.n, None, 1) if accelerate == "anderson" else None
    (U, R, E), E_prev, it, Up = state, np.inf, 0, None
    hist = [E]
    while True:
        B = pb.work_rhs(R)
        gn = pb.gnorm(U, None, B)
        rel = 0.0 if abs(E) <= zero_E else ((E_prev - E) / abs(E) if np.isfinite(E_prev) else np.inf)
        status = ("converged" if it > 0 or abs(E) > zero_E else "rigid") if rel < crit.etol and gn < crit.gtol \
            else "max_iter" if it >= max_iter \
            else "time_budget" if time_budget_s is not None and clock() - t0 > time_budget_s else None
        if status is None and it > 0 and E >= E_prev and not jacobi:
            status = "stalled"
        if status is not None:
            break
        Ug = pb.global_step(U, None, B)
        Rg, Eg = pb.work_step(Ug, R.copy(), jacobi)
        info["n_sweeps"] += 1
        Un, Rn, En = Ug, Rg, Eg
        if acc is not None:  # residual of the joint map (U, R) -> (Ug, Rg); alpha = 0: R = R*(U), U's only
            cand = acc.step(pb.pack(U, R if pb.wR > 0 else Rg), pb.pack(Ug, Rg))
            if cand is not None:
                Ua, Ra = pb.unpack(cand, Ug)
                Ra, Ea = pb.work_step(Ua, Ra, jacobi)
                info["n_sweeps"] += 1
                if Ea < Eg:
                    Un, Rn, En = Ua, Ra, Ea
                else:
                    info["n_fallback"] += 1
                    if opts["reset"]:
                        acc.reset()
        Up, U, R, E_prev, E, it = U, Un, Rn, E, En, it + 1
        hist.append(E)
    move = 0.0 if Up is None else float(np.sqrt(((U - Up) ** 2).sum(1).max()))  # the last iteration's
    info.update(energy=E, gnorm=gn, rel_decrease=rel, energy_history=hist, move=move)
    return U, R, it, status

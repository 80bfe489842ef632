"""ARAP-SR: as-rigid-as-possible with smooth rotations (Levi & Gotsman 2015, "Smooth
rotation enhanced as-rigid-as-possible mesh animation", IEEE TVCG), behind the
:class:`sshade.method_interface.Deformer` interface (:class:`ARAPSR`).

Two protocols: ``"converged"`` (:func:`baselines.arap_sr_solver.solve_arap_sr`; that
module states the energy and both definitions of alpha) and ``"paper"``
(:func:`arap_sr_deform`: Open3D's plain Smoothed-ARAP iteration, run "until convergence
with a cutoff of 1000 iterations", paper §4.1). Why it is written on libigl and checked
against Open3D: docs/methods.md, "Implementation notes: baselines/arap_sr.py".
"""
from __future__ import annotations

import time

import numpy as np

from sshade.arap import DEFAULT_CRITERION, PROTOCOLS, ArapResult, bbox_diag, make_criterion, rigid_fit
from sshade.errors import SShaDeError
from sshade.mesh.unit_frame import unit_frame
from sshade.mesh.validate import validate_handles, validate_mesh
from sshade.warmup import WARMED, warm_once

from .arap_sr_solver import ALPHA_SCALINGS, SRProblem, solve_arap_sr
from .coarse_start import SR_ENERGY, check_start, start_rotations
from .fullres_arap import check_arap_args

__all__ = ["arap_sr_deform", "ARAPSR", "PAPER_STOPS"]

#: stopping rules of the paper protocol (:func:`arap_sr_deform`); the first is the default
PAPER_STOPS = ("energy", "move")


def arap_sr_deform(V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray, *,
                   alpha: float = 0.01, alpha_scaling: str = "valence", stop: str = "energy",
                   tol: float = 1e-4, criterion=None, max_iter: int = 1000,
                   time_budget_s: float | None = None) -> ArapResult:
    """ARAP with smooth rotations under the paper protocol (§4.1; the converged protocol
    is :func:`baselines.arap_sr_solver.solve_arap_sr`).

    From the rigid fit of the handles, each iteration takes every rotation at once from the
    previous ones (Jacobi local step, :meth:`baselines.arap_sr_solver.SRProblem.sweep`), then
    the global step, until ``stop`` fires: ``"energy"`` (default; the relative change of
    ``E`` over one iteration below ``criterion.etol``) or ``"move"`` (the largest vertex move
    of one iteration below ``tol * bbox_diag``). ``status`` is then ``"converged"`` when the
    gradient norm is below ``criterion.gtol`` (and, for the energy stop, the relative
    decrease below ``criterion.etol``), else ``"stalled"``; ``"max_iter"`` /
    ``"time_budget"`` at the caps.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64 (validated). handles : (h,) int64;
    targets : (h, 3) float64.
    alpha : float >= 0, rotation-smoothness weight (times the surface area A, so it is
        scale-free); 0 gives plain ARAP (spokes).
    alpha_scaling : one of :data:`baselines.arap_sr_solver.ALPHA_SCALINGS` (default
        ``"valence"``: Open3D's alpha).
    stop : one of :data:`PAPER_STOPS`. tol : float > 0, the move rule's tolerance
        (fraction of the bounding-box diagonal).
    criterion : :class:`sshade.arap.Criterion` or None (``DEFAULT_CRITERION``).
    max_iter : int >= 0, iteration cap. time_budget_s : optional cap on iteration time.

    Returns
    -------
    :class:`sshade.arap.ArapResult`; ``info``: ``status``, ``stop``, ``energy`` (``E``,
    mesh units^2), ``gnorm``, ``rel_decrease``, ``alpha``, ``alpha_scaling``.

    Raises
    ------
    SShaDeError on a bad ``stop``, ``alpha`` or ``alpha_scaling``.

    Examples
    --------
    Example::

        res = arap_sr_deform(V, F, handles, targets, alpha=0.01)
    """
    if stop not in PAPER_STOPS:
        raise SShaDeError(f"ARAP-SR: stop must be one of {PAPER_STOPS}, got {stop!r}")
    crit = DEFAULT_CRITERION if criterion is None else criterion
    V = np.ascontiguousarray(V, np.float64)
    diag = bbox_diag(V)
    R0, t0_ = rigid_fit(V[handles], targets)
    info = {"alpha": alpha, "alpha_scaling": alpha_scaling, "stop": stop}
    if float(np.abs(V[handles] @ R0.T + t0_ - targets).max()) <= 1e-12 * diag:
        return ArapResult(V=V @ R0.T + t0_, iterations=0, converged=True, last_move=0.0, precompute_s=0.0,
                          solve_s=0.0, info=dict(info, rigid=True, status="rigid"))
    t0 = time.perf_counter()
    pb = SRProblem(V, F, handles, targets, alpha, alpha_scaling=alpha_scaling)
    t1 = time.perf_counter()
    U = V @ R0.T + t0_
    U[pb.h] = pb.T
    R = pb.sweep(U, np.broadcast_to(R0, (pb.n, 3, 3)).copy(), jacobi=True)
    U, R, it, move, rel, status = _paper_iterations(pb, U, R, stop, tol * diag, crit, max_iter, time_budget_s)
    t2 = time.perf_counter()
    gn = pb.gnorm(U, R)
    if status == "rule":
        status = "converged" if gn < crit.gtol and (stop == "move" or abs(rel) < crit.etol) else "stalled"
    info.update(status=status, energy=pb.energy(U, R), gnorm=gn, rel_decrease=rel)
    return ArapResult(V=U, iterations=it, converged=status == "converged", last_move=move, precompute_s=t1 - t0,
                      solve_s=t2 - t1, info=dict(info, R=R))


def _paper_iterations(pb: SRProblem, U, R, stop, thresh, crit, max_iter, time_budget_s):
    """The iterations of :func:`arap_sr_deform` from ``(U, R)`` (``R`` the local step at
    ``U``): ``(U, R, iterations, last_move, rel_decrease, status)`` with status ``"rule"``
    (the stop rule fired), ``"max_iter"`` or ``"time_budget"``."""
    t0 = time.perf_counter()
    E, it, move, rel = pb.energy(U, R), 0, np.inf, np.inf
    while True:
        if it >= max_iter:
            return U, R, it, move, rel, "max_iter"
        if time_budget_s is not None and time.perf_counter() - t0 > time_budget_s:
            return U, R, it, move, rel, "time_budget"
        Un = pb.global_step(U, R)
        R = pb.sweep(Un, R.copy(), jacobi=True)
        En = pb.energy(Un, R)
        move = float(np.sqrt(((Un - U) ** 2).sum(1).max()))
        rel = (E - En) / abs(En) if En != 0 else 0.0
        U, E, it = Un, En, it + 1
        if (move < thresh) if stop == "move" else (abs(rel) < crit.etol):
            return U, R, it, move, rel, "rule"


class ARAPSR:
    """ARAP-SR baseline behind the :class:`sshade.method_interface.Deformer` interface.

    Parameters
    ----------
    alpha : float >= 0, rotation smoothness (times the surface area).
    alpha_scaling : ``"valence"`` (default: alpha as Open3D's Smoothed ARAP defines it, the
        neighbour term divided by the valence) or ``"none"`` (without the valence: about 6x
        stiffer at the same alpha); :mod:`baselines.arap_sr_solver`.
    protocol : ``"converged"`` (default, ``info["protocol"] = "converged-sr"``:
        :func:`baselines.arap_sr_solver.solve_arap_sr`, Gauss-Seidel local step and
        Anderson acceleration, stopped by the energy-and-gradient criterion ``etol`` /
        ``gtol``) or ``"paper"`` (:func:`arap_sr_deform`: Open3D's plain iteration run
        until the stop rule ``stop`` fires, at most 1000 iterations, then the stop
        classified converged or stalled by the gradient; ``info["protocol"] =
        "paper-sr"``, or ``"move-rule"`` with ``stop="move"``).
    stop : ``"paper"`` protocol's stop rule, :data:`PAPER_STOPS`: ``"energy"`` (default,
        relative energy change below ``etol``) or ``"move"`` (largest vertex move below
        ``tol`` x diagonal).
    tol : float > 0, ``"paper"`` with ``stop="move"``: move tolerance (fraction of the
        bounding-box diagonal).
    max_iter : int or None, iteration cap (None: 10000 converged, 1000 paper).
    etol, gtol : floats or None, the criterion (None: the defaults of
        :data:`sshade.arap.DEFAULT_CRITERION`): the ``"converged"`` protocol's stop, and
        under ``"paper"`` the energy stop (``etol``) and the converged/stalled test
        (``gtol``).
    start : ``"converged"`` protocol's start: ``"rigid"`` (the rigid fit of the handles),
        ``"coarse"`` (:func:`baselines.coarse_start.coarse_start`: the rotations of the
        same energy solved on a ``coarse_n_low``-vertex remesh), ``"auto"`` (default:
        coarse when the mesh has at least ``COARSE_MIN_RATIO * coarse_n_low`` vertices,
        falling back to rigid if the remesh or the low-res solve raises SShaDeError).
        Either start is stopped by the same full-resolution criterion.
    coarse_n_low : int >= 4, the remesh's sample count for the coarse start.

    Raises
    ------
    SShaDeError on a bad value.
    """

    name = "ARAP-SR"

    def __init__(self, *, alpha: float = 0.01, tol: float = 1e-4, max_iter: int | None = None,
                 protocol: str = "converged", etol: float | None = None, gtol: float | None = None,
                 start: str = "auto", coarse_n_low: int = 6000, alpha_scaling: str = "valence",
                 stop: str = "energy"):
        if protocol not in PROTOCOLS:
            raise SShaDeError(f"{self.name}: unknown protocol {protocol!r}; use one of {PROTOCOLS}")
        if stop not in PAPER_STOPS:
            raise SShaDeError(f"{self.name}: stop must be one of {PAPER_STOPS}, got {stop!r}")
        self.stop = stop
        self.start, self.coarse_n_low = check_start(self.name, start, coarse_n_low)
        args = check_arap_args(self.name, tol, max_iter, etol, gtol, alpha=alpha)  # SShaDeError on a bad value
        self.alpha, self.tol, self.protocol = args["alpha"], args["tol"], protocol
        if alpha_scaling not in ALPHA_SCALINGS:
            raise SShaDeError(f"{self.name}: alpha_scaling must be one of {ALPHA_SCALINGS}, got {alpha_scaling!r}")
        self.alpha_scaling = alpha_scaling
        self.max_iter = ({"converged": 10000, "paper": 1000}[protocol] if args["max_iter"] is None
                         else args["max_iter"])
        self.criterion = make_criterion(etol, gtol)
        self.info: dict = {}
        #: (n, 3, 3) float64 or None: the rotations of the last converged-protocol result
        #: (its reduced energy and a reference's continued solve start there; not in ``info``,
        #: which is stored as JSON)
        self.rotations: np.ndarray | None = None

    def effective_params(self) -> dict:
        """The parameters :meth:`deform` runs with, every default resolved: ``alpha`` and
        ``alpha_scaling`` (Open3D's Smoothed ARAP definition with ``valence``), ``protocol``,
        ``stop`` (the paper protocol's), ``tol``, ``max_iter``, ``etol`` / ``gtol``,
        ``start``, ``coarse_n_low``."""
        return {"alpha": self.alpha, "alpha_scaling": self.alpha_scaling, "protocol": self.protocol,
                "stop": self.stop, "tol": self.tol, "max_iter": self.max_iter, "etol": self.criterion.etol,
                "gtol": self.criterion.gtol, "start": self.start, "coarse_n_low": self.coarse_n_low}

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` so ``V[handles]`` reach ``targets``; (n, 3) float64.
        Solved in the mesh's unit frame (:mod:`sshade.mesh.unit_frame`) and mapped back,
        so a moved or scaled input gives the moved or scaled result; ``info["energy"]``
        in mesh units. Raises ``SShaDeError`` on invalid mesh or handles."""
        self.rotations = None
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        frame = unit_frame(V)  # solved centred and scaled (sshade.mesh.unit_frame), mapped back
        U, T = frame.to_unit(V), frame.to_unit(targets)
        if self.protocol == "paper":
            res = arap_sr_deform(U, F, handles, T, alpha=self.alpha, alpha_scaling=self.alpha_scaling,
                                 stop=self.stop, tol=self.tol, criterion=self.criterion, max_iter=self.max_iter)
        else:
            res = self._converged(U, F, handles, T)
        self.rotations = res.info.get("R") if self.protocol == "converged" else None
        proto = ("converged-sr" if self.protocol == "converged" else
                 "move-rule" if self.stop == "move" else "paper-sr")
        self.info = {"iterations": res.iterations, "converged": res.converged, "protocol": proto, "handles": "hard",
                     "precompute_s": res.precompute_s, "solve_s": res.solve_s, "alpha": self.alpha,
                     "alpha_scaling": self.alpha_scaling,
                     "s_per_iter": res.solve_s / max(res.iterations, 1)}
        for k in ("status", "energy", "gnorm", "rel_decrease", "n_fallback", "coarse_n", "coarse_iterations",
                  "coarse_s"):
            if k in res.info:
                self.info[k] = res.info[k]
        if "energy" in self.info:
            self.info["energy"] = frame.energy(self.info["energy"])
        Vd = frame.from_unit(res.V, out=res.V)
        Vd[handles] = targets  # hard constraints: exactly the targets given
        return Vd

    def _converged(self, V, F, handles, targets):
        """The converged protocol from the start of ``self.start``
        (:func:`baselines.coarse_start.start_rotations`); a coarse start's seconds count in
        ``precompute_s`` and its numbers go to ``info``."""
        R0, cinfo = start_rotations(self.start, V, F, handles, targets, energy=SR_ENERGY, alpha=self.alpha,
                                    alpha_scaling=self.alpha_scaling,
                                    coarse_n_low=self.coarse_n_low, criterion=self.criterion)
        res = solve_arap_sr(V, F, handles, targets, alpha=self.alpha, alpha_scaling=self.alpha_scaling,
                            criterion=self.criterion,
                            max_iter=self.max_iter, R0=R0)
        if cinfo:
            res.precompute_s += cinfo["remesh_s"] + cinfo["coarse_s"]
            res.info.update(cinfo)
        return res

    def warmup(self, n_vertices: int | None = None) -> float:
        """First-call costs (libigl, the linear solver, the polar and energy kernels, mesh
        validation, the remesh of a coarse start) paid once on a tiny mesh outside any timed call
        (:func:`sshade.warmup.warm_once`); ``n_vertices`` is ignored. Returns the seconds
        spent."""
        coarse = self.protocol == "converged" and self.start != "rigid"  # + the remesh's kernels
        return warm_once(WARMED, ("arap_sr", self.protocol, coarse),
                         lambda V, F, h, T: ARAPSR(alpha=self.alpha, alpha_scaling=self.alpha_scaling,
                                                   max_iter=5, protocol=self.protocol,
                                                   start="coarse" if coarse else "rigid",
                                                   coarse_n_low=40).deform(V, F, h, T))


def warmup_kernels() -> float:
    """Warm ARAP-SR under both protocols (:meth:`ARAPSR.warmup` with the defaults and with
    ``protocol="paper"``): the entry point ``sshade.warmup`` of ``python -m sshade warmup``.
    Returns the seconds spent."""
    return ARAPSR().warmup() + ARAPSR(protocol="paper").warmup()

"""Handle-driven ARAP under one of two protocols (:func:`arap_deform`, :data:`PROTOCOLS`):
SShaDe's low-res step (paper §3.3, §4.1: spokes-and-rims) and the full-resolution
baselines (Sorkine & Alexa 2007 "spokes"; Chao et al. 2010 "spokes and rims"); with
``energy="arap_sr"`` (:data:`DEFORM_ENERGIES`) ARAP with smooth rotations
(:mod:`sshade.arap.smooth_rotations`) under the same two protocols.

- ``"converged"`` (default): :func:`sshade.arap.solver.solve_arap`, stopped by
  :class:`sshade.arap.criterion.Criterion`;
- ``"paper"`` (paper §4.1, Table 1): libigl's ``arap_solve`` one iteration at a time
  (:func:`iterate`), stopped by the largest vertex move; ``"stalled"`` where the gradient
  test fails. Both start from the rigid fit of the handles. Details: docs/methods.md
  ("Implementation notes: sshade/arap/local_global.py").
"""
from __future__ import annotations

import time

import igl
import numpy as np

from ..errors import SShaDeError
from .criterion import DEFAULT_CRITERION, gradient_norm
from .operators import ENERGIES, bbox_diag, build_operators
from .result import ArapResult
from .rigid import rigid_fit
from .smooth_rotations import DEFAULT_ALPHA, SR_ENERGY, SRProblem, arap_sr_deform, solve_arap_sr
from .solver import ArapSolver

__all__ = ["arap_deform", "ArapDeformer", "iterate", "PROTOCOLS", "DEFAULT_MAX_ITER", "DEFORM_ENERGIES"]

PROTOCOLS = ("converged", "paper")
#: Iteration cap of each protocol when none is given (paper §4.1: 1000).
DEFAULT_MAX_ITER = {"converged": 10000, "paper": 1000}
#: The energies :func:`arap_deform` solves: :data:`sshade.arap.ENERGIES` and ARAP-SR's.
DEFORM_ENERGIES = (*ENERGIES, SR_ENERGY)


def iterate(step, U: np.ndarray, *, thresh: float, max_iter: int,
            time_budget_s: float | None = None) -> tuple[np.ndarray, int, bool, float]:
    """The paper's stopping rule (§4.1) around any local/global step.

    Parameters
    ----------
    step : callable (n, 3) -> (n, 3), one local/global iteration.
    U : (n, 3) float64 start. thresh : float, stop when the largest vertex move of one
        iteration is below it (mesh units). max_iter : int.
    time_budget_s : float or None, also stop (unconverged) after this many seconds.

    Returns
    -------
    (U, iterations, converged, last_move).
    """
    t0 = time.perf_counter()
    it, move, converged = 0, np.inf, False
    while it < max_iter:
        Un = step(U)
        it += 1
        move = float(np.sqrt(((Un - U) ** 2).sum(1).max()))
        U = Un
        if move < thresh:
            converged = True
            break
        if time_budget_s is not None and time.perf_counter() - t0 > time_budget_s:
            break
    return U, it, converged, move


def arap_deform(V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray, *,
                energy: str = "spokes_and_rims", tol: float = 1e-4, max_iter: int | None = None,
                V0: np.ndarray | None = None, time_budget_s: float | None = None,
                protocol: str = "converged", criterion=None, accelerate: str = "lbfgs",
                anderson_m: int | None = None, R0: np.ndarray | None = None,
                alpha: float = DEFAULT_ALPHA) -> ArapResult:
    """Handle-driven ARAP deformation under one of the two protocols (:data:`PROTOCOLS`).

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces.
    handles : (h,) int64 constrained vertex indices. targets : (h, 3) float64 positions.
    energy : ``"spokes"`` (ARAP, Sorkine & Alexa 2007), ``"spokes_and_rims"``
        (Elastic, Chao et al. 2010) or ``"arap_sr"`` (ARAP with smooth rotations, Levi &
        Gotsman 2015, Open3D's alpha: :func:`sshade.arap.smooth_rotations.solve_arap_sr`
        under ``"converged"``, :func:`sshade.arap.smooth_rotations.arap_sr_deform` with the
        move rule under ``"paper"``); :data:`DEFORM_ENERGIES`.
    tol : float, ``"paper"`` protocol: stop when the largest per-vertex move in one
        iteration is below ``tol * bbox_diag(V)``.
    max_iter : int or None, iteration cap (None: :data:`DEFAULT_MAX_ITER` of the
        protocol; paper: 1000).
    V0 : (n, 3) float64 or None, initial guess; default the best rigid fit of the
        handles (:func:`sshade.arap.rigid.rigid_fit`; for two or collinear handles the
        fit turning the mesh least) applied to ``V``.
    time_budget_s : float or None, stop (unconverged) once the iterations have taken
        this many seconds (for benchmarks of slow full-resolution runs).
    protocol : ``"converged"`` or ``"paper"`` (:data:`PROTOCOLS`).
    criterion : :class:`sshade.arap.criterion.Criterion` or None (its default), the
        ``"converged"`` protocol's stopping thresholds; under ``"paper"`` its ``gtol``
        tells a converged stop from a stalled one (``info["status"]``).
    accelerate : ``"lbfgs"`` (default), ``"anderson"`` or ``"none"``, the ``"converged"``
        protocol's iteration (:func:`sshade.arap.solver.solve_arap`; ``"arap_sr"`` has no
        L-BFGS: ``"lbfgs"`` runs its Anderson acceleration).
    anderson_m : int or None, its history window (None: 10 for L-BFGS, 5 for Anderson).
    R0 : (n, 3, 3) float64 or None, ``"converged"`` protocol only: start from the global
        step of these rotations (:func:`sshade.arap.solver.solve_arap`), not with ``V0``.
    alpha : float >= 0, ``"arap_sr"`` only: the smoothness weight, times the surface area
        of ``(V, F)`` (default :data:`sshade.arap.smooth_rotations.DEFAULT_ALPHA`, with
        Open3D's valence scaling).

    Returns
    -------
    ArapResult (``info["protocol"]`` names the protocol, ``info["status"]`` how it stopped,
    ``info["gnorm"]`` the gradient norm at the result; the ``"converged"`` protocol adds
    the final energy and histories, see :func:`sshade.arap.solver.solve_arap`;
    ``"arap_sr"`` adds ``energy`` and the rotations ``R``).

    Raises
    ------
    SShaDeError on an unknown energy or protocol, ``R0`` under the ``"paper"`` protocol
    (inputs are assumed validated by the caller), a bad ``alpha`` (``"arap_sr"``).

    Examples
    --------
    Example::

        import igl
        res = arap_deform(V, F, np.array([0, 5]), V[[0, 5]] + 0.1)
    """
    return ArapDeformer(V, F, handles, energy=energy, protocol=protocol, alpha=alpha).deform(
        targets, tol=tol, max_iter=max_iter, V0=V0, time_budget_s=time_budget_s, criterion=criterion,
        accelerate=accelerate, anderson_m=anderson_m, R0=R0)


class ArapDeformer:
    """:func:`arap_deform` prepared once for a mesh and a handle set, then run for any
    targets (an animation's frames): the ``"converged"`` protocol keeps its
    :class:`sshade.arap.solver.ArapSolver` (operators, numbering, Cholesky factor), the
    ``"paper"`` protocol libigl's ``ARAPData`` after ``arap_precomputation``, ``"arap_sr"``
    its :class:`sshade.arap.smooth_rotations.SRProblem`. Each is made on the first call
    whose handles do not move rigidly (a rigid motion needs none).

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces. handles : (h,) int64
        constrained vertex indices (validated by the caller, as for :func:`arap_deform`).
    energy : one of :data:`DEFORM_ENERGIES`. protocol : one of :data:`PROTOCOLS`.
    alpha : float >= 0, ``"arap_sr"``'s smoothness weight (:func:`arap_deform`).

    Raises
    ------
    SShaDeError on an unknown energy or protocol.

    Examples
    --------
    >>> from sshade.arap.problems import twisted_bar
    >>> V, F, h, T = twisted_bar(60.0, h=0.25)
    >>> d = ArapDeformer(V, F, h, energy="spokes")
    >>> d.deform(T).converged and d.deform(T * 1.01).converged
    True
    """

    def __init__(self, V, F, handles, *, energy: str = "spokes_and_rims", protocol: str = "converged",
                 alpha: float = DEFAULT_ALPHA):
        if energy not in DEFORM_ENERGIES:
            raise SShaDeError(f"unknown ARAP energy {energy!r}; use one of {DEFORM_ENERGIES}")
        if protocol not in PROTOCOLS:
            raise SShaDeError(f"unknown ARAP protocol {protocol!r}; use one of {PROTOCOLS}")
        self.V = np.ascontiguousarray(V, np.float64)
        self.F = np.ascontiguousarray(F, np.int64)
        self.handles = handles
        self.energy, self.protocol, self.alpha = energy, protocol, alpha
        self.diag = bbox_diag(self.V)
        self._solver = self._data = self._ops = self._sr = None

    @property
    def factorisation(self):
        """The converged protocol's factorised ``L_ff``
        (:attr:`sshade.arap.solver.ArapSolver.factorisation`; ``"arap_sr"``: its
        :class:`SRProblem`'s, under either protocol), None until a solve made it."""
        if self._sr is not None:
            return self._sr.solver
        return None if self._solver is None else self._solver.factorisation

    def deform(self, targets, *, tol: float = 1e-4, max_iter: int | None = None, V0: np.ndarray | None = None,
               time_budget_s: float | None = None, criterion=None, accelerate: str = "lbfgs",
               anderson_m: int | None = None, R0: np.ndarray | None = None,
               carry_history: bool = False) -> ArapResult:
        """The deformation for ``targets`` ((h, 3) float64); parameters and result as
        :func:`arap_deform`, and ``carry_history`` (``"converged"`` protocol: start the
        accelerator with the last solve's history, as
        :meth:`sshade.arap.solver.ArapSolver.solve`; not ``"arap_sr"``'s, which starts each
        solve without history). Raises SShaDeError for ``R0`` under the ``"paper"`` protocol."""
        protocol, V, handles = self.protocol, self.V, self.handles
        if R0 is not None and protocol != "converged":
            raise SShaDeError("start rotations R0 are for the 'converged' protocol only")
        if max_iter is None:
            max_iter = DEFAULT_MAX_ITER[protocol]
        bc = np.ascontiguousarray(targets, np.float64)
        R, t = rigid_fit(V[handles], bc)
        rigid_resid = float(np.abs(V[handles] @ R.T + t - bc).max())
        if rigid_resid <= 1e-12 * self.diag:
            # The handles move rigidly: the rigid motion (no distortion at all) is the answer,
            # under both protocols. It is the minimiser wherever the cotangent weights are
            # positive; on meshes with obtuse triangles libigl's weights turn negative and the
            # raw energy could be lowered by distorting, which no user asks for. (Also avoids
            # libigl's single-precision 3x3 polar decomposition adding ~1e-6 noise.)
            return ArapResult(V=V @ R.T + t, iterations=0, converged=True, last_move=0.0,
                              precompute_s=0.0, solve_s=0.0, info={"rigid": True, "protocol": protocol,
                                                                   "status": "rigid"})
        if self.energy == SR_ENERGY:
            return self._smooth_rotations(bc, tol=tol, max_iter=max_iter, V0=V0, R0=R0, time_budget_s=time_budget_s,
                                          criterion=criterion, accelerate=accelerate, anderson_m=anderson_m)
        if protocol == "converged":
            if self._solver is None:
                self._solver = ArapSolver(V, self.F, handles, energy=self.energy)
            res = self._solver.solve(targets, U0=V0, R0=R0, criterion=criterion, max_iter=max_iter,
                                     accelerate=accelerate, anderson_m=anderson_m, time_budget_s=time_budget_s,
                                     carry_history=carry_history)
            res.info["protocol"] = "converged"
            return res
        U = V @ R.T + t if V0 is None else np.ascontiguousarray(V0, np.float64).copy()
        res = self._paper(bc, U, thresh=tol * self.diag, max_iter=max_iter, time_budget_s=time_budget_s)
        return self._classify(res, DEFAULT_CRITERION if criterion is None else criterion)

    def _smooth_rotations(self, bc: np.ndarray, *, tol, max_iter, V0, R0, time_budget_s, criterion, accelerate,
                          anderson_m) -> ArapResult:
        """ARAP-SR for the targets ``bc`` (h, 3) under this deformer's protocol, options as
        :meth:`deform`: :func:`solve_arap_sr` (``"lbfgs"`` runs its Anderson acceleration;
        ``anderson_m`` None: its window) or :func:`arap_sr_deform` with the move rule
        (``tol``). Its :class:`SRProblem` is made by the first call (its seconds in that
        result's ``precompute_s``) and given each later call's targets."""
        t0 = time.perf_counter()
        if self._sr is None:
            self._sr = SRProblem(self.V, self.F, self.handles, bc, self.alpha)
        else:
            self._sr.set_targets(bc)
        setup_s = time.perf_counter() - t0
        if self.protocol == "paper":
            res = arap_sr_deform(self.V, self.F, self.handles, bc, alpha=self.alpha, stop="move", tol=tol,
                                 criterion=criterion, max_iter=max_iter, time_budget_s=time_budget_s, V0=V0,
                                 problem=self._sr)
        else:
            window = {} if anderson_m is None else {"anderson_m": anderson_m}
            res = solve_arap_sr(self.V, self.F, self.handles, bc, alpha=self.alpha, criterion=criterion,
                                max_iter=max_iter, accelerate="anderson" if accelerate == "lbfgs" else accelerate,
                                U0=V0, R0=R0, time_budget_s=time_budget_s, problem=self._sr, **window)
        res.precompute_s += setup_s
        res.info["protocol"] = self.protocol
        return res

    def _paper(self, bc: np.ndarray, U: np.ndarray, *, thresh: float, max_iter: int,
               time_budget_s: float | None) -> ArapResult:
        """The ``"paper"`` protocol: libigl's local/global from ``U`` (n, 3) (its handle
        rows set to ``bc`` (h, 3) here), stopped by :func:`iterate`; libigl's
        precomputation on the first call (its seconds in that result's ``precompute_s``)."""
        b = np.ascontiguousarray(self.handles, np.int32)
        U[b] = bc
        t0 = time.perf_counter()
        if self._data is None:
            data = igl.ARAPData()
            data.energy = (igl.ARAP_ENERGY_TYPE_SPOKES if self.energy == "spokes"
                           else igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS)
            data.max_iter = 1
            igl.arap_precomputation(self.V, self.F, 3, b, data)
            self._data = data
        t1 = time.perf_counter()
        U, it, converged, move = iterate(lambda X: igl.arap_solve(bc, self._data, X), U, thresh=thresh,
                                         max_iter=max_iter, time_budget_s=time_budget_s)
        t2 = time.perf_counter()
        return ArapResult(V=U, iterations=it, converged=converged, last_move=move,
                          precompute_s=t1 - t0, solve_s=t2 - t1,
                          info={"protocol": "paper", "status": ("converged" if converged else
                                                               "max_iter" if it >= max_iter else "time_budget")})

    def _classify(self, res: ArapResult, criterion) -> ArapResult:
        """Under the ``"paper"`` protocol, tell a converged stop of the move rule from a
        stalled one by the gradient norm at the result (``criterion.gtol``, the converged
        protocol's test); sets ``res.converged``, ``info["status"]`` and ``info["gnorm"]``.
        Not timed (outside ``solve_s``)."""
        if self._ops is None:
            self._ops = build_operators(self.V, self.F, self.energy)
        ops = self._ops
        free = np.ones(len(self.V), bool)
        free[self.handles] = False
        g = 2.0 * (ops.L @ res.V - ops.rhs(ops.rotations(res.V)))[free]
        gn = gradient_norm(g, ops.mass[free], ops.diag)
        res.info["gnorm"] = gn
        if res.info["status"] == "converged" and not gn < criterion.gtol:
            res.info["status"] = "stalled"
            res.converged = False
        return res



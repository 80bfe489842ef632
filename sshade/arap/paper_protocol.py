"""The paper's protocol for the ARAP energies (paper §4.1, Table 1): libigl's
``arap_solve`` one iteration at a time, stopped when the largest vertex move of one
iteration falls below a tolerance (:func:`iterate`), the stop then told converged or
stalled by the gradient norm at the result (:class:`PaperSolver`, :func:`paper_deform`).

This module imports nothing of the converged solver (:mod:`sshade.arap.solver`, its
accelerators and loop kernels), so the code identity of a row run under this protocol
does not hold that solver (eval.run.code_identity; docs/implementation.md). ARAP-SR's
paper protocol is :func:`sshade.arap.sr_paper_protocol.arap_sr_deform`;
:func:`sshade.arap.local_global.arap_deform` picks either for an energy.
"""
from __future__ import annotations

import time

import igl
import numpy as np

from ..errors import SShaDeError
from ..mesh.validate import validate_handles, validate_mesh
from ..warmup_base import WARMED, warm_once
from .criterion import gradient_norm
from .operators import ENERGIES, bbox_diag, build_operators
from .options import READS, ArapOptions
from .result import ArapResult
from .rigid import rigid_fit
from .rigid_motion import rigid_motion

__all__ = ["iterate", "PaperSolver", "paper_deform", "warm_paper"]


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


class PaperSolver:
    """The paper's protocol prepared for a mesh, a handle set and an ARAP energy, then run
    for any targets: libigl's ``ARAPData`` after ``arap_precomputation`` (made by the
    first :meth:`solve`), and the energy's operators for the gradient test (made by the
    first :meth:`classify`).

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces. handles : (h,) int64
        constrained vertex indices (validated by the caller).
    energy : ``"spokes"`` (ARAP, Sorkine & Alexa 2007) or ``"spokes_and_rims"`` (Elastic,
        Chao et al. 2010).

    Examples
    --------
    >>> from sshade.arap.problems import twisted_bar
    >>> V, F, h, T = twisted_bar(60.0, h=0.25)
    >>> res = PaperSolver(V, F, h, "spokes").deform(T, ArapOptions(protocol="paper"))
    >>> res.info["status"] in ("converged", "stalled", "max_iter")
    True
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, handles: np.ndarray, energy: str):
        self.V = np.ascontiguousarray(V, np.float64)
        self.F = np.ascontiguousarray(F, np.int64)
        self.handles, self.energy = handles, energy
        self.diag = bbox_diag(self.V)
        self._data = self._ops = None

    def deform(self, targets: np.ndarray, options: ArapOptions, U0: np.ndarray | None = None) -> ArapResult:
        """The paper's protocol for ``targets`` (h, 3) float64 from ``U0`` ((n, 3) float64;
        None: the best rigid fit of the handles applied to the rest positions), with
        ``options``' ``tol`` (fraction of the bounding-box diagonal), ``max_iter`` (None:
        1000), ``time_budget_s`` and ``criterion.gtol``: :meth:`solve`, then
        :meth:`classify`. Returns an ArapResult as :func:`paper_deform`."""
        bc = np.ascontiguousarray(targets, np.float64)
        if U0 is None:
            R, t = rigid_fit(self.V[self.handles], bc)
            U = self.V @ R.T + t
        else:
            U = np.ascontiguousarray(U0, np.float64).copy()
        res = self.solve(bc, U, thresh=options.tol * self.diag, max_iter=options.iteration_cap(),
                         time_budget_s=options.time_budget_s)
        return self.classify(res, options.criterion)

    def solve(self, bc: np.ndarray, U: np.ndarray, *, thresh: float, max_iter: int,
              time_budget_s: float | None) -> ArapResult:
        """libigl's local/global from ``U`` (n, 3) (its handle rows set to ``bc`` (h, 3)
        here), stopped by :func:`iterate` (``thresh`` in mesh units); libigl's
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

    def classify(self, res: ArapResult, criterion) -> ArapResult:
        """Tell a converged stop of the move rule from a stalled one by the gradient norm at
        the result (``criterion.gtol``, the converged protocol's test); sets
        ``res.converged``, ``info["status"]`` and ``info["gnorm"]``. Not timed (outside
        ``solve_s``)."""
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


def paper_deform(V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray,
                 options: ArapOptions | None = None, *, U0: np.ndarray | None = None) -> ArapResult:
    """Handle-driven ARAP or Elastic under the paper's protocol (§4.1): what
    :func:`sshade.arap.local_global.arap_deform` runs for these energies under
    ``protocol="paper"``, without the converged solver's code.

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces.
    handles : (h,) int64 constrained vertex indices. targets : (h, 3) float64 positions.
    options : ArapOptions with ``protocol="paper"`` and ``energy`` ``"spokes"`` or
        ``"spokes_and_rims"``; it reads ``tol`` (fraction of the bounding-box diagonal),
        ``max_iter`` (None: 1000), ``time_budget_s`` and ``criterion`` (its ``gtol``).
    U0 : (n, 3) float64 or None, the start (default: the best rigid fit of the handles
        applied to ``V``, :func:`sshade.arap.rigid.rigid_fit`).

    Returns
    -------
    ArapResult: ``info["status"]`` ``"rigid"`` (the handles move rigidly:
    :func:`sshade.arap.rigid_motion.rigid_motion`), ``"converged"``, ``"stalled"``,
    ``"max_iter"`` or ``"time_budget"``; ``info["gnorm"]`` the gradient norm at the result.

    Raises
    ------
    SShaDeError on options not an ArapOptions, of another protocol or energy, or setting
    a field this protocol does not read (inputs are assumed validated by the caller).
    """
    o = ArapOptions.of(options, "paper_deform")
    if o.protocol != "paper" or o.energy not in ENERGIES:
        raise SShaDeError(f"paper_deform: the paper protocol of the energies {ENERGIES}, "
                          f"got protocol {o.protocol!r}, energy {o.energy!r}")
    o.refuse_unused(READS["arap_deform (paper)"] | {"energy", "protocol"}, "paper_deform (paper protocol)")
    solver = PaperSolver(V, F, handles, o.energy)
    bc = np.ascontiguousarray(targets, np.float64)
    rigid = rigid_motion(solver.V, handles, bc, solver.diag, "paper")
    return rigid if rigid is not None else solver.deform(bc, o, U0)


def warm_paper(energy: str) -> float:
    """Warm the paper protocol of ``energy`` (``"spokes"`` or ``"spokes_and_rims"``) once per
    process: a baseline's checks and :func:`paper_deform` on
    :func:`sshade.warmup_base.tiny_problem` (libigl's set-up, the gradient test's kernels;
    libigl's iteration has no parallel variant to compile). Returns the seconds spent (0.0
    when warm). Errors of the run propagate (:func:`sshade.warmup_base.warm_once`)."""

    def run(V, F, h, T):  # as the baselines' deform: validation, then the solve
        V, F = validate_mesh(V, F)
        h, T = validate_handles(V, h, T)
        return paper_deform(V, F, h, T, ArapOptions(energy=energy, protocol="paper"))
    return warm_once(WARMED, ("fullres", energy, "paper"), run)

"""Handle-driven ARAP under one of two protocols (:func:`arap_deform`; its options
:class:`sshade.arap.options.ArapOptions`): SShaDe's low-res step (paper §3.3, §4.1:
spokes-and-rims) and the full-resolution baselines (Sorkine & Alexa 2007 "spokes"; Chao et
al. 2010 "spokes and rims"); with ``energy="arap_sr"`` ARAP with smooth rotations
(:mod:`sshade.arap.smooth_rotations`) under the same two protocols.

- ``"converged"`` (default): :func:`sshade.arap.solver.solve_arap`, stopped by
  :class:`sshade.arap.criterion.Criterion`;
- ``"paper"`` (paper §4.1, Table 1): libigl's ``arap_solve`` one iteration at a time,
  stopped by the largest vertex move; ``"stalled"`` where the gradient test fails
  (:mod:`sshade.arap.paper_protocol`). Both start from the rigid fit of the handles. Details: docs/implementation.md
  ("Implementation notes: sshade/arap/local_global.py").
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..errors import SShaDeError
from .operators import bbox_diag
from .options import READS, SR_ENERGY, ArapOptions
from .paper_protocol import PaperSolver, iterate
from .result import ArapResult
from .rigid_motion import rigid_motion
from .smooth_rotations import SRProblem
from .solver import ArapSolver
from .sr_paper_protocol import arap_sr_deform
from .sr_solver import solve_arap_sr

__all__ = ["arap_deform", "ArapDeformer", "iterate", "deformer_reads", "DEFORMER_SETUP"]

#: the options an :class:`ArapDeformer` is set up with: each deform's must be the same
DEFORMER_SETUP = ("energy", "protocol", "alpha", "alpha_scaling", "linear_solver", "threads", "reorder")


def deformer_reads(energy: str, protocol: str) -> frozenset[str]:
    """The fields of :class:`sshade.arap.options.ArapOptions` that :func:`arap_deform` reads
    for ``energy`` under ``protocol``: ``energy``, ``protocol`` and those of the solver it
    runs (:data:`sshade.arap.options.READS`): ``solve_arap`` or ``solve_arap_sr`` under
    ``"converged"``; libigl's ``arap_solve`` or ``arap_sr_deform`` (always the move rule:
    no ``stop``) under ``"paper"``."""
    if protocol == "converged":
        used = READS["solve_arap_sr" if energy == SR_ENERGY else "solve_arap"]
    else:
        used = READS["arap_sr_deform"] - {"stop"} if energy == SR_ENERGY else READS["arap_deform (paper)"]
    return used | {"energy", "protocol"}


def arap_deform(V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray,
                options: ArapOptions | None = None, *, U0: np.ndarray | None = None,
                R0: np.ndarray | None = None) -> ArapResult:
    """Handle-driven ARAP deformation under one of the two protocols
    (:data:`sshade.arap.options.PROTOCOLS`).

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces.
    handles : (h,) int64 constrained vertex indices. targets : (h, 3) float64 positions.
    options : :class:`sshade.arap.options.ArapOptions` or None (its defaults). ``energy``:
        ``"spokes"`` (ARAP, Sorkine & Alexa 2007), ``"spokes_and_rims"`` (Elastic, Chao et
        al. 2010) or ``"arap_sr"`` (ARAP with smooth rotations, Levi & Gotsman 2015, of
        ``alpha`` and ``alpha_scaling``: :func:`sshade.arap.sr_solver.solve_arap_sr`
        under ``"converged"``, :func:`sshade.arap.sr_paper_protocol.arap_sr_deform` with the
        move rule under ``"paper"``). ``protocol``: ``"converged"`` (default:
        :func:`sshade.arap.solver.solve_arap`'s options; ``accelerate="lbfgs"`` runs
        ARAP-SR's Anderson acceleration) or ``"paper"`` (libigl's iteration, stopped when
        the largest per-vertex move in one iteration is below ``tol * bbox_diag(V)`` or at
        ``max_iter``, None: 1000; ``criterion.gtol`` tells a converged stop from a stalled
        one). What each reads: :func:`deformer_reads`; the others must keep their defaults.
    U0 : (n, 3) float64 or None, initial guess; default the best rigid fit of the
        handles (:func:`sshade.arap.rigid.rigid_fit`; for two or collinear handles the
        fit turning the mesh least) applied to ``V``.
    R0 : (n, 3, 3) float64 or None, ``"converged"`` protocol only: start from the global
        step of these rotations (:func:`sshade.arap.solver.solve_arap`), not with ``U0``.

    Returns
    -------
    ArapResult (``info["protocol"]`` names the protocol, ``info["status"]`` how it stopped,
    ``info["gnorm"]`` the gradient norm at the result; the ``"converged"`` protocol adds
    the final energy and histories, see :func:`sshade.arap.solver.solve_arap`;
    ``"arap_sr"`` adds ``energy`` and the rotations ``R``).

    Raises
    ------
    SShaDeError on options not an ArapOptions or setting a field the energy and protocol
    do not read, ``R0`` under the ``"paper"`` protocol (inputs are assumed validated by the
    caller).

    Examples
    --------
    Example::

        res = arap_deform(V, F, np.array([0, 5]), V[[0, 5]] + 0.1, ArapOptions(protocol="paper"))
    """
    return ArapDeformer(V, F, handles, options).deform(targets, U0=U0, R0=R0)


class ArapDeformer:
    """:func:`arap_deform` prepared once for a mesh and a handle set, then run for any
    targets (an animation's frames): the ``"converged"`` protocol keeps its
    :class:`sshade.arap.solver.ArapSolver` (operators, numbering, Cholesky factor), the
    ``"paper"`` protocol its :class:`sshade.arap.paper_protocol.PaperSolver` (libigl's
    ``ARAPData``), ``"arap_sr"``
    its :class:`sshade.arap.smooth_rotations.SRProblem`. Each is made on the first call
    whose handles do not move rigidly (a rigid motion needs none).

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces. handles : (h,) int64
        constrained vertex indices (validated by the caller, as for :func:`arap_deform`).
    options : :class:`sshade.arap.options.ArapOptions` or None, as :func:`arap_deform`;
        its set-up fields (:data:`DEFORMER_SETUP`: energy, protocol, ARAP-SR's alpha, the linear
        solver, threads, numbering) hold for every deform.

    Attributes
    ----------
    options : ArapOptions (each deform's unless it gives its own). energy, protocol : str.

    Raises
    ------
    SShaDeError on options not an ArapOptions or setting a field the energy and protocol
    do not read (:func:`deformer_reads`).

    Examples
    --------
    >>> from sshade.arap.options import ArapOptions
    >>> from sshade.arap.problems import twisted_bar
    >>> V, F, h, T = twisted_bar(60.0, h=0.25)
    >>> d = ArapDeformer(V, F, h, ArapOptions(energy="spokes"))
    >>> d.deform(T).converged and d.deform(T * 1.01).converged
    True
    """

    def __init__(self, V, F, handles, options: ArapOptions | None = None):
        self.options = _checked(options, "ArapDeformer")
        self.V = np.ascontiguousarray(V, np.float64)
        self.F = np.ascontiguousarray(F, np.int64)
        self.handles = handles
        self.energy, self.protocol = self.options.energy, self.options.protocol
        self.diag = bbox_diag(self.V)
        self._solver = self._paper = self._sr = None

    @property
    def factorisation(self):
        """The converged protocol's factorised ``L_ff``
        (:attr:`sshade.arap.solver.ArapSolver.factorisation`; ``"arap_sr"``: its
        :class:`SRProblem`'s, under either protocol), None until a solve made it."""
        if self._sr is not None:
            return self._sr.solver
        return None if self._solver is None else self._solver.factorisation

    def deform(self, targets, *, options: ArapOptions | None = None, U0: np.ndarray | None = None,
               R0: np.ndarray | None = None, carry_history: bool = False) -> ArapResult:
        """The deformation for ``targets`` ((h, 3) float64); ``U0``, ``R0`` and the result
        as :func:`arap_deform`. ``options``: None (the deformer's) or another
        :class:`~sshade.arap.options.ArapOptions` with the same set-up fields
        (:data:`DEFORMER_SETUP`). ``carry_history`` (``"converged"`` protocol: start the accelerator
        with the last solve's history, as :meth:`sshade.arap.solver.ArapSolver.solve`; not
        ``"arap_sr"``'s, which starts each solve without history). Raises SShaDeError for
        ``R0`` under the ``"paper"`` protocol, bad options or another set-up."""
        protocol, V, handles = self.protocol, self.V, self.handles
        if options is None:
            o = self.options
        else:
            o = _checked(options, "ArapDeformer.deform")
            o.refuse_other_setup(self.options, DEFORMER_SETUP, "ArapDeformer.deform")
        if R0 is not None and protocol != "converged":
            raise SShaDeError("start rotations R0 are for the 'converged' protocol only")
        bc = np.ascontiguousarray(targets, np.float64)
        rigid = rigid_motion(V, handles, bc, self.diag, protocol)  # the answer, under both protocols
        if rigid is not None:
            return rigid
        if self.energy == SR_ENERGY:
            return self._smooth_rotations(bc, o, U0, R0)
        if protocol == "converged":
            if self._solver is None:
                self._solver = ArapSolver(V, self.F, handles, o)
            res = self._solver.solve(targets, options=o, U0=U0, R0=R0, carry_history=carry_history)
            res.info["protocol"] = "converged"
            return res
        if self._paper is None:
            self._paper = PaperSolver(V, self.F, handles, self.energy)
        return self._paper.deform(bc, o, U0)

    def _smooth_rotations(self, bc: np.ndarray, o: ArapOptions, U0, R0) -> ArapResult:
        """ARAP-SR for the targets ``bc`` (h, 3) under this deformer's protocol, options
        ``o`` and starts as :meth:`deform`: :func:`solve_arap_sr` (``"lbfgs"`` runs its
        Anderson acceleration) or :func:`arap_sr_deform` with the move rule. Its
        :class:`SRProblem` is made by the first call (its seconds in that result's
        ``precompute_s``) and given each later call's targets."""
        t0 = time.perf_counter()
        if self._sr is None:
            self._sr = SRProblem(self.V, self.F, self.handles, bc, o.alpha, o.linear_solver, o.alpha_scaling)
        else:
            self._sr.set_targets(bc)
        setup_s = time.perf_counter() - t0
        if self.protocol == "paper":
            res = arap_sr_deform(self.V, self.F, self.handles, bc, replace(o, stop="move"), U0=U0, problem=self._sr)
        else:
            sr = replace(o, accelerate="anderson") if o.accelerate == "lbfgs" else o
            res = solve_arap_sr(self.V, self.F, self.handles, bc, sr, U0=U0, R0=R0, problem=self._sr)
        res.precompute_s += setup_s
        res.info["protocol"] = self.protocol
        return res


def _checked(options, who: str) -> ArapOptions:
    """``options`` (None: the defaults) for :func:`arap_deform`: an :class:`ArapOptions`
    setting no field its energy and protocol do not read. Raises SShaDeError naming ``who``."""
    options = ArapOptions.of(options, who)
    options.refuse_unused(deformer_reads(options.energy, options.protocol),
                          f"{who} ({options.protocol} protocol, energy {options.energy!r})")
    return options

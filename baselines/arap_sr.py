"""ARAP-SR: as-rigid-as-possible with smooth rotations (Levi & Gotsman 2015, "Smooth
rotation enhanced as-rigid-as-possible mesh animation", IEEE TVCG), at full resolution
behind the :class:`sshade.method_interface.Deformer` interface (:class:`ARAPSR`).

Its energy is :mod:`sshade.arap.smooth_rotations` (which states both definitions of
alpha); each protocol runs in a module of its own, named by :data:`PROTOCOL_MODULES`:
``"converged"`` (:mod:`baselines.arap_sr_converged`, :func:`sshade.arap.solve_arap_sr`)
and ``"paper"`` (:mod:`baselines.arap_sr_paper`, :func:`sshade.arap.arap_sr_deform`:
Open3D's plain Smoothed-ARAP iteration, run "until convergence with a cutoff of 1000
iterations", paper §4.1), so a row's code identity holds its own protocol's code only. Why
it is written on libigl and checked against Open3D: docs/implementation.md,
"Implementation notes: baselines/arap_sr.py".
"""
from __future__ import annotations

import importlib

import numpy as np

from sshade.arap import (
    ALPHA_SCALINGS,
    DEFAULT_ALPHA,
    DEFAULT_MAX_ITER,
    PAPER_STOPS,
    PROTOCOLS,
    make_criterion,
)
from sshade.errors import SShaDeError
from sshade.mesh.unit_frame import unit_frame
from sshade.mesh.validate import validate_handles, validate_mesh

from .coarse_start import COARSE_N_LOW
from .fullres_arap import check_arap_args
from .starts import check_start

__all__ = ["ARAPSR", "PROTOCOL_MODULES"]

#: the module that runs each protocol (:data:`sshade.arap.PROTOCOLS`): ``solve(method, V,
#: F, handles, targets) -> ArapResult`` and ``warmup(method, n_vertices) -> seconds``.
#: Read as a literal by the code identity (eval.run.code_identity.identity_roots)
PROTOCOL_MODULES = {"converged": "baselines.arap_sr_converged", "paper": "baselines.arap_sr_paper"}


class ARAPSR:
    """ARAP-SR baseline behind the :class:`sshade.method_interface.Deformer` interface.

    Parameters
    ----------
    alpha : float >= 0, rotation smoothness (times the surface area).
    alpha_scaling : ``"valence"`` (default: alpha as Open3D's Smoothed ARAP defines it, the
        neighbour term divided by the valence) or ``"none"`` (without the valence: about 6x
        stiffer at the same alpha); :mod:`sshade.arap.smooth_rotations`.
    protocol : ``"converged"`` (default, ``info["protocol"] = "converged-sr"``:
        :func:`sshade.arap.solve_arap_sr`, Gauss-Seidel local step and
        Anderson acceleration, stopped by the energy-and-gradient criterion ``etol`` /
        ``gtol``) or ``"paper"`` (:func:`sshade.arap.arap_sr_deform`: Open3D's plain iteration run
        until the stop rule ``stop`` fires, at most 1000 iterations, then the stop
        classified converged or stalled by the gradient; ``info["protocol"] =
        "paper-sr"``, or ``"move-rule"`` with ``stop="move"``).
    stop : ``"paper"`` protocol's stop rule (:data:`sshade.arap.PAPER_STOPS`):
        ``"energy"`` (default, relative energy change below ``etol``) or ``"move"``
        (largest vertex move below ``tol`` x diagonal).
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

    def __init__(self, *, alpha: float = DEFAULT_ALPHA, tol: float = 1e-4, max_iter: int | None = None,
                 protocol: str = "converged", etol: float | None = None, gtol: float | None = None,
                 start: str = "auto", coarse_n_low: int = COARSE_N_LOW, alpha_scaling: str = "valence",
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
        self.max_iter = DEFAULT_MAX_ITER[protocol] if args["max_iter"] is None else args["max_iter"]
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
        res = self._protocol.solve(self, U, F, handles, T)
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

    @property
    def _protocol(self):
        """The module that runs :attr:`protocol` (:data:`PROTOCOL_MODULES`), imported on first use."""
        return importlib.import_module(PROTOCOL_MODULES[self.protocol])

    def warmup(self, n_vertices: int | None = None) -> float:
        """First-call costs (libigl, the linear solver, the polar and energy kernels, mesh
        validation, the remesh of a coarse start) paid once on a tiny mesh outside any timed
        call, and the parallel kernels when an ``n_vertices`` mesh runs them: the ``warmup``
        of this protocol's module (:data:`PROTOCOL_MODULES`). Returns the seconds spent."""
        return self._protocol.warmup(self, n_vertices)


def warmup_kernels() -> float:
    """Warm ARAP-SR under both protocols (:meth:`ARAPSR.warmup` with the defaults and with
    ``protocol="paper"``): the entry point ``sshade.warmup`` of ``python -m sshade warmup``.
    Returns the seconds spent."""
    return ARAPSR().warmup() + ARAPSR(protocol="paper").warmup()

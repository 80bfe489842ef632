"""Full-resolution ARAP baselines (paper §4.1): ARAP (spokes) and Elastic (spokes and rims).

The front every protocol shares (parameters, validation, the unit frame, the info
columns); each protocol runs in a module of its own, named by :data:`PROTOCOL_MODULES` and
imported when a baseline is built under it: :mod:`baselines.fullres_converged` (the
converged solver, its coarse start) and :mod:`baselines.fullres_paper` (libigl's
iteration). A row's code identity holds this module and the one its protocol names
(eval.run.code_identity), so a change to the converged solver leaves the paper
protocol's rows current.
"""
from __future__ import annotations

import importlib
import math

import numpy as np

from sshade.arap import DEFAULT_MAX_ITER, PROTOCOLS, ArapOptions, make_criterion
from sshade.errors import SShaDeError
from sshade.mesh.unit_frame import unit_frame
from sshade.mesh.validate import validate_handles, validate_mesh

from .coarse_start import COARSE_N_LOW
from .starts import check_start

__all__ = ["FullResArap", "ARAP", "Elastic", "check_arap_args", "PROTOCOL_MODULES"]

#: the module that runs each protocol (:data:`sshade.arap.PROTOCOLS`): ``solve(method, V,
#: F, handles, targets) -> (ArapResult, start info)`` and ``warmup(method, n_vertices) ->
#: seconds``. Read as a literal by the code identity (eval.run.code_identity.identity_roots)
PROTOCOL_MODULES = {"converged": "baselines.fullres_converged", "paper": "baselines.fullres_paper"}


def check_arap_args(name: str, tol, max_iter, etol=None, gtol=None, alpha=None) -> dict:
    """A full-resolution baseline's parameters, checked when it is built (so the command
    line and the evaluator refuse a bad value before any work): ``tol`` a finite number
    > 0 (fraction of the bounding-box diagonal), ``max_iter`` an int >= 1 or None,
    ``etol`` / ``gtol`` / ``alpha`` finite numbers >= 0 or None.

    Returns
    -------
    dict of the same keys, as float / int / None.

    Raises
    ------
    SShaDeError naming ``name``, the parameter and its value.
    """
    def number(key, v, positive):
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise SShaDeError(f"{name}: {key} must be a number, got {v!r}") from None
        if isinstance(v, bool) or not math.isfinite(f) or (f <= 0 if positive else f < 0):
            raise SShaDeError(f"{name}: {key} must be a finite number {'>' if positive else '>='} 0, got {v!r}")
        return f
    out = {"tol": number("tol", tol, True), "max_iter": None}
    if max_iter is not None:
        try:
            out["max_iter"] = int(max_iter)
        except (TypeError, ValueError, OverflowError):
            raise SShaDeError(f"{name}: max_iter must be an integer >= 1 or null, got {max_iter!r}") from None
        if isinstance(max_iter, bool) or out["max_iter"] != max_iter or out["max_iter"] < 1:
            raise SShaDeError(f"{name}: max_iter must be an integer >= 1 or null, got {max_iter!r}")
    for key, v in (("etol", etol), ("gtol", gtol), ("alpha", alpha)):
        out[key] = None if v is None else number(key, v, False)
    return out


class FullResArap:
    """ARAP on the full-resolution mesh, under one of the protocols of
    :func:`sshade.arap.arap_deform`.

    Parameters
    ----------
    energy : ``"spokes"`` or ``"spokes_and_rims"``.
    tol : float, ``"paper"`` protocol: move tolerance (fraction of the bounding-box
        diagonal).
    max_iter : int or None, iteration cap (None: the protocol's default; paper: 1000).
    name : str, the table row label.
    protocol : ``"converged"`` (default: L-BFGS-accelerated local/global to the
        energy-and-gradient criterion) or ``"paper"`` (libigl, paper §4.1 move rule).
    etol, gtol : floats or None, the ``"converged"`` criterion
        (:class:`sshade.arap.criterion.Criterion`; None: its defaults).
    start : ``"converged"`` protocol's start: ``"rigid"`` (default: the rigid fit of the
        handles), ``"coarse"`` (:func:`baselines.coarse_start.coarse_start`: the global
        step of the rotations of the same energy solved on a ``coarse_n_low``-vertex
        remesh), ``"auto"`` (coarse when the mesh has at least ``COARSE_MIN_RATIO *
        coarse_n_low`` vertices, falling back to rigid if the coarse start raises
        SShaDeError). Either start is stopped by the same full-resolution criterion; why
        rigid is the default here: docs/implementation.md, "Implementation notes:
        baselines/coarse_start.py".
    coarse_n_low : int >= 4, the remesh's sample count for the coarse start.

    Raises
    ------
    SShaDeError on a bad parameter value.

    Examples
    --------
    Example::

        m = Elastic()
        Vd = m.deform(V, F, handles, targets)
        m.info["iterations"]
    """

    def __init__(self, energy: str, *, tol: float = 1e-4, max_iter: int | None = None, name: str | None = None,
                 protocol: str = "converged", etol: float | None = None, gtol: float | None = None,
                 start: str = "rigid", coarse_n_low: int = COARSE_N_LOW):
        if protocol not in PROTOCOLS:
            raise SShaDeError(f"{name or energy}: unknown protocol {protocol!r}; use one of {PROTOCOLS}")
        self.start, self.coarse_n_low = check_start(name or energy, start, coarse_n_low)
        args = check_arap_args(name or energy, tol, max_iter, etol, gtol)
        self.energy = energy
        self.tol = args["tol"]
        self.max_iter = args["max_iter"]
        self.name = name or energy
        self.protocol = protocol
        self.criterion = make_criterion(etol, gtol)
        self.info: dict = {}

    @property
    def _protocol(self):
        """The module that runs :attr:`protocol` (:data:`PROTOCOL_MODULES`), imported on first use."""
        return importlib.import_module(PROTOCOL_MODULES[self.protocol])

    def effective_params(self) -> dict:
        """The parameters :meth:`deform` runs with, every default resolved: ``energy``,
        ``protocol``, ``tol`` (the paper protocol's move rule), ``max_iter`` (None: the
        protocol's cap, :data:`sshade.arap.DEFAULT_MAX_ITER`), ``etol`` / ``gtol`` (the
        converged criterion), ``start``, ``coarse_n_low``."""
        return {"energy": self.energy, "protocol": self.protocol, "tol": self.tol,
                "max_iter": DEFAULT_MAX_ITER[self.protocol] if self.max_iter is None else self.max_iter,
                "etol": self.criterion.etol, "gtol": self.criterion.gtol, "start": self.start,
                "coarse_n_low": self.coarse_n_low}

    def arap_options(self) -> ArapOptions:
        """The options of :func:`sshade.arap.arap_deform` :meth:`deform` runs with:
        ``energy``, ``protocol``, ``max_iter``, the criterion and, under the paper
        protocol, the move rule's ``tol``."""
        paper = {"tol": self.tol} if self.protocol == "paper" else {}
        return ArapOptions(energy=self.energy, protocol=self.protocol, max_iter=self.max_iter,
                           criterion=self.criterion, **paper)

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` so ``V[handles]`` reach ``targets``; returns (n, 3) float64.
        Solved in the mesh's unit frame (:mod:`sshade.mesh.unit_frame`) and mapped back,
        so a moved or scaled input gives the moved or scaled result; ``info["energy"]``
        in mesh units.

        Raises ``SShaDeError`` on invalid mesh or handles.
        """
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        frame = unit_frame(V)  # solved centred and scaled (sshade.mesh.unit_frame), mapped back
        V, T = frame.to_unit(V), frame.to_unit(targets)
        res, cinfo = self._protocol.solve(self, V, F, handles, T)
        self.info = {"iterations": res.iterations, "converged": res.converged, "protocol": self.protocol,
                     "handles": "hard",
                     "status": res.info.get("status"), "precompute_s": res.precompute_s, "solve_s": res.solve_s,
                     "s_per_iter": res.solve_s / max(res.iterations, 1)}
        for k in ("energy", "gnorm", "rel_decrease", "n_fallback", "linear_solver"):
            if k in res.info:
                self.info[k] = res.info[k]
        self.info.update({k: cinfo[k] for k in ("coarse_n", "coarse_iterations", "coarse_s") if k in cinfo})
        if "energy" in self.info:
            self.info["energy"] = frame.energy(self.info["energy"])
        Vd = frame.from_unit(res.V, out=res.V)
        Vd[handles] = targets  # hard constraints: exactly the targets given
        return Vd

    def warmup(self, n_vertices: int | None = None) -> float:
        """Compile (or load from numba's cache) the kernels :meth:`deform` runs for this
        energy and protocol (parallel variants too when an ``n_vertices`` mesh uses them),
        outside any timed call (:func:`sshade.warmup.warm_fullres`), and the remesh and
        low-res solve of a coarse start when one runs (``n_vertices`` None: whenever
        ``start`` is not ``"rigid"``). Returns the seconds spent (0.0 when warm)."""
        return self._protocol.warmup(self, n_vertices)


class ARAP(FullResArap):
    """ARAP, spokes energy (Sorkine & Alexa 2007), full resolution."""

    def __init__(self, *, tol: float = 1e-4, max_iter: int | None = None, protocol: str = "converged",
                 etol: float | None = None, gtol: float | None = None, start: str = "rigid",
                 coarse_n_low: int = COARSE_N_LOW):
        super().__init__("spokes", tol=tol, max_iter=max_iter, name="ARAP", protocol=protocol, etol=etol, gtol=gtol,
                         start=start, coarse_n_low=coarse_n_low)


class Elastic(FullResArap):
    """Elastic = spokes-and-rims ARAP (Chao et al. 2010), full resolution."""

    name = "Elastic"

    def __init__(self, *, tol: float = 1e-4, max_iter: int | None = None, protocol: str = "converged",
                 etol: float | None = None, gtol: float | None = None, start: str = "rigid",
                 coarse_n_low: int = COARSE_N_LOW):
        super().__init__("spokes_and_rims", tol=tol, max_iter=max_iter, name=Elastic.name, protocol=protocol,
                         etol=etol, gtol=gtol, start=start, coarse_n_low=coarse_n_low)

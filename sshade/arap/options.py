"""The options of the ARAP solvers in one checked, frozen record (:class:`ArapOptions`), as
libigl's ``ARAPData`` holds ``arap_solve``'s.

The four public solvers take one: :func:`sshade.arap.solver.solve_arap` (and
:class:`~sshade.arap.solver.ArapSolver`), :func:`sshade.arap.sr_solver.solve_arap_sr`,
:func:`sshade.arap.sr_paper_protocol.arap_sr_deform` and
:func:`sshade.arap.local_global.arap_deform` (and
:class:`~sshade.arap.local_global.ArapDeformer`). The record is checked once, when it is
made; each solver reads some of its fields (:data:`READS`) and refuses one it does not
read that is set to another value than its default (:meth:`ArapOptions.refuse_unused`).
Also here: the names the fields take (:data:`PROTOCOLS`, :data:`DEFORM_ENERGIES`, ...).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

import numpy as np

from ..errors import SShaDeError
from .criterion import DEFAULT_CRITERION, Criterion
from .linear import LINEAR_SOLVERS
from .operators import ENERGIES

__all__ = ["ArapOptions", "READS", "PROTOCOLS", "DEFAULT_MAX_ITER", "DEFAULT_ALPHA", "SR_ENERGY",
           "DEFORM_ENERGIES", "ACCELERATIONS", "ALPHA_SCALINGS", "PAPER_STOPS"]

#: the two protocols (docs/protocols.md): run to the energy-and-gradient criterion, or the
#: paper's (§4.1) move rule with its cap
PROTOCOLS = ("converged", "paper")
#: iteration cap of each protocol when ``max_iter`` is None (paper §4.1: 1000)
DEFAULT_MAX_ITER = {"converged": 10000, "paper": 1000}
#: the name of ARAP-SR's energy beside :data:`sshade.arap.ENERGIES` (its ``alpha`` given apart)
SR_ENERGY = "arap_sr"
#: the energies :func:`sshade.arap.arap_deform` solves: :data:`sshade.arap.ENERGIES` and ARAP-SR's
DEFORM_ENERGIES = (*ENERGIES, SR_ENERGY)
#: ``alpha`` when none is given: Open3D's Smoothed ARAP default (with ``alpha_scaling="valence"``)
DEFAULT_ALPHA = 0.01
#: the iterations a solver may run (``accelerate``); ``"auto"``: L-BFGS for the ARAP
#: energies, Anderson for ARAP-SR (which has no L-BFGS)
ACCELERATIONS = ("auto", "lbfgs", "anderson", "none")
#: definitions of ARAP-SR's alpha (:mod:`sshade.arap.smooth_rotations`): the first is the default
ALPHA_SCALINGS = ("valence", "none")
#: stopping rules of ARAP-SR's paper protocol (:func:`sshade.arap.arap_sr_deform`); the first
#: is the default
PAPER_STOPS = ("energy", "move")

_RUN = ("criterion", "max_iter", "time_budget_s")
#: the fields each solver reads (``"arap_deform (paper)"``: libigl's iteration, for the ARAP
#: energies); :func:`sshade.arap.arap_deform` reads ``energy``, ``protocol`` and those of the
#: solver it runs (:func:`sshade.arap.local_global.deformer_reads`)
READS = {
    "solve_arap": frozenset({"energy", *_RUN, "accelerate", "history", "linear_solver", "threads", "reorder"}),
    "solve_arap_sr": frozenset({"energy", *_RUN, "accelerate", "history", "linear_solver", "alpha",
                                "alpha_scaling", "jacobi", "reset_on_reject"}),
    "arap_sr_deform": frozenset({"energy", "protocol", *_RUN, "tol", "stop", "linear_solver", "alpha",
                                 "alpha_scaling"}),
    "arap_deform (paper)": frozenset({*_RUN, "tol"}),
}


@dataclass(frozen=True)
class ArapOptions:
    """How an ARAP solver runs, checked when made (SShaDeError naming the field and value).

    Fields (readers in brackets: ``solve_arap`` also means :class:`ArapSolver`,
    ``arap_deform`` also :class:`ArapDeformer`, which reads the fields of the solver its
    energy and protocol run, :data:`READS`):

    energy : str, default ``"spokes_and_rims"``. One of :data:`sshade.arap.ENERGIES`
        (``"spokes"``, Sorkine & Alexa 2007; ``"spokes_and_rims"``, Chao et al. 2010) or
        ``"arap_sr"`` (smooth rotations, Levi & Gotsman 2015: arap_deform only; the ARAP-SR
        solvers accept it or the default). [all]
    protocol : str, default ``"converged"``, one of :data:`PROTOCOLS`. [arap_deform;
        arap_sr_deform, which is the paper protocol, accepts it]
    criterion : :class:`sshade.arap.criterion.Criterion`, default
        :data:`sshade.arap.criterion.DEFAULT_CRITERION` (None is taken as it): the
        converged protocol's stop; under the paper protocol ``gtol`` tells a converged stop
        from a stalled one and ARAP-SR's energy stop uses ``etol``. [all]
    max_iter : int >= 0 or None, default None: cap on iterations (global solves); None is
        :data:`DEFAULT_MAX_ITER` of the protocol (:meth:`iteration_cap`): solve_arap and
        solve_arap_sr are the converged protocol (10000), arap_sr_deform the paper one (1000).
        [all]
    accelerate : str, default ``"auto"``, one of :data:`ACCELERATIONS` (``True``: Anderson,
        ``False``: none): ``"auto"`` is L-BFGS for the ARAP energies, Anderson for ARAP-SR;
        ``"lbfgs"`` for ARAP-SR runs Anderson in arap_deform and is refused by
        solve_arap_sr. [solve_arap, solve_arap_sr]
    history : int >= 1 or None, default None: the accelerator's window, L-BFGS's memory
        (None: 10) or Anderson's (None: 5). [solve_arap, solve_arap_sr]
    time_budget_s : float >= 0 or None, default None: stop (unconverged, status
        ``"time_budget"``) once the iterations took this many seconds. [all]
    tol : float > 0, default 1e-4: the paper protocol's move rule, a fraction of the
        bounding-box diagonal. [arap_deform under "paper", arap_sr_deform]
    stop : str, default ``"energy"``, one of :data:`PAPER_STOPS`: arap_sr_deform's rule
        (arap_deform's paper ARAP-SR always takes ``"move"``). [arap_sr_deform]
    linear_solver : str, default ``"auto"``, one of :data:`sshade.arap.LINEAR_SOLVERS`.
        [solve_arap, solve_arap_sr, arap_sr_deform]
    threads : int >= 1 or None, default None: the numba kernels' threads (None: automatic,
        :class:`sshade.arap.threads.ThreadPicker`; the iterates do not depend on it). [solve_arap]
    reorder : bool or None, default None: iterate in a cache-friendly numbering (None: from
        :data:`sshade.arap.kernel_data.REORDER_MIN_VERTICES` vertices). [solve_arap]
    alpha : float >= 0, default :data:`DEFAULT_ALPHA`: ARAP-SR's smoothness weight (times
        the surface area). [ARAP-SR]
    alpha_scaling : str, default ``"valence"``, one of :data:`ALPHA_SCALINGS`. [ARAP-SR]
    jacobi : bool, default False: Jacobi local step (measurements only). [solve_arap_sr]
    reset_on_reject : bool, default False: forget Anderson's history after a rejected
        candidate. [solve_arap_sr]

    Raises
    ------
    SShaDeError on a field of the wrong type or out of range.

    Examples
    --------
    >>> o = ArapOptions(energy="spokes", accelerate="anderson")
    >>> o.iteration_cap(), o.acceleration(), o.window(o.acceleration())
    (10000, 'anderson', 5)
    """

    energy: str = "spokes_and_rims"
    protocol: str = "converged"
    criterion: Criterion = DEFAULT_CRITERION
    max_iter: int | None = None
    accelerate: str = "auto"
    history: int | None = None
    time_budget_s: float | None = None
    tol: float = 1e-4
    stop: str = "energy"
    linear_solver: str = "auto"
    threads: int | None = None
    reorder: bool | None = None
    alpha: float = DEFAULT_ALPHA
    alpha_scaling: str = "valence"
    jacobi: bool = False
    reset_on_reject: bool = False

    def __post_init__(self):
        for name, value in _checked(self).items():
            object.__setattr__(self, name, value)

    @classmethod
    def of(cls, options, who: str) -> ArapOptions:
        """``options`` itself, or the defaults for None. Raises SShaDeError naming ``who``
        for anything but an :class:`ArapOptions`."""
        if options is None:
            return cls()
        if not isinstance(options, cls):
            raise SShaDeError(f"{who}: options must be an ArapOptions, got {type(options).__name__}")
        return options

    def iteration_cap(self, protocol: str | None = None) -> int:
        """``max_iter``, or :data:`DEFAULT_MAX_ITER` of ``protocol`` (None: this record's)."""
        if self.max_iter is not None:
            return self.max_iter
        return DEFAULT_MAX_ITER[self.protocol if protocol is None else protocol]

    def acceleration(self, energy: str | None = None) -> str:
        """``accelerate`` for ``energy`` (None: this record's), ``"auto"`` resolved:
        ``"anderson"`` for :data:`SR_ENERGY`, else ``"lbfgs"``."""
        if self.accelerate != "auto":
            return self.accelerate
        return "anderson" if (self.energy if energy is None else energy) == SR_ENERGY else "lbfgs"

    def window(self, accelerate: str) -> int:
        """``history``, or the window of ``accelerate`` when None: 10 for ``"lbfgs"``, else 5."""
        if self.history is not None:
            return self.history
        return 10 if accelerate == "lbfgs" else 5

    def refuse_unused(self, used: frozenset[str], who: str) -> None:
        """Raise SShaDeError naming the field and ``who`` for a field not in ``used`` (the
        fields ``who`` reads, :data:`READS`) whose value is not its default."""
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name not in used and value != f.default:
                readers = ", ".join(k for k, v in READS.items() if f.name in v) or "arap_deform"
                raise SShaDeError(f"{who} does not read the option {f.name} (given {value!r}, default "
                                  f"{f.default!r}); it is read by {readers}")

    def refuse_other_setup(self, made_with: ArapOptions, names: tuple[str, ...], who: str) -> None:
        """Raise SShaDeError naming the field when one of ``names`` (the set-up's fields)
        differs from ``made_with``'s, the options ``who`` was set up with."""
        for name in names:
            mine, theirs = getattr(self, name), getattr(made_with, name)
            if mine != theirs:
                raise SShaDeError(f"{who}: {name}={mine!r}, but it was set up with {theirs!r} (a set-up "
                                  "option: make another one)")


def _checked(o: ArapOptions) -> dict:
    """The fields of ``o`` that are normalised (``criterion`` None, ``accelerate``
    True/False, numbers as int/float), all of them checked. Raises SShaDeError."""
    out = {"criterion": DEFAULT_CRITERION if o.criterion is None else o.criterion}
    for name, names in (("energy", DEFORM_ENERGIES), ("protocol", PROTOCOLS), ("stop", PAPER_STOPS),
                        ("linear_solver", LINEAR_SOLVERS), ("alpha_scaling", ALPHA_SCALINGS)):
        _one_of(name, getattr(o, name), names)
    if not isinstance(out["criterion"], Criterion):
        raise SShaDeError(f"criterion must be a Criterion, got {type(o.criterion).__name__}")
    acc = o.accelerate
    if isinstance(acc, (bool, np.bool_)):
        acc = "anderson" if acc else "none"
    if not isinstance(acc, str) or acc not in ACCELERATIONS:
        raise SShaDeError(f"accelerate must be one of {ACCELERATIONS} (or True/False), got {o.accelerate!r}")
    out["accelerate"] = acc
    for name, lo in (("max_iter", 0), ("history", 1), ("threads", 1)):
        out[name] = _integer(name, getattr(o, name), lo)
    out["time_budget_s"] = None if o.time_budget_s is None else _number("time_budget_s", o.time_budget_s, 0.0)
    out["tol"] = _number("tol", o.tol, 0.0, positive=True, finite=True)
    if not (isinstance(o.alpha, numbers.Real) and not isinstance(o.alpha, (bool, np.bool_))
            and math.isfinite(o.alpha) and o.alpha >= 0):
        raise SShaDeError(f"ARAP-SR: alpha must be a finite number >= 0, got {o.alpha!r}")
    out["alpha"] = float(o.alpha)
    for name in ("reorder", "jacobi", "reset_on_reject"):
        v = getattr(o, name)
        if not (isinstance(v, (bool, np.bool_)) or (v is None and name == "reorder")):
            raise SShaDeError(f"{name} must be True or False{' or None' if name == 'reorder' else ''}, got {v!r}")
        out[name] = None if v is None else bool(v)
    return out


def _one_of(name: str, value, names: tuple) -> None:
    """Raise SShaDeError unless ``value`` is one of the strings ``names``."""
    if not isinstance(value, str) or value not in names:
        label = {"energy": "unknown ARAP energy", "protocol": "unknown ARAP protocol",
                 "linear_solver": "unknown linear solver"}.get(name)
        if label:
            raise SShaDeError(f"{label} {value!r}; use one of {names}")
        raise SShaDeError(f"{'ARAP-SR: ' if name in ('stop', 'alpha_scaling') else ''}{name} must be one of "
                          f"{names}, got {value!r}")


def _integer(name: str, v, lo: int) -> int | None:
    """``v`` (None, or an integer, not a bool) as an int >= ``lo``; SShaDeError otherwise."""
    if v is None:
        return None
    if not isinstance(v, numbers.Integral) or isinstance(v, (bool, np.bool_)) or v < lo:
        raise SShaDeError(f"{name} must be an integer >= {lo} or None, got {v!r}")
    return int(v)


def _number(name: str, v, lo: float, *, positive: bool = False, finite: bool = False) -> float:
    """``v`` (a real number, not a bool or NaN) as a float ``>= lo`` (``> lo`` when
    ``positive``; finite when ``finite``); SShaDeError otherwise."""
    ok = isinstance(v, numbers.Real) and not isinstance(v, (bool, np.bool_)) and not math.isnan(v) \
        and (v > lo if positive else v >= lo) and (math.isfinite(v) or not finite)
    if not ok:
        raise SShaDeError(f"{name} must be a {'finite ' if finite else ''}number {'>' if positive else '>='} "
                          f"{lo:g}{'' if finite else ' or None'}, got {v!r}")
    return float(v)

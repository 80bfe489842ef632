"""What a method's result is scored against and how far it lies from it: the energy a
method is compared with (:func:`method_energy`; ARAP-SR's named by :func:`sr_energy`), its
operators, and the distance of a result to a reference solution (:func:`reference_metrics`),
part of every row with reference columns; the reference itself is an artifact of
:mod:`eval.metrics.reference`. Floor 1 of eval/ (tests/test_layering.py); notes: docs/implementation.md.

- ``ref_mean_pct`` / ``ref_max_pct``: mean / max vertex distance to the reference, in % of
  the rest mesh's bounding-box diagonal;
- ``energy_gap``: ``(E(U) - E(U*)) / |E(U*)|``, ``E`` the reference's energy (libigl's weights,
  :mod:`sshade.arap.operators`), ``>= 0`` up to the reference's tolerance; ``|E(U*)|`` as the
  spokes energy can be negative at its minimum (negative cotangent weights, e.g. FAUST's)."""
from __future__ import annotations

import numpy as np

from harness.method_registry import method_meta
from sshade.arap import (
    ALPHA_SCALINGS,
    DEFAULT_ALPHA,
    ENERGIES,
    SRProblem,
    build_operators,
)
from sshade.errors import SShaDeError

__all__ = ["SR_GAP_SWEEPS", "sr_energy", "sr_params", "sr_alpha", "method_energy", "energy_operators",
           "reference_metrics"]


#: Gauss-Seidel sweeps of the rotations at a method's ARAP-SR result, from its own
#: rotations, before its energy gap is read (:func:`reference_metrics`).
SR_GAP_SWEEPS = 20


#: prefix of the ARAP-SR energies (:func:`sr_energy`)
_SR = "arap_sr_"


def sr_energy(alpha: float, alpha_scaling: str = "valence") -> str:
    """The name of ARAP-SR's energy with smoothness weight ``alpha`` under the definition
    ``alpha_scaling`` (Levi & Gotsman 2015; :mod:`sshade.arap.smooth_rotations`), e.g.
    ``"arap_sr_valence_0.01"``: both are part of the name, hence of the cache key and file
    name. Raises SShaDeError on an unknown ``alpha_scaling``."""
    if alpha_scaling not in ALPHA_SCALINGS:
        raise SShaDeError(f"ARAP-SR: alpha_scaling must be one of {ALPHA_SCALINGS}, got {alpha_scaling!r}")
    return f"{_SR}{alpha_scaling}_{float(alpha)!r}"


def sr_params(energy: str) -> tuple[float, str] | None:
    """``(alpha, alpha_scaling)`` of an ARAP-SR energy name (:func:`sr_energy`), None for
    another energy. Raises SShaDeError on a malformed ARAP-SR name."""
    if not str(energy).startswith(_SR):
        return None
    scaling, _, a = str(energy)[len(_SR):].rpartition("_")
    try:
        a = float(a)
    except ValueError:
        raise SShaDeError(f"bad ARAP-SR energy name {energy!r}") from None
    if not (np.isfinite(a) and a >= 0) or scaling not in ALPHA_SCALINGS:
        raise SShaDeError(f"bad ARAP-SR energy name {energy!r}")
    return a, scaling


def sr_alpha(energy: str) -> float | None:
    """``alpha`` of an ARAP-SR energy name (:func:`sr_energy`), None for another energy.
    Raises SShaDeError on a malformed ARAP-SR name."""
    p = sr_params(energy)
    return None if p is None else p[0]


def _check_energy(energy: str) -> None:
    if energy not in ENERGIES and sr_alpha(energy) is None:
        raise SShaDeError(f"unknown ARAP energy {energy!r}; use one of {ENERGIES} or sr_energy(alpha)")


def method_energy(method) -> str:
    """The energy a method's result is scored against: its own ``energy`` attribute when
    it names one of :data:`sshade.arap.ENERGIES`, else its file's ``reference``
    (:func:`harness.method_registry.method_meta`): an energy of :data:`sshade.arap.ENERGIES`, or
    ``arap_sr``, the method's own ARAP-SR energy with its ``alpha`` and ``alpha_scaling``
    (:func:`sr_energy`; default 0.01, ``"valence"``); a plug-in's, spokes-and-rims (the
    energy of SShaDe's low-resolution step, paper §4.1).

    Raises
    ------
    SShaDeError on a ``reference`` that names no energy."""
    e = getattr(method, "energy", None)
    if e in ENERGIES:
        return str(e)
    ref = method_meta(str(getattr(method, "name", method)))["reference"]
    if ref == "arap_sr":
        return sr_energy(getattr(method, "alpha", DEFAULT_ALPHA), getattr(method, "alpha_scaling", "valence"))
    if ref not in ENERGIES:
        raise SShaDeError(f"method {getattr(method, 'name', method)}: reference must be one of "
                          f"{[*ENERGIES, 'arap_sr']}, got {ref!r}")
    return str(ref)


def energy_operators(V, F, energy: str):
    """What :func:`reference_metrics` evaluates ``energy`` with: the
    :class:`sshade.arap.ArapOperators` of ``(V, F)`` for an ARAP energy, an energy-only
    :class:`sshade.arap.SRProblem` for an ARAP-SR one. Raises SShaDeError on
    an unknown energy."""
    _check_energy(energy)
    p = sr_params(energy)
    return build_operators(V, F, energy) if p is None else SRProblem(V, F, None, None, p[0], alpha_scaling=p[1])


def reference_metrics(V_rest, Vd, F, ref: Reference, operators=None, R0=None) -> dict:  # noqa: F821 (a
    # Reference of eval.metrics.reference, which imports this module: the annotation is never evaluated)
    """Distance of a deformed mesh to a reference solution.

    Parameters
    ----------
    V_rest : (n, 3) float64 rest positions (for the bounding-box diagonal and the energy).
    Vd : (n, 3) float64 the method's result. F : (m, 3) int64 faces.
    ref : :class:`Reference` of the same case.
    operators : :func:`energy_operators` of ``(V_rest, F, ref.energy_type)`` or None
        (built here). For ARAP-SR ``E(Vd) = min_R E(Vd, R)`` by Gauss-Seidel sweeps
        (:meth:`sshade.arap.SRProblem.reduced_energy`) from ARAP's optimal
        rotations (at most 2,000 sweeps: at 169k vertices they stop short of the
        minimum and overstate the gap, by ~0.3% on DeFAUST s00_p01), or, with ``R0``,
        ``E(Vd, R)`` after at most :data:`SR_GAP_SWEEPS` sweeps from ``R0`` (an upper
        bound of ``min_R E(Vd, R)``, since no sweep raises the energy).
    R0 : (n, 3, 3) float64 or None, the method's own ARAP-SR rotations
        (:attr:`baselines.arap_sr.ARAPSR.rotations`).

    Returns
    -------
    dict ``ref_mean_pct``, ``ref_max_pct`` (% of the diagonal), ``energy_gap``
    (``(E(Vd) - E(U*)) / |E(U*)|``; NaN when the reference energy is 0), ``ref_energy``.

    Raises
    ------
    SShaDeError when ``Vd`` and the reference have different shapes.
    """
    V_rest = np.asarray(V_rest, np.float64)
    Vd = np.asarray(Vd, np.float64)
    if Vd.shape != ref.U.shape:
        raise SShaDeError(f"result has shape {Vd.shape}, the reference {ref.U.shape}")
    diag = float(np.linalg.norm(V_rest.max(0) - V_rest.min(0)))
    d = np.linalg.norm(Vd - ref.U, axis=1) / diag * 100.0
    ops = operators if operators is not None else energy_operators(V_rest, F, ref.energy_type)
    if R0 is not None and np.shape(R0) != (len(Vd), 3, 3):
        R0 = None  # not this mesh's rotations
    if sr_alpha(ref.energy_type) is None:
        E = float(ops.energy(Vd))
    else:
        E = float(ops.reduced_energy(Vd, R0, max_sweeps=SR_GAP_SWEEPS if R0 is not None else 2000)[0])
    gap = (E - ref.energy) / abs(ref.energy) if ref.energy != 0 else float("nan")
    return {"ref_mean_pct": float(d.mean()), "ref_max_pct": float(d.max()), "energy_gap": float(gap),
            "ref_energy": float(ref.energy)}


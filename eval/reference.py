"""Reference solutions: the deep-converged full-resolution ARAP minimiser of a case,
computed once, cached on disk, and the distance of any method's result to it.

A benchmark row is only as good as its reference. For every case (rest mesh, handles,
targets) and ARAP energy (``"spokes"``: ARAP, Sorkine & Alexa 2007; ``"spokes_and_rims"``:
Elastic, Chao et al. 2010), :func:`reference_solution` runs
:func:`sshade.arap.solve_arap` (L-BFGS-accelerated local/global, Armijo line
search) with :data:`sshade.arap.DEEP_CRITERION` (until the energy stops
changing in float64; on the FAUST cases L-BFGS reaches the same energy as the
Anderson-accelerated iteration to 12 digits, or a lower one: s0_p1 spokes -0.0822362
against -0.0822274, and on DeFAUST s00_p01 spokes -0.0273515 where a 4,836-iteration
Anderson run had stopped at -0.027234) and stores the result in ``cache_dir`` under a key hashing the
mesh, the handles, the targets, the energy and the solver settings, so every later run
(any method, any experiment) reuses it. :func:`reference_metrics` scores a deformed mesh
against it:

- ``ref_mean_pct`` / ``ref_max_pct``: mean / max vertex distance to the reference, in %
  of the rest mesh's bounding-box diagonal;
- ``energy_gap``: ``(E(U) - E(U*)) / |E(U*)|``, i.e. ``E(U) / E(U*) - 1`` for a positive
  minimum, with ``E`` the reference's energy (libigl's weights, :mod:`sshade.arap.operators`);
  ``>= 0`` up to the reference's own tolerance. (libigl's cotangent weights are negative
  on obtuse triangles, so the spokes energy of a mesh with many of them, e.g. FAUST's,
  can be negative at its minimum: hence ``|E(U*)|``.)
"""
from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from defaust.store import read_npz, write_npz
from sshade.arap import DEEP_CRITERION, ENERGIES, build_operators, solve_arap
from sshade.errors import SShaDeError

__all__ = ["REFERENCE_VERSION", "Reference", "reference_key", "reference_solution", "reference_metrics",
           "method_energy"]

log = logging.getLogger("eval")

#: Bumped whenever the reference solver's output for the same inputs changes.
REFERENCE_VERSION = 1

#: Method name -> the ARAP energy its result is compared with.
_METHOD_ENERGY = {"ARAP": "spokes", "ARAP-SR": "spokes", "Elastic": "spokes_and_rims", "SShaDe": "spokes_and_rims"}


def method_energy(method) -> str:
    """The ARAP energy a method's result is scored against: its own ``energy`` attribute
    when it names one of :data:`sshade.arap.ENERGIES`, else by name (ARAP and
    ARAP-SR: spokes; Elastic, SShaDe and any other method: spokes-and-rims, the energy of
    SShaDe's low-resolution step, paper §4.1)."""
    e = getattr(method, "energy", None)
    if e in ENERGIES:
        return str(e)
    return _METHOD_ENERGY.get(str(getattr(method, "name", method)), "spokes_and_rims")


@dataclass
class Reference:
    """A cached reference solution.

    Attributes
    ----------
    U : (n, 3) float64 the deep-converged minimiser (mesh units).
    energy : float, its ARAP energy (mesh units^2). energy_type : str.
    key : str, the cache key (hex). path : Path of the cache file.
    info : dict, how it was obtained: iterations, status, gnorm, seconds, cached (bool).
    """

    U: np.ndarray
    energy: float
    energy_type: str
    key: str
    path: Path
    info: dict = field(default_factory=dict)


def reference_key(V, F, handles, targets, energy: str, solver: dict) -> str:
    """SHA-256 (hex) of everything a reference depends on: the bytes of ``V`` (n, 3)
    float64, ``F`` (m, 3) int64, ``handles`` (h,) int64, ``targets`` (h, 3) float64, the
    energy, the solver settings and :data:`REFERENCE_VERSION`."""
    h = hashlib.sha256()
    for a, dt in ((V, np.float64), (F, np.int64), (handles, np.int64), (targets, np.float64)):
        h.update(np.ascontiguousarray(a, dt).tobytes())
        h.update(str(np.shape(a)).encode())
    h.update(json.dumps({"energy": energy, "solver": solver, "version": REFERENCE_VERSION},
                        sort_keys=True).encode())
    return h.hexdigest()


def _solver_settings(max_iter: int, time_budget_s: float | None) -> dict:
    return {"etol": DEEP_CRITERION.etol, "gtol": DEEP_CRITERION.gtol, "max_iter": int(max_iter),
            "time_budget_s": time_budget_s, "accelerate": "lbfgs"}


def reference_solution(V, F, handles, targets, *, energy: str = "spokes_and_rims", cache_dir="data/references",
                       max_iter: int = 50000, time_budget_s: float | None = 3600.0,
                       U0: np.ndarray | None = None) -> Reference:
    """The deep-converged ARAP minimiser of one case, from the cache or computed and cached.

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces (validated by the caller).
    handles : (h,) int64 vertex indices. targets : (h, 3) float64 target positions.
    energy : ``"spokes"`` or ``"spokes_and_rims"``.
    cache_dir : folder of the cache files (created; one ``<energy>_<key>.npz`` each).
    max_iter, time_budget_s : caps of the deep solve (recorded in the key and ``info``).
    U0 : (n, 3) float64 or None, a start for the deep solve (e.g. a method's result;
        the minimiser does not depend on it, only the time to reach it). Not part of
        the key.

    Returns
    -------
    :class:`Reference` (``info["cached"]`` tells whether it was read from disk).

    Raises
    ------
    SShaDeError on an unknown energy or an unreadable cache file (delete it to recompute).
    """
    if energy not in ENERGIES:
        raise SShaDeError(f"unknown ARAP energy {energy!r}; use one of {ENERGIES}")
    solver = _solver_settings(max_iter, time_budget_s)
    key = reference_key(V, F, handles, targets, energy, solver)
    path = Path(cache_dir) / f"{energy}_{key[:24]}.npz"
    if path.is_file():
        d = read_npz(path)
        if str(d.get("key", "")) != key or d["U"].shape != np.shape(V):
            raise SShaDeError(f"{path}: reference cache entry does not match its key; delete it to recompute")
        info = json.loads(str(d["info"]))
        info["cached"] = True
        return Reference(U=d["U"], energy=float(d["energy"]), energy_type=energy, key=key, path=path, info=info)
    t0 = time.perf_counter()
    res = solve_arap(V, F, handles, targets, energy=energy, U0=U0, criterion=DEEP_CRITERION, max_iter=max_iter,
                     time_budget_s=time_budget_s, accelerate=solver["accelerate"])
    dt = time.perf_counter() - t0
    info = {"iterations": int(res.iterations), "status": str(res.info.get("status")),
            "gnorm": float(res.info.get("gnorm", np.nan)), "rel_decrease": float(res.info.get("rel_decrease", np.nan)),
            "seconds": round(dt, 3), "solver": solver, "n_vertices": int(len(V)), "cached": False}
    E = float(res.info.get("energy", np.nan))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_npz(path, {"U": np.asarray(res.V, np.float64), "energy": np.float64(E), "key": np.array(key),
                     "info": np.array(json.dumps(info))})
    log.info("reference %s for %d vertices: %d iterations, %s, %.1f s -> %s", energy, len(V), res.iterations,
             info["status"], dt, path)
    return Reference(U=np.asarray(res.V, np.float64), energy=E, energy_type=energy, key=key, path=path, info=info)


def reference_metrics(V_rest, Vd, F, ref: Reference, operators=None) -> dict:
    """Distance of a deformed mesh to a reference solution.

    Parameters
    ----------
    V_rest : (n, 3) float64 rest positions (for the bounding-box diagonal and the energy).
    Vd : (n, 3) float64 the method's result. F : (m, 3) int64 faces.
    ref : :class:`Reference` of the same case.
    operators : :class:`sshade.arap.ArapOperators` of ``(V_rest, F, ref.energy_type)``
        or None (built here).

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
    ops = operators if operators is not None else build_operators(V_rest, F, ref.energy_type)
    E = float(ops.energy(Vd))
    gap = (E - ref.energy) / abs(ref.energy) if ref.energy != 0 else float("nan")
    return {"ref_mean_pct": float(d.mean()), "ref_max_pct": float(d.max()), "energy_gap": float(gap),
            "ref_energy": float(ref.energy)}

"""Reference solutions: the deep-converged full-resolution ARAP minimiser of a case,
computed once, cached on disk, and the distance of any method's result to it.
Floor 1 of eval/ (eval/metrics/, tests/test_layering.py); notes: docs/experiments.md.

- ``ref_mean_pct`` / ``ref_max_pct``: mean / max vertex distance to the reference, in %
  of the rest mesh's bounding-box diagonal;
- ``energy_gap``: ``(E(U) - E(U*)) / |E(U*)|``, i.e. ``E(U) / E(U*) - 1`` for a positive
  minimum, with ``E`` the reference's energy (libigl's weights, :mod:`sshade.arap.operators`);
  ``>= 0`` up to the reference's own tolerance. (libigl's cotangent weights are negative
  on obtuse triangles, so the spokes energy of a mesh with many of them, e.g. FAUST's,
  can be negative at its minimum: hence ``|E(U*)|``.)"""
from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from baselines.coarse_start import coarse_start, uses_coarse
from defaust.store import read_npz, write_npz
from eval.run.code_identity import numerical_versions, sources_digest
from harness.method_registry import method_meta
from sshade.arap import (
    ALPHA_SCALINGS,
    DEEP_CRITERION,
    ENERGIES,
    SR_ENERGY,
    SRProblem,
    build_operators,
    solve_arap,
    solve_arap_sr,
)
from sshade.errors import SShaDeError
from sshade.files import inside_folder

__all__ = ["REFERENCE_VERSION", "Reference", "status_words", "reference_key", "reference_path",
           "reference_solution", "reference_metrics",
           "method_energy", "sr_energy", "sr_alpha", "sr_params", "energy_operators"]

log = logging.getLogger("eval")

#: Bumped whenever the reference solver's output for the same inputs changes.
REFERENCE_VERSION = 1

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
        return sr_energy(getattr(method, "alpha", 0.01), getattr(method, "alpha_scaling", "valence"))
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


def _deep_solve(V, F, handles, targets, energy, solver, U0, R0=None):
    """The deep solve of ``energy``: ``(U, E, result)``."""
    p = sr_params(energy)
    if p is None:
        res = solve_arap(V, F, handles, targets, energy=energy, U0=U0, criterion=DEEP_CRITERION,
                         max_iter=solver["max_iter"], time_budget_s=solver["time_budget_s"],
                         accelerate=solver["accelerate"])
    else:
        U0, R0 = _sr_start(V, F, handles, targets, p, U0, R0)
        res = solve_arap_sr(V, F, handles, targets, alpha=p[0], alpha_scaling=p[1], U0=U0, R0=R0,
                            criterion=DEEP_CRITERION,
                            max_iter=solver["max_iter"], time_budget_s=solver["time_budget_s"])
    return np.asarray(res.V, np.float64), float(res.info.get("energy", np.nan)), res


def _sr_start(V, F, handles, targets, params, U0, R0):
    """``(U0, R0)`` for ARAP-SR's deep solve: a converged ARAP-SR result ``U0`` with its
    rotations ``R0``, so the deep solve continues that path; else (no ``R0``: sweeps for
    the rotations of a given ``U0`` crawl at 169k vertices), on a mesh of at least
    ``COARSE_MIN_RATIO`` x 6,000 vertices, the method's own coarse start
    (:func:`baselines.coarse_start.coarse_start`; from the rigid fit the solve takes
    hours at 169k vertices); else the rigid fit (``(None, None)``). ``params``:
    ``(alpha, alpha_scaling)``."""
    if U0 is not None and R0 is not None:
        return U0, R0
    if uses_coarse("auto", len(V), 6000):  # the method's own rule (baselines/coarse_start.py)
        return None, coarse_start(V, F, handles, targets, energy=SR_ENERGY, alpha=params[0], n_low=6000,
                                  alpha_scaling=params[1])[0]
    return None, None


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


#: how a solver status reads in a log line; the status itself (``info["status"]``,
#: ``ref_status`` in cases.csv) keeps the solvers' names.
_STATUS_WORDS = {"stalled": "reached float64 precision", "max_iter": "stopped at max_iter",
                 "time_budget": "stopped at the time budget"}


def status_words(status) -> str:
    """A solver status (:func:`sshade.arap.solve_arap`) in words for a log line:
    ``stalled`` (the energy stopped decreasing in float64 round-off, a success) reads
    ``reached float64 precision``; ``converged`` and unknown values are kept."""
    return _STATUS_WORDS.get(str(status), str(status))


#: The source folders whose code decides a reference: the energies, their operators and
#: solvers (ARAP's and Elastic's in ``sshade/arap``, ARAP-SR's in ``baselines``).
REFERENCE_CODE = ("sshade/arap", "baselines")


def reference_key(V, F, handles, targets, energy: str, solver: dict) -> str:
    """SHA-256 (hex) of everything a reference depends on: the bytes of ``V`` (n, 3)
    float64, ``F`` (m, 3) int64, ``handles`` (h,) int64, ``targets`` (h, 3) float64, the
    energy, the solver settings, :data:`REFERENCE_VERSION` and the code that defines the
    energies and solves them (:data:`REFERENCE_CODE`: the sources of ``sshade/arap`` and
    ``baselines``, and the numerical libraries' versions, :mod:`eval.run.code_identity`): a
    reference cached by other code is computed again, never reused."""
    h = hashlib.sha256()
    for a, dt in ((V, np.float64), (F, np.int64), (handles, np.int64), (targets, np.float64)):
        h.update(np.ascontiguousarray(a, dt).tobytes())
        h.update(str(np.shape(a)).encode())
    code = {"sources": sources_digest(REFERENCE_CODE), "versions": numerical_versions()}
    h.update(json.dumps({"energy": energy, "solver": solver, "version": REFERENCE_VERSION, "code": code},
                        sort_keys=True).encode())
    return h.hexdigest()


def _solver_settings(max_iter: int, time_budget_s: float | None, energy: str) -> dict:
    out = {"etol": DEEP_CRITERION.etol, "gtol": DEEP_CRITERION.gtol, "max_iter": int(max_iter),
           "time_budget_s": time_budget_s, "accelerate": "lbfgs" if sr_alpha(energy) is None else "anderson"}
    if sr_alpha(energy) is not None:  # Anderson on (U, R) keeping its history; coarse or continued start
        out["scheme"] = 2
    return out


def reference_path(V, F, handles, targets, *, energy: str, cache_dir, max_iter: int = 50000,
                   time_budget_s: float | None = 3600.0) -> tuple[str, Path]:
    """``(key, path)``: the cache key (:func:`reference_key`) of a case's reference and
    the file :func:`reference_solution` reads or writes for it (arguments as there); a
    hash of the arrays, no solve: ``path.is_file()`` tells cheaply whether it is cached.
    Raises SShaDeError on an unknown energy."""
    _check_energy(energy)
    key = reference_key(V, F, handles, targets, energy, _solver_settings(max_iter, time_budget_s, energy))
    return key, Path(cache_dir) / f"{energy}_{key[:24]}.npz"


def reference_solution(V, F, handles, targets, *, energy: str = "spokes_and_rims", cache_dir="data/references",
                       max_iter: int = 50000, time_budget_s: float | None = 3600.0,
                       U0: np.ndarray | None = None, R0: np.ndarray | None = None) -> Reference:
    """The deep-converged ARAP minimiser of one case, from the cache or computed and cached.

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces (validated by the caller).
    handles : (h,) int64 vertex indices. targets : (h, 3) float64 target positions.
    energy : ``"spokes"``, ``"spokes_and_rims"`` (:func:`sshade.arap.solve_arap`) or an
        ARAP-SR energy :func:`sr_energy` (``alpha``; :func:`sshade.arap.solve_arap_sr`,
        Anderson-accelerated block descent; ``energy`` = ``E(U, R)`` at the final state).
    cache_dir : folder of the cache files (created; one ``<energy>_<key>.npz`` each).
    max_iter, time_budget_s : caps of the deep solve (recorded in the key and ``info``).
    U0 : (n, 3) float64 or None, a start for the deep solve (e.g. a method's result;
        the minimiser does not depend on it, only the time to reach it). Not part of
        the key. For an ARAP-SR energy, without ``U0`` the deep solve starts from the
        coarse start on meshes of at least 24,000 vertices (:func:`baselines.coarse_start.coarse_start`).
    R0 : (n, 3, 3) float64 or None, ARAP-SR's rotations at ``U0``; ARAP-SR's deep solve
        continues from ``(U0, R0)`` only when both are given; ignored for the other energies.

    Returns
    -------
    :class:`Reference` (``info["cached"]`` tells whether it was read from disk).

    Raises
    ------
    SShaDeError on an unknown energy.

    A cache entry is used only when it is whole (:func:`_read_entry`: a real file, not a
    link, under its key, of the case's shape, finite, its content digest matching); any
    other entry is computed again and replaced, with one warning line saying why. The
    digest tells an edited or damaged entry from a whole one, not a forger's: whoever
    edits an entry can recompute it.
    """
    solver = _solver_settings(max_iter, time_budget_s, energy)
    key, path = reference_path(V, F, handles, targets, energy=energy, cache_dir=cache_dir, max_iter=max_iter,
                               time_budget_s=time_budget_s)
    if path.is_file() or path.is_symlink():
        found, why = _read_entry(path, cache_dir, key, np.shape(V))
        if found is not None:
            U, E, info = found
            return Reference(U=U, energy=E, energy_type=energy, key=key, path=path, info={**info, "cached": True})
        log.warning("%s: reference cache entry not used (%s); computing it again", path, why)
        if path.is_symlink():
            path.unlink()  # the link, never what it points to
    t0 = time.perf_counter()
    U, E, res = _deep_solve(V, F, handles, targets, energy, solver, U0, R0)
    dt = time.perf_counter() - t0
    info = {"iterations": int(res.iterations), "status": str(res.info.get("status")),
            "gnorm": float(res.info.get("gnorm", np.nan)), "rel_decrease": float(res.info.get("rel_decrease", np.nan)),
            "seconds": round(dt, 3), "solver": solver, "n_vertices": int(len(V)), "cached": False}
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(info)
    write_npz(inside_folder(cache_dir, path.name, "reference cache"),
              {"U": U, "energy": np.float64(E), "key": np.array(key), "info": np.array(text),
               "content": np.array(_content_digest(U, E, key, text))})
    log.info("reference %s for %d vertices: %d iterations, %s, %.1f s -> %s", energy, len(V), res.iterations,
             status_words(info["status"]), dt, path)
    return Reference(U=U, energy=E, energy_type=energy, key=key, path=path, info=info)


def _content_digest(U: np.ndarray, E: float, key: str, info: str) -> str:
    """SHA-256 (hex) of a cache entry's content: ``U`` (n, 3) float64's bytes, the energy,
    the key and the info text. Stored beside them, it tells an edited or corrupted entry
    from a whole one; it is no signature (whoever edits the entry can recompute it)."""
    h = hashlib.sha256(np.ascontiguousarray(U, np.float64).tobytes())
    h.update(np.float64(E).tobytes())
    h.update(key.encode() + b"\0" + info.encode())
    return h.hexdigest()


def _read_entry(path: Path, cache_dir, key: str, shape: tuple):
    """A cache entry read as untrusted input: ``((U, E, info), None)`` when it is a real
    file inside ``cache_dir`` (no link), a readable npz of the expected arrays, under
    ``key``, with a finite ``U`` of ``shape``, a finite energy, a JSON mapping as info and
    a matching :func:`_content_digest`; else ``(None, why)``."""
    try:
        inside_folder(cache_dir, path.name, "reference cache entry")
        d = read_npz(path)
    except SShaDeError as e:
        return None, str(e)
    if set(d) != {"U", "energy", "key", "info", "content"}:
        return None, f"arrays {sorted(d)}, not U, energy, key, info, content"
    U, E = d["U"], d["energy"]
    if d["key"].shape != () or str(d["key"]) != key:
        return None, "it does not match its key"
    if U.dtype != np.float64 or U.shape != shape or not np.isfinite(U).all():
        return None, f"its solution is not a finite float64 array of shape {shape}"
    if E.shape != () or E.dtype != np.float64 or not np.isfinite(E):
        return None, "its energy is not a finite float64"
    text = str(d["info"])
    try:
        info = json.loads(text)
    except ValueError:
        info = None
    if not isinstance(info, dict):
        return None, "its info is not a JSON mapping"
    if str(d["content"]) != _content_digest(U, float(E), key, text):
        return None, "edited: its content digest does not match"
    return (U, float(E), info), None


def reference_metrics(V_rest, Vd, F, ref: Reference, operators=None, R0=None) -> dict:
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

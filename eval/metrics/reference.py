"""Reference solutions: the deep-converged full-resolution ARAP minimiser of a case,
computed once and cached on disk (:func:`reference_solution`), an artifact of its own:
the code of this module's import closure solves it, and a row scored against it records
its content digest, not that code (:mod:`eval.run.code_identity`, docs/reproduction.md).
What a result is scored against and how far it lies from the reference:
:mod:`eval.metrics.reference_scores`.
Floor 1 of eval/ (eval/metrics/, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from baselines.coarse_start import COARSE_N_LOW, coarse_start, uses_coarse
from defaust.store import read_npz, write_npz
from eval.metrics.reference_scores import sr_alpha, sr_params
from eval.run.reference_cache import reference_key
from sshade.arap import (
    DEEP_CRITERION,
    ENERGIES,
    SR_ENERGY,
    ArapOptions,
    solve_arap,
    solve_arap_sr,
)
from sshade.errors import SShaDeError
from sshade.files import inside_folder
from sshade.mesh.unit_frame import unit_frame

__all__ = ["Reference", "status_words", "reference_path", "reference_solution"]

log = logging.getLogger("eval")

#: The second-order probe of a deep solve of a spokes energy (:func:`_probe`): the deep
#: minimiser's vertices moved by Gaussian noise of ``PROBE_SCALE`` unit-frame lengths
#: (:func:`sshade.mesh.unit_frame.unit_frame`; numpy ``default_rng(PROBE_SEED)``), solved
#: again to the default criterion, at most ``PROBE_ROUNDS`` times; a probe lower than the
#: deep energy by more than ``PROBE_RTOL`` of it found a lower basin.
PROBE_SCALE, PROBE_SEED, PROBE_ROUNDS, PROBE_RTOL = 1e-3, 0, 3, 1e-9

def _check_energy(energy: str) -> None:
    if energy not in ENERGIES and sr_alpha(energy) is None:
        raise SShaDeError(f"unknown ARAP energy {energy!r}; use one of {ENERGIES} or sr_energy(alpha)")


def _deep_solve(V, F, handles, targets, energy, solver, U0, R0=None):
    """The deep solve of ``energy``: ``(U, E, result)``."""
    p = sr_params(energy)
    if p is None:
        options = ArapOptions(energy=energy, criterion=DEEP_CRITERION, max_iter=solver["max_iter"],
                              time_budget_s=solver["time_budget_s"], accelerate=solver["accelerate"])
        res = solve_arap(V, F, handles, targets, options, U0=U0)
    else:
        U0, R0 = _sr_start(V, F, handles, targets, p, U0, R0)
        options = ArapOptions(alpha=p[0], alpha_scaling=p[1], criterion=DEEP_CRITERION, max_iter=solver["max_iter"],
                              time_budget_s=solver["time_budget_s"])
        res = solve_arap_sr(V, F, handles, targets, options, U0=U0, R0=R0)
    return np.asarray(res.V, np.float64), float(res.info.get("energy", np.nan)), res


def _probe(V, F, handles, targets, energy, solver, U, E, res):
    """The second-order probe of a deep solve ``(U, E, res)`` of a spokes energy: a
    first-order stop (the gradient criterion) also holds at a saddle, and a deep solve
    continued from a method that stopped at one stays there. Each round moves every free
    vertex of ``U`` by Gaussian noise (:data:`PROBE_SCALE`, :data:`PROBE_SEED`) and solves
    again to the default criterion; a probe lower than ``E`` by more than
    :data:`PROBE_RTOL` of it (a saddle, or a minimum that shallow) starts a new deep
    solve, and the next round probes that; a probe that comes back no lower ends the
    rounds with ``(U, E, res)`` unchanged, bit for bit. ARAP-SR's energy (rotations in
    its state) is not probed. Returns ``(U, E, res, probe)``: ``probe`` the record of the
    rounds (``None`` for ARAP-SR): ``scale``, ``seed``, ``rounds`` (each: ``energy``,
    ``probe_energy``, ``probe_iterations``, ``lower``), ``deep_iterations`` (of the deep
    solves before the last) and ``verified`` (the last round found no lower energy)."""
    if sr_params(energy) is not None:
        return U, E, res, None
    rng = np.random.default_rng(PROBE_SEED)
    sigma = PROBE_SCALE * unit_frame(V).scale
    options = ArapOptions(energy=energy, max_iter=solver["max_iter"], time_budget_s=solver["time_budget_s"])
    rounds, deep_iterations = [], 0
    for _ in range(PROBE_ROUNDS):
        p = solve_arap(V, F, handles, targets, options, U0=U + sigma * rng.standard_normal(U.shape))
        Ep = float(p.info.get("energy", np.nan))
        lower = bool(Ep < E - PROBE_RTOL * abs(E))
        rounds.append({"energy": E, "probe_energy": Ep, "probe_iterations": int(p.iterations), "lower": lower})
        if not lower:
            break
        log.info("reference %s: a probe found a lower energy (%.9g against %.9g): solving again from it",
                 energy, Ep, E)
        deep_iterations += int(res.iterations)
        U, E, res = _deep_solve(V, F, handles, targets, energy, solver, np.asarray(p.V, np.float64))
    return U, E, res, {"scale": PROBE_SCALE, "seed": PROBE_SEED, "rounds": rounds,
                       "deep_iterations": deep_iterations, "verified": not rounds[-1]["lower"]}


def _sr_start(V, F, handles, targets, params, U0, R0):
    """``(U0, R0)`` for ARAP-SR's deep solve: a converged ARAP-SR result ``U0`` with its
    rotations ``R0``, so the deep solve continues that path; else (no ``R0``: sweeps for
    the rotations of a given ``U0`` crawl at 169k vertices), on a mesh of at least
    ``COARSE_MIN_RATIO`` x ``COARSE_N_LOW`` vertices, the method's own coarse start
    (:func:`baselines.coarse_start.coarse_start`; from the rigid fit the solve takes
    hours at 169k vertices); else the rigid fit (``(None, None)``). ``params``:
    ``(alpha, alpha_scaling)``."""
    if U0 is not None and R0 is not None:
        return U0, R0
    if uses_coarse("auto", len(V), COARSE_N_LOW):  # the method's own rule (baselines/coarse_start.py)
        return None, coarse_start(V, F, handles, targets, energy=SR_ENERGY, alpha=params[0], n_low=COARSE_N_LOW,
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
    info : dict, how it was obtained: iterations, status, gnorm, seconds, cached (bool),
        and for a spokes energy ``probe``, its second-order probe (:func:`_probe`).
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


def _solver_settings(max_iter: int, time_budget_s: float | None, energy: str) -> dict:
    out = {"etol": DEEP_CRITERION.etol, "gtol": DEEP_CRITERION.gtol, "max_iter": int(max_iter),
           "time_budget_s": time_budget_s, "accelerate": "lbfgs" if sr_alpha(energy) is None else "anderson"}
    if sr_alpha(energy) is not None:  # Anderson on (U, R) keeping its history; coarse or continued start
        out["scheme"] = 2
    else:  # the second-order probe (_probe)
        out["probe"] = {"scale": PROBE_SCALE, "seed": PROBE_SEED, "rounds": PROBE_ROUNDS, "rtol": PROBE_RTOL}
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
    :class:`Reference` (``info["cached"]`` tells whether it was read from disk). For a
    spokes energy the deep solve's stop is probed to the second order (:func:`_probe`:
    a first-order stop holds at a saddle too): a lower basin found there is solved
    deep again, and ``info["probe"]`` records the rounds.

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
    U, E, res, probe = _probe(V, F, handles, targets, energy, solver, U, E, res)
    dt = time.perf_counter() - t0
    info = {"iterations": int(res.iterations), "status": str(res.info.get("status")),
            "gnorm": float(res.info.get("gnorm", np.nan)), "rel_decrease": float(res.info.get("rel_decrease", np.nan)),
            "seconds": round(dt, 3), "solver": solver, "n_vertices": int(len(V)), "cached": False}
    if probe is not None:
        info["probe"] = probe
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


_ENTRY = ("U", "energy", "key", "info", "content")  # the arrays of a cache entry


def _read_entry(path: Path, cache_dir, key: str, shape: tuple):
    """A cache entry read as untrusted input: ``((U, E, info), None)`` when it is a real
    file inside ``cache_dir`` (no link), a readable npz of the expected arrays, under
    ``key``, with a finite ``U`` of ``shape``, a finite energy, a JSON mapping as info and
    a matching :func:`_content_digest`; else ``(None, why)``."""
    try:
        inside_folder(cache_dir, path.name, "reference cache entry")
        d = read_npz(path, _ENTRY, max_bytes={"U": 8 * int(np.prod(shape)) + 4096, "info": 64 * 2**20,
                                              "energy": 4096, "key": 4096, "content": 4096})
    except SShaDeError as e:  # another member, or one larger than its entry needs: refused before it is inflated
        return None, str(e)
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



"""Compile-before-timing: run a method once on a tiny mesh so that numba's compilation
(or its cache loads) and lazy imports' first-call costs happen outside the timed call.

Every method of the evaluator has a ``warmup(n_vertices=None) -> float`` built on
:func:`warm_once` (SShaDe's: :func:`sshade.pipeline.warm_sshade`); the evaluator records its
seconds as ``compile_s``. Also :func:`tiny_problem`, :func:`warm_fullres`,
:func:`warm_parallel_kernels`. This module imports nothing above the ARAP solver; cold
caches: docs/implementation.md ("Implementation notes: sshade/warmup.py").
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from .arap import ArapOptions, arap_deform, kernels, solver_kernels
from .arap.threads import resolve_threads
from .mesh.validate import validate_handles, validate_mesh

__all__ = ["tiny_problem", "warm_once", "warm_fullres", "warm_parallel_kernels", "uses_parallel_kernels", "WARMED"]

_TINY: tuple | None = None
#: Keys of the warm-ups done in this process (forked workers inherit it): the ``done``
#: set of :func:`warm_once` shared by every method of this project.
WARMED: set = set()


def tiny_problem() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A small deformation problem: a 162-vertex icosphere (unit radius), 6 handles,
    three of them static and three moved by a rotation of 30 degrees and a shift.

    Returns
    -------
    V : (162, 3) float64; F : (320, 3) int64; handles : (6,) int64; targets : (6, 3)
    float64. Fresh copies on every call.
    """
    global _TINY
    if _TINY is None:
        import trimesh
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        V = np.ascontiguousarray(m.vertices, np.float64)
        F = np.ascontiguousarray(m.faces, np.int64)
        lo = np.argsort(V[:, 2])[:3]                 # bottom: static
        hi = np.argsort(V[:, 2])[-3:]                # top: rotated about z, shifted
        c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        handles = np.concatenate([lo, hi]).astype(np.int64)
        targets = np.concatenate([V[lo], V[hi] @ R.T + [0.1, 0, 0.2]])
        _TINY = (V, F, handles, targets)
    return tuple(np.array(a) for a in _TINY)


def uses_parallel_kernels(n_vertices: int | None) -> bool:
    """Whether a full-resolution ARAP solve on an ``n_vertices`` mesh runs numba's parallel
    kernels (:func:`sshade.arap.threads.resolve_threads` in the automatic mode, from this
    thread: enough rotation cells = vertices, more than one thread, not inside a worker
    process). False for None."""
    if n_vertices is None:
        return False
    return resolve_threads(None, int(n_vertices)) > 1


def warm_parallel_kernels(smooth_rotations: bool = False) -> None:
    """Compile (or load from numba's cache) the parallel variants of the ARAP kernels
    (:mod:`sshade.arap.kernels`, :mod:`sshade.arap.solver_kernels`), and ARAP-SR's local
    step (``smooth_rotations``). Starts numba's thread pool: call it only where a parallel
    solve follows anyway (:func:`uses_parallel_kernels`)."""
    kernels.fused_kernels(True)
    solver_kernels.loop_kernels(True)
    solver_kernels.anderson_kernels(True)
    if smooth_rotations:
        kernels.sr_local_kernel(True)


def warm_once(done: set, key, run: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], object],
              *, parallel: bool = False) -> float:
    """Run ``run(V, F, handles, targets)`` on :func:`tiny_problem` once per ``key`` (kept
    in the caller's ``done`` set), plus :func:`warm_parallel_kernels` when ``parallel``.

    Returns
    -------
    float, seconds spent (0.0 when ``key`` was already warm). Errors of ``run`` propagate
    (a method that cannot run on the tiny problem would fail on the real one too).
    """
    if key in done and (not parallel or (key, "parallel") in done):
        return 0.0
    t0 = time.perf_counter()
    if key not in done:
        run(*tiny_problem())
        done.add(key)
    if parallel and (key, "parallel") not in done:
        warm_parallel_kernels()
        done.add((key, "parallel"))
    return time.perf_counter() - t0


def warm_fullres(energy: str, protocol: str, n_vertices: int | None = None) -> float:
    """Warm a full-resolution ARAP solve (:func:`sshade.arap.arap_deform`) of ``energy``
    (``"spokes"`` or ``"spokes_and_rims"``) under ``protocol`` (``"converged"`` or
    ``"paper"``), with the parallel kernels too when an ``n_vertices`` mesh uses them
    (:func:`uses_parallel_kernels`). Returns the seconds spent (0.0 when warm)."""

    def run(V, F, h, T):  # as the baselines' deform: validation, then the solve
        V, F = validate_mesh(V, F)
        h, T = validate_handles(V, h, T)
        return arap_deform(V, F, h, T, ArapOptions(energy=energy, protocol=protocol))
    return warm_once(WARMED, ("fullres", energy, protocol), run,
                     parallel=protocol == "converged" and uses_parallel_kernels(n_vertices))

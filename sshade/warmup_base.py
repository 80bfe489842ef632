"""The ground of the warm-ups (:mod:`sshade.warmup`): a tiny deformation problem
(:func:`tiny_problem`) and a method's run on it once per process (:func:`warm_once`, the
keys done in :data:`WARMED`), so that numba's compilation (or its cache loads) and lazy
imports' first-call costs happen outside a timed call.

It imports no solver: a method whose protocol runs no converged solver (the paper
protocol of :mod:`baselines.fullres_paper`) warms up without holding one in its code
identity (eval.run.code_identity).
"""
from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

__all__ = ["tiny_problem", "warm_once", "WARMED"]

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


def warm_once(done: set, key, run: Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], object]) -> float:
    """Run ``run(V, F, handles, targets)`` on :func:`tiny_problem` once per ``key`` (kept
    in the caller's ``done`` set).

    Returns
    -------
    float, seconds spent (0.0 when ``key`` was already warm). Errors of ``run`` propagate
    (a method that cannot run on the tiny problem would fail on the real one too).
    """
    if key in done:
        return 0.0
    t0 = time.perf_counter()
    run(*tiny_problem())
    done.add(key)
    return time.perf_counter() - t0

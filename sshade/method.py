"""The one small interface every deformation method implements (SShaDe and the
baselines), so the evaluator treats them alike.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["Deformer"]


@runtime_checkable
class Deformer(Protocol):
    """A handle-driven deformation method.

    Attributes
    ----------
    name : str, the row label in tables ("ARAP", "Elastic", "SShaDe", ...).
    info : dict, filled by the last :meth:`deform` call with per-stage timings in
        seconds (keys ending in ``_s``), iteration counts and seeds.

    Methods
    -------
    deform(V, F, handles, targets) -> (n, 3) float64
        ``V`` (n,3) float64 rest positions, ``F`` (m,3) int64, ``handles`` (h,) int64
        vertex indices, ``targets`` (h,3) float64 positions. Returns deformed positions
        with the same connectivity ``F``. Raises ``SShaDeError`` on bad input.
    warmup(n_vertices=None) -> float, optional
        Compile or load whatever the first :meth:`deform` on an ``n_vertices`` mesh
        would (numba kernels, lazy imports), returning the seconds spent (0.0 when
        already warm). The evaluator calls it before the timed call and reports the
        seconds as ``compile_s``, never inside ``time_s`` (:mod:`sshade.warmup`).
    """

    name: str
    info: dict

    def deform(self, V: np.ndarray, F: np.ndarray, handles: np.ndarray,
               targets: np.ndarray) -> np.ndarray: ...

"""The paper's protocol of ARAP-SR (:mod:`baselines.arap_sr`; paper §4.1, Table 1): Open3D's
plain Smoothed-ARAP iteration from the rigid fit of the handles, stopped by its energy (or
move) rule (:func:`sshade.arap.sr_paper_protocol.arap_sr_deform`), and its warm-up.

It imports nothing of the converged solvers, so these rows keep their code identity when
those change (eval.run.code_identity). Named by :data:`baselines.arap_sr.PROTOCOL_MODULES`;
docs/protocols.md.
"""
from __future__ import annotations

import numpy as np

from sshade.arap import ArapOptions, arap_sr_deform
from sshade.arap.kernels import fused_kernels, sr_local_kernel
from sshade.arap.threads import uses_parallel_kernels
from sshade.warmup_base import WARMED, warm_once

__all__ = ["solve", "warmup"]


def solve(method, V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray):
    """:func:`baselines.arap_sr_converged.solve`'s contract under the paper protocol (the
    arrays as there): the :class:`sshade.arap.ArapResult` of
    :func:`sshade.arap.sr_paper_protocol.arap_sr_deform` with ``method``'s stop rule."""
    options = ArapOptions(alpha=method.alpha, alpha_scaling=method.alpha_scaling, stop=method.stop, tol=method.tol,
                          criterion=method.criterion, max_iter=method.max_iter)
    return arap_sr_deform(V, F, handles, targets, options)


def warmup(method, n_vertices: int | None = None) -> float:
    """Warm ``method``'s solve on :func:`sshade.warmup_base.tiny_problem` once per process,
    and, when an ``n_vertices`` mesh runs them (:func:`sshade.arap.threads.uses_parallel_kernels`),
    the parallel local step and right-hand side. Returns the seconds spent."""
    s = warm_once(WARMED, ("arap_sr", "paper", False),
                  lambda V, F, h, T: type(method)(alpha=method.alpha, alpha_scaling=method.alpha_scaling, max_iter=5,
                                                  protocol="paper").deform(V, F, h, T))
    if uses_parallel_kernels(n_vertices):
        def parallel(*_):
            fused_kernels(True)
            sr_local_kernel(True)
        s += warm_once(WARMED, ("arap_sr", "paper", "parallel"), parallel)
    return s

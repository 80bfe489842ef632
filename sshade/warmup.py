"""Compile-before-timing: run a method once on a tiny mesh so that numba's compilation
(or its cache loads) and lazy imports' first-call costs happen outside the timed call.

Every method of the evaluator has a ``warmup(n_vertices=None) -> float`` built on
:func:`warm_once` (SShaDe's: :func:`sshade.pipeline.warm_sshade`); the evaluator records its
seconds as ``compile_s``. Also :func:`warm_fullres`, :func:`warm_parallel_kernels`, and
:func:`tiny_problem`, :func:`warm_once`, :data:`WARMED` (:mod:`sshade.warmup_base`). This
module imports nothing above the ARAP solver; cold caches: docs/implementation.md
("Implementation notes: sshade/warmup.py").
"""
from __future__ import annotations

from .arap import ArapOptions, arap_deform, kernels, solver_kernels
from .arap.paper_protocol import warm_paper
from .arap.threads import uses_parallel_kernels
from .mesh.validate import validate_handles, validate_mesh
from .warmup_base import WARMED, tiny_problem, warm_once

__all__ = ["tiny_problem", "warm_once", "warm_fullres", "warm_parallel_kernels", "uses_parallel_kernels", "WARMED"]


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


def warm_fullres(energy: str, protocol: str, n_vertices: int | None = None) -> float:
    """Warm a full-resolution ARAP solve (:func:`sshade.arap.arap_deform`) of ``energy``
    (``"spokes"`` or ``"spokes_and_rims"``) under ``protocol``: ``"converged"``, with the
    parallel kernels too when an ``n_vertices`` mesh uses them (:func:`uses_parallel_kernels`),
    or ``"paper"`` (:func:`sshade.arap.paper_protocol.warm_paper`). Returns the seconds
    spent (0.0 when warm)."""
    if protocol == "paper":
        return warm_paper(energy)

    def run(V, F, h, T):  # as the baselines' deform: validation, then the solve
        V, F = validate_mesh(V, F)
        h, T = validate_handles(V, h, T)
        return arap_deform(V, F, h, T, ArapOptions(energy=energy, protocol=protocol))
    s = warm_once(WARMED, ("fullres", energy, protocol), run)
    if uses_parallel_kernels(n_vertices):
        s += warm_once(WARMED, ("fullres", "parallel"), lambda *_: warm_parallel_kernels())
    return s

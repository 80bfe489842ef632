"""The paper's protocol of the full-resolution ARAP baselines (:mod:`baselines.fullres_arap`;
paper §4.1, Table 1): libigl's local/global from the rigid fit of the handles, stopped by
the largest vertex move (:func:`sshade.arap.paper_protocol.paper_deform`), and its warm-up.

It imports nothing of the converged solver, so these rows keep their code identity when
that solver changes (eval.run.code_identity). Named by
:data:`baselines.fullres_arap.PROTOCOL_MODULES`; docs/protocols.md.
"""
from __future__ import annotations

import numpy as np

from sshade.arap.paper_protocol import paper_deform
from sshade.mesh.validate import validate_handles, validate_mesh
from sshade.warmup_base import WARMED, warm_once

__all__ = ["solve", "warmup"]


def solve(method, V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray) -> tuple:
    """:func:`baselines.fullres_converged.solve`'s contract under the paper protocol (the
    arrays as there): ``(ArapResult of :func:`sshade.arap.paper_protocol.paper_deform`,
    {})``, no start info (the paper protocol starts from the rigid fit)."""
    return paper_deform(V, F, handles, targets, method.arap_options()), {}


def warmup(method, n_vertices: int | None = None) -> float:
    """Warm ``method``'s solve on :func:`sshade.warmup_base.tiny_problem`: libigl's set-up
    and the gradient test's kernels, once per energy and process (``n_vertices`` unused:
    libigl's iteration has no parallel variant to compile). Returns the seconds spent (0.0
    when warm)."""
    options = method.arap_options()

    def run(V, F, h, T):  # as the baselines' deform: validation, then the solve
        V, F = validate_mesh(V, F)
        h, T = validate_handles(V, h, T)
        return paper_deform(V, F, h, T, options)
    return warm_once(WARMED, ("fullres", method.energy, "paper"), run)

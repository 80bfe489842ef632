"""The paper's protocol of the full-resolution ARAP baselines (:mod:`baselines.fullres_arap`;
paper §4.1, Table 1): libigl's local/global from the rigid fit of the handles, stopped by
the largest vertex move (:func:`sshade.arap.paper_protocol.paper_deform`), and its warm-up.

It imports nothing of the converged solver, so these rows keep their code identity when
that solver changes (eval.run.code_identity). Named by
:data:`baselines.fullres_arap.PROTOCOL_MODULES`; docs/protocols.md.
"""
from __future__ import annotations

import numpy as np

from sshade.arap.paper_protocol import paper_deform, warm_paper

__all__ = ["solve", "warmup"]


def solve(method, V: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray) -> tuple:
    """:func:`baselines.fullres_converged.solve`'s contract under the paper protocol (the
    arrays as there): ``(ArapResult of :func:`sshade.arap.paper_protocol.paper_deform`,
    {})``, no start info (the paper protocol starts from the rigid fit)."""
    return paper_deform(V, F, handles, targets, method.arap_options()), {}


def warmup(method, n_vertices: int | None = None) -> float:
    """Warm ``method``'s solve (:func:`sshade.arap.paper_protocol.warm_paper` of its energy),
    once per energy and process (``n_vertices`` unused: libigl's iteration has no parallel
    variant to compile). Returns the seconds spent (0.0 when warm)."""
    return warm_paper(method.energy)

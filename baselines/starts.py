"""The starts of the full-resolution baselines' converged protocol, by name (:data:`STARTS`),
and the check of a baseline's start parameters when it is built (:func:`check_start`).

The starts themselves: :mod:`baselines.coarse_start`. This module imports no solver, so a
baseline under the paper protocol checks its parameters without holding one in its code
identity (eval.run.code_identity).
"""
from __future__ import annotations

import numpy as np

from sshade.errors import SShaDeError

__all__ = ["STARTS", "check_start"]

#: the converged protocol's starts: ``auto``, the rigid fit of the handles, the coarse start
STARTS = ("auto", "rigid", "coarse")


def check_start(name: str, start, coarse_n_low) -> tuple[str, int]:
    """A baseline's ``start`` (one of :data:`STARTS`) and ``coarse_n_low`` (an int >= 4),
    checked when it is built. Returns ``(start, coarse_n_low)``; raises SShaDeError
    naming ``name``, the parameter and its value."""
    if not isinstance(start, str) or start not in STARTS:
        raise SShaDeError(f"{name}: unknown start {start!r}; use one of {STARTS}")
    if isinstance(coarse_n_low, bool) or not isinstance(coarse_n_low, int | np.integer) or coarse_n_low < 4:
        raise SShaDeError(f"{name}: coarse_n_low must be an integer >= 4, got {coarse_n_low!r}")
    return start, int(coarse_n_low)

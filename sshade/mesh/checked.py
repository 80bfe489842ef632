"""A mesh checked once: the arrays a caller has already validated, trusted by the checks below it.

:func:`checked_mesh` is a context manager: inside it, :func:`sshade.mesh.validate.validate_mesh`
called on these very arrays (the same read-only objects, not equal copies) returns them
at once, with the half-edges built when they were checked, instead of running its
O(n + m) checks again (70 ms at 170k vertices). :func:`sshade.guard.run_method` validates
the mesh once, hands the method read-only copies and trusts them for the method's call,
so a method that checks its input (every public entry point does: a library user may
call it with raw arrays) does not pay for it again inside its timed region. Anchor:
scikit-learn's nested-validation skip (``skip_parameter_validation``). The trust is a
context variable: it does not reach another thread, and ends with the block.
"""
from __future__ import annotations

import contextlib
import contextvars

import numpy as np

__all__ = ["checked_mesh", "trusted_mesh"]

_TRUSTED: contextvars.ContextVar = contextvars.ContextVar("sshade_checked_mesh", default=None)


@contextlib.contextmanager
def checked_mesh(V: np.ndarray, F: np.ndarray, he, *, single_component: bool):
    """Trust ``(V, F)`` as checked within the block.

    Parameters
    ----------
    V : (n, 3) float64 read-only, C-contiguous; F : (m, 3) int64 read-only, C-contiguous:
        arrays :func:`sshade.mesh.validate.validate_mesh` passed (default ``allow_boundary``
        and ``area_tol``). he : their :class:`sshade.mesh.halfedge.HalfEdges`.
    single_component : bool, whether the mesh is one connected component (then a check
        that refuses several components is satisfied too).

    Raises
    ------
    ValueError if ``V`` or ``F`` is writeable (a method could change what was checked).
    """
    if V.flags.writeable or F.flags.writeable:
        raise ValueError("checked_mesh: V and F must be read-only")
    token = _TRUSTED.set((V, F, he, bool(single_component)))
    try:
        yield
    finally:
        _TRUSTED.reset(token)


def trusted_mesh(V, F, *, allow_components: bool, default_checks: bool):
    """``(V, F, he)`` writeable copies of ``V`` and ``F`` and their half-edges when they
    are the arrays of the enclosing :func:`checked_mesh` block, still read-only, and the
    check asked for is one they passed (``default_checks``: default ``allow_boundary`` and
    ``area_tol``; several components only where ``allow_components`` or the mesh is one
    component); else None. Copies, as ``validate_mesh`` makes of a read-only input."""
    t = _TRUSTED.get()
    if t is None or V is not t[0] or F is not t[1] or not default_checks:
        return None
    if V.flags.writeable or F.flags.writeable or not (allow_components or t[3]):
        return None
    return V.copy(), F.copy(), t[2]

"""The answer when the handles move rigidly: the rigid motion itself, under every protocol
and energy (:func:`rigid_motion`), without setting up any solver.

Shared by :class:`sshade.arap.local_global.ArapDeformer` and
:func:`sshade.arap.paper_protocol.paper_deform`; the fit is
:func:`sshade.arap.rigid.rigid_fit`.
"""
from __future__ import annotations

import numpy as np

from .result import ArapResult
from .rigid import rigid_fit

__all__ = ["rigid_motion"]


def rigid_motion(V: np.ndarray, handles: np.ndarray, targets: np.ndarray, diag: float,
                 protocol: str) -> ArapResult | None:
    """The rigid motion of the whole mesh when the handles' targets are one, else None.

    The handles move rigidly when the best rigid fit of ``V[handles]`` to ``targets``
    leaves no residual above ``1e-12 * diag``. The rigid motion (no distortion at all) is
    then the answer under both protocols. It is the minimiser wherever the cotangent
    weights are positive; on meshes with obtuse triangles libigl's weights turn negative
    and the raw energy could be lowered by distorting, which no user asks for. (It also
    avoids libigl's single-precision 3x3 polar decomposition adding ~1e-6 noise.)

    Parameters
    ----------
    V : (n, 3) float64 rest positions. handles : (h,) int64 vertex indices.
    targets : (h, 3) float64 positions. diag : float, the bounding-box diagonal of ``V``
        (mesh units). protocol : str, written to the result's ``info["protocol"]``.

    Returns
    -------
    ArapResult (``V`` the moved mesh (n, 3), 0 iterations, ``info["status"] = "rigid"``)
    or None.
    """
    R, t = rigid_fit(V[handles], targets)
    if not float(np.abs(V[handles] @ R.T + t - targets).max()) <= 1e-12 * diag:  # NaN: not rigid
        return None
    return ArapResult(V=V @ R.T + t, iterations=0, converged=True, last_move=0.0, precompute_s=0.0, solve_s=0.0,
                      info={"rigid": True, "protocol": protocol, "status": "rigid"})

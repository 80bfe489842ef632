"""Best rigid motion between corresponding point sets (Kabsch / Umeyama without scaling):
the start of every ARAP solve (a rigid motion of the handles is reproduced exactly) and
the rigid alignment of :mod:`sshade.components`.
"""
from __future__ import annotations

import numpy as np

__all__ = ["rigid_fit"]


def rigid_fit(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best rigid motion (rotation, no reflection) taking points ``P`` to ``Q``.

    Kabsch/Umeyama without scaling: minimises ``sum ||R p_i + t - q_i||^2``.

    Parameters
    ----------
    P, Q : (h, 3) float64 corresponding points, h >= 1.

    Returns
    -------
    R : (3, 3) float64 rotation, det(R) = +1. With fewer than 3 non-collinear points the
        rotation is the minimum-norm one SVD gives (identity for a single point).
    t : (3,) float64 translation.

    Examples
    --------
    >>> P = np.random.default_rng(0).normal(size=(10, 3))
    >>> R, t = rigid_fit(P, P + 1.0)
    >>> np.allclose(R, np.eye(3)), np.allclose(t, 1.0)
    (True, True)
    """
    P = np.asarray(P, np.float64)
    Q = np.asarray(Q, np.float64)
    cp, cq = P.mean(0), Q.mean(0)
    if len(P) == 1:
        return np.eye(3), cq - cp
    H = (P - cp).T @ (Q - cq)
    U, S, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    if d == 0:
        d = 1.0
    D = np.diag([1.0, 1.0, d])
    R = Vt.T @ D @ U.T
    return R, cq - R @ cp

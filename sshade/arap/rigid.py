"""Best rigid motion between corresponding point sets (Kabsch / Umeyama without scaling):
the start of every ARAP solve (a rigid motion of the handles is reproduced exactly) and
the rigid alignment of :mod:`sshade.components`.

The least-squares rotation is unique when the points span a plane or more. For a
degenerate set (collinear points, among them every pair of points; coincident points) a
whole family of rotations fits equally well, and :func:`rigid_fit` returns the one
nearest the identity, so a mesh driven by two handles is not spun about their axis.
"""
from __future__ import annotations

import numpy as np

__all__ = ["rigid_fit", "minimal_rotation", "RANK_TOL"]

#: A point set counts as collinear when the second singular value of its cross-covariance
#: is at most ``RANK_TOL`` times the first. Those singular values go as the squares of
#: the points' spreads, so 1e-10 means a spread across the best-fit line below about 1e-5
#: of the spread along it: exact lines and lines rounded to float32 (relative 1e-7) are
#: caught, any set spanning a plane by more than that is fitted as before. The
#: cross-covariance counts as zero (any rotation fits) when its largest singular value is
#: at most ``RANK_TOL`` times the product of the two sets' centred Frobenius norms.
RANK_TOL = 1e-10


def rigid_fit(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best rigid motion (rotation, no reflection) taking points ``P`` to ``Q``.

    Minimises ``sum_i ||R p_i + t - q_i||^2`` over rotations ``R`` and translations ``t``:
    ``t = mean(Q) - R mean(P)`` and ``R`` maximises ``trace(R H)``, ``H = Pc^T Qc`` the
    cross-covariance of the centred sets (Kabsch 1976; Umeyama 1991 without scaling),
    from the SVD ``H = U S V^T``. The rule by the rank of ``H`` (:data:`RANK_TOL`):

    - rank >= 2 (the points span a plane or more, either set): ``R = V diag(1, 1, d)
      U^T``, ``d = sign det(V U^T)``, the unique Kabsch rotation;
    - rank 1 (either set collinear, e.g. two points): every rotation taking the first
      left singular vector ``u1`` to the first right one ``v1`` fits equally well; ``R`` is
      the one nearest the identity (smallest angle, hence smallest ``||R - I||_F``): the
      minimal rotation between the two directions, about ``u1 x v1`` by their angle.
      Antiparallel directions: a half turn about the axis perpendicular to ``u1`` and to
      the coordinate axis least aligned with it. Same directions: the identity;
    - rank 0 (``H`` about zero, e.g. either set a single or repeated point): the identity.

    Parameters
    ----------
    P, Q : (h, 3) float64 corresponding points, h >= 1.

    Returns
    -------
    R : (3, 3) float64 rotation, det(R) = +1.
    t : (3,) float64 translation.

    Examples
    --------
    >>> P = np.random.default_rng(0).normal(size=(10, 3))
    >>> R, t = rigid_fit(P, P + 1.0)
    >>> np.allclose(R, np.eye(3)), np.allclose(t, 1.0)
    (True, True)

    Two points: the smallest rotation turning the segment, none about it.

    >>> R, t = rigid_fit(np.array([[0., 0, 0], [0, 1, 0]]), np.array([[0., 0, 0], [1, 1, 0]]))
    >>> bool(np.allclose(R @ [0, 0, 1], [0, 0, 1]))
    True
    """
    P = np.asarray(P, np.float64)
    Q = np.asarray(Q, np.float64)
    cp, cq = P.mean(0), Q.mean(0)
    if len(P) == 1:
        return np.eye(3), cq - cp
    Pc, Qc = P - cp, Q - cq
    H = Pc.T @ Qc
    U, S, Vt = np.linalg.svd(H)
    if S[1] > RANK_TOL * S[0]:  # rank >= 2: Kabsch
        d = np.sign(np.linalg.det(Vt.T @ U.T))
        if d == 0:
            d = 1.0
        D = np.diag([1.0, 1.0, d])
        R = Vt.T @ D @ U.T
        return R, cq - R @ cp
    coincident = not np.ptp(P, axis=0).any() or not np.ptp(Q, axis=0).any()
    if coincident or not S[0] > RANK_TOL * np.linalg.norm(Pc) * np.linalg.norm(Qc):
        R = np.eye(3)  # rank 0: every rotation fits
    else:
        R = minimal_rotation(U[:, 0], Vt[0])
    return R, cq - R @ cp


def minimal_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction ``a`` to direction ``b``.

    Parameters
    ----------
    a, b : (3,) float64 nonzero vectors (normalised here).

    Returns
    -------
    (3, 3) float64 rotation about ``a x b`` by the angle between ``a`` and ``b``
    (Rodrigues' formula, the angle from ``atan2(|a x b|, a . b)``). Parallel directions
    (``|a x b|`` below 1e-12): the identity; antiparallel: a half turn about the axis
    perpendicular to ``a`` and to the coordinate axis least aligned with ``a``.

    Examples
    --------
    >>> R = minimal_rotation(np.array([1., 0, 0]), np.array([0., 1, 0]))
    >>> bool(np.allclose(R @ [1, 0, 0], [0, 1, 0]) and np.allclose(R @ [0, 0, 1], [0, 0, 1]))
    True
    """
    a = np.asarray(a, np.float64) / np.linalg.norm(a)
    b = np.asarray(b, np.float64) / np.linalg.norm(b)
    w = np.cross(a, b)
    s, c = float(np.linalg.norm(w)), float(a @ b)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        k = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        k /= np.linalg.norm(k)
        return 2.0 * np.outer(k, k) - np.eye(3)  # half turn about k
    k = w / s
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    theta = np.arctan2(s, c)
    return np.eye(3) + np.sin(theta) * K + (1.0 - np.cos(theta)) * (K @ K)

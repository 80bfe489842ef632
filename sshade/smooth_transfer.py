"""The transfer with deformation gradients that vary smoothly across the low-res mesh
(``transfer="vertex"``; an alternative to Algorithm 1's one frame per triangle, §3.2).

Each low-res triangle's deformation gradient J_t (its edges and unit normal at rest to
those deformed) is averaged, area-weighted, at its corners (J_k); a high-res vertex v
anchored at a = sum_k b_k N_k is rebuilt as a' + Jbar (v - a) + 1/2 sum_k b_k J_k (a - N_k),
Jbar = sum_k b_k J_k: the mean of the piecewise-linear map and of the corners' affine
maps blended, which is exact for a quadratic deformation with exact J_k (the two
interpolants' errors are opposite). Measured: docs/differences.md M10.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from .errors import SShaDeError
from .lrf import transfer as frame_transfer

__all__ = ["triangle_jacobians", "vertex_jacobians", "smooth_decode", "rebuild", "TRANSFERS"]

#: How a high-res vertex follows the low-res mesh: one frame per triangle (Alg. 1,
#: :mod:`sshade.lrf`) or the corners' deformation gradients blended (this module).
TRANSFERS = ("triangle", "vertex")


def triangle_jacobians(VN: np.ndarray, VN_def: np.ndarray, FN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The deformation gradient of each low-res triangle, its unit normal taken to the
    deformed unit normal, and the rest areas.

    Parameters
    ----------
    VN, VN_def : (k, 3) float64 rest / deformed low-res positions. FN : (t, 3) int64.

    Returns
    -------
    J : (t, 3, 3) float64 with ``J @ [e1 e2 n] = [e1' e2' n']`` (e1, e2 the edges from
    corner 0, n the unit normal; a rotation for a rigid motion). A : (t,) rest areas.

    Raises
    ------
    SShaDeError on a degenerate (zero-area) triangle, rest or deformed.
    """
    def frame(P):
        e1, e2 = P[FN[:, 1]] - P[FN[:, 0]], P[FN[:, 2]] - P[FN[:, 0]]
        n = np.cross(e1, e2)
        dbl = np.linalg.norm(n, axis=1)
        if not (np.isfinite(dbl).all() and (dbl > 0).all()):
            raise SShaDeError(f"smooth transfer: {int((~(dbl > 0)).sum())} degenerate low-res triangles")
        return np.stack([e1, e2, n / dbl[:, None]], axis=2), dbl / 2
    M, A = frame(VN)
    Md, _ = frame(VN_def)
    return Md @ np.linalg.inv(M), A


def vertex_jacobians(VN: np.ndarray, VN_def: np.ndarray, FN: np.ndarray) -> np.ndarray:
    """J_k: the area-weighted mean of :func:`triangle_jacobians` over the triangles at
    each low-res vertex.

    Parameters
    ----------
    VN, VN_def : (k, 3) float64 rest / deformed low-res positions. FN : (t, 3) int64.

    Returns
    -------
    (k, 3, 3) float64, C-contiguous (a vertex in no triangle: zeros).
    """
    J, A = triangle_jacobians(VN, VN_def, FN)
    k, t = len(VN), len(FN)
    S = sp.csr_matrix((np.repeat(A, 3), (FN.ravel(), np.repeat(np.arange(t), 3))), shape=(k, t))  # corner x triangle
    w = np.asarray(S.sum(axis=1)).ravel()
    out = S @ J.reshape(t, 9)
    out[w > 0] /= w[w > 0, None]
    return np.ascontiguousarray(out.reshape(k, 3, 3))


def smooth_decode(V: np.ndarray, tri: np.ndarray, bary: np.ndarray | None, VN: np.ndarray, VN_def: np.ndarray,
                  FN: np.ndarray, *, Jv: np.ndarray | None = None) -> np.ndarray:
    """Rebuild the high-res vertices on the deformed low-res mesh with the corners'
    deformation gradients (module docstring; ``transfer="vertex"``).

    Parameters
    ----------
    V : (n, 3) float64 high-res rest positions. tri : (n,) int triangle P(v).
    bary : (n, 3) float64 the anchor's barycentric coordinates (the projection's), or
        None for the barycenter. VN, VN_def : (k, 3) float64 rest / deformed low-res
        positions. FN : (t, 3) int64.
    Jv : (k, 3, 3) float64 or None, :func:`vertex_jacobians` of ``(VN, VN_def, FN)``
        when already computed.

    Returns
    -------
    (n, 3) float64 deformed positions. A rigid motion of the low-res mesh is reproduced
    exactly; a vertex at a low-res vertex goes exactly to its deformed position.
    """
    if Jv is None:
        Jv = vertex_jacobians(VN, VN_def, FN)
    w = np.full((1, 3), 1.0 / 3.0) if bary is None else np.ascontiguousarray(bary, np.float64)
    out = np.empty((len(tri), 3))
    _smooth_kernel(np.ascontiguousarray(V, np.float64), np.ascontiguousarray(tri, np.int64), w, bary is not None,
                   np.ascontiguousarray(VN, np.float64), np.ascontiguousarray(VN_def, np.float64),
                   np.ascontiguousarray(FN, np.int64), np.ascontiguousarray(Jv, np.float64), out)
    return out


@njit(cache=True, nogil=True)
def _smooth_kernel(V, tri, bary, per_vertex, P, Q, FN, Jv, out):
    """``out[i] = a' + sum_k b_k J_k (V[i] - a) + 1/2 sum_k b_k J_k (a - P_k)``, a and a'
    the anchor on P and Q: :func:`smooth_decode` in one pass."""
    for i in range(len(tri)):
        t = tri[i]
        r = i if per_vertex else 0
        a = np.zeros(3)
        ad = np.zeros(3)
        for k in range(3):
            for d in range(3):
                a[d] += bary[r, k] * P[FN[t, k], d]
                ad[d] += bary[r, k] * Q[FN[t, k], d]
        for d in range(3):
            out[i, d] = ad[d]
        for k in range(3):
            c = FN[t, k]
            b = bary[r, k]
            for d in range(3):
                s = 0.0
                for e in range(3):
                    s += Jv[c, d, e] * ((V[i, e] - a[e]) + 0.5 * (a[e] - P[c, e]))
                out[i, d] += b * s


def rebuild(V: np.ndarray, tri: np.ndarray, bary: np.ndarray | None, VN: np.ndarray, VN_def: np.ndarray,
            FN: np.ndarray, *, transfer: str = "vertex", gradient: str = "normalized") -> np.ndarray:
    """The high-res vertices ``V`` following ``VN -> VN_def`` by the chosen transfer.

    Parameters
    ----------
    V : (n, 3) float64 high-res rest positions. tri : (n,) int triangle P(v). bary : (n, 3)
    float64 the anchor's barycentric coordinates, or None for the barycenter. VN, VN_def :
    (k, 3) float64 rest / deformed low-res positions. FN : (t, 3) int64.
    transfer : ``"vertex"`` (:func:`smooth_decode`) or ``"triangle"`` (Alg. 1,
        :func:`sshade.lrf.transfer` with ``gradient``).

    Returns
    -------
    (n, 3) float64 deformed positions.
    """
    if transfer == "vertex":
        return smooth_decode(V, tri, bary, VN, VN_def, FN)
    return frame_transfer(V, tri, VN, VN_def, FN, gradient=gradient, bary=bary)

"""The transfer with deformation gradients that vary smoothly across the low-res mesh
(``transfer="vertex"``; an alternative to Algorithm 1's one frame per triangle, §3.2).

Each low-res triangle's deformation gradient J_t (its edges and unit normal at rest to
those deformed) is averaged, area-weighted, at its corners (J_k); a high-res vertex v
anchored at a = sum_k b_k N_k is rebuilt as a' + Jbar (v - a) + 1/2 sum_k b_k J_k (a - N_k),
Jbar = sum_k b_k J_k: the mean of the piecewise-linear map and of the corners' affine
maps blended, which is exact for a quadratic deformation with exact J_k (the two
interpolants' errors are opposite). Measured: docs/differences.md M10. It is computed
regrouped per corner, v' = sum_k b_k (t_k + J_k g), g = v - a/2 made once at rest
(:func:`smooth_offsets`) and t_k = N'_k - J_k N_k / 2 once per deformed mesh
(:func:`corner_maps`): a third of the rest data per vertex (docs/implementation.md).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from numba import njit

from .errors import SShaDeError
from .lrf import anchor_weights, decode_rows
from .lrf import transfer as frame_transfer

__all__ = ["triangle_jacobians", "JacobianRest", "jacobian_rest", "vertex_jacobians", "smooth_offsets", "corner_maps",
           "smooth_decode", "smooth_decode_with", "rebuild", "TRANSFERS"]

#: How a high-res vertex follows the low-res mesh: one frame per triangle (Alg. 1,
#: :mod:`sshade.lrf`) or the corners' deformation gradients blended (this module).
TRANSFERS = ("triangle", "vertex")

#: What :func:`_smooth_kernel` is given and makes: the rest offsets given (decode), the
#: rest positions given (the offsets made inline, then decode), or the offsets alone.
_GIVEN, _FROM_REST, _OFFSETS = 0, 1, 2
_NO_MAPS, _NO_REST = np.zeros((0, 3, 4)), np.zeros((0, 3))


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
    M, A = _edge_frames(VN, FN)
    Md, _ = _edge_frames(VN_def, FN)
    return Md @ np.linalg.inv(M), A


def _edge_frames(P: np.ndarray, FN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[e1 e2 n]`` (t, 3, 3) (columns: the edges from corner 0 and the unit normal) and
    the areas (t,) of the triangles ``FN`` on ``P``; SShaDeError on a degenerate one."""
    e1, e2 = P[FN[:, 1]] - P[FN[:, 0]], P[FN[:, 2]] - P[FN[:, 0]]
    n = np.cross(e1, e2)
    dbl = np.linalg.norm(n, axis=1)
    if not (np.isfinite(dbl).all() and (dbl > 0).all()):
        raise SShaDeError(f"smooth transfer: {int((~(dbl > 0)).sum())} degenerate low-res triangles")
    return np.stack([e1, e2, n / dbl[:, None]], axis=2), dbl / 2


class JacobianRest(NamedTuple):
    """What :func:`vertex_jacobians` needs of the rest low-res mesh (:func:`jacobian_rest`):
    ``Minv`` (t, 3, 3) the inverse rest frames ``[e1 e2 n]^-1``, ``S`` (k, t) sparse
    corner-by-triangle rest areas, ``w`` (k,) their sums, ``has`` (k,) bool ``w > 0``."""

    Minv: np.ndarray
    S: sp.csr_matrix
    w: np.ndarray
    has: np.ndarray


def jacobian_rest(VN: np.ndarray, FN: np.ndarray) -> JacobianRest:
    """The rest-pose part of :func:`vertex_jacobians`, made once for many deformed meshes.

    Parameters
    ----------
    VN : (k, 3) float64 rest low-res positions. FN : (t, 3) int64.

    Returns
    -------
    :class:`JacobianRest`.

    Raises
    ------
    SShaDeError on a degenerate (zero-area) rest triangle.
    """
    M, A = _edge_frames(VN, FN)
    k, t = len(VN), len(FN)
    S = sp.csr_matrix((np.repeat(A, 3), (FN.ravel(), np.repeat(np.arange(t), 3))), shape=(k, t))  # corner x triangle
    w = np.asarray(S.sum(axis=1)).ravel()
    return JacobianRest(np.linalg.inv(M), S, w, w > 0)


def vertex_jacobians(VN: np.ndarray, VN_def: np.ndarray, FN: np.ndarray, *,
                     rest: JacobianRest | None = None) -> np.ndarray:
    """J_k: the area-weighted mean of :func:`triangle_jacobians` over the triangles at
    each low-res vertex (§3.2's transfer, ``transfer="vertex"``).

    Parameters
    ----------
    VN, VN_def : (k, 3) float64 rest / deformed low-res positions. FN : (t, 3) int64.
    rest : :func:`jacobian_rest` of ``(VN, FN)`` when made already (the same numbers).

    Returns
    -------
    (k, 3, 3) float64, C-contiguous (a vertex in no triangle: zeros).

    Raises
    ------
    SShaDeError on a degenerate (zero-area) triangle, rest or deformed.
    """
    if rest is None:
        rest = jacobian_rest(VN, FN)
    out = np.empty((len(VN), 3, 3))
    bad = _vertex_jacobians_kernel(np.ascontiguousarray(VN_def, np.float64), np.ascontiguousarray(FN, np.int64),
                                   rest.Minv, rest.S.indptr, rest.S.indices, rest.S.data, rest.w, out)
    if bad:
        raise SShaDeError(f"smooth transfer: {bad} degenerate low-res triangles")
    return out


@njit(cache=True, nogil=True)
def _vertex_jacobians_kernel(Q, FN, Minv, ptr, idx, val, w, out):
    """:func:`vertex_jacobians` in one pass over the triangles (each one's ``[e1' e2' n']
    Minv``, ``Minv`` (t, 3, 3)) and one over the corners (their area-weighted sum, the
    CSR matrix ``(ptr, idx, val)`` (k, t) in its stored order, over ``w`` where positive):
    into ``out`` (k, 3, 3); returns the number of degenerate deformed triangles."""
    J = np.empty((len(FN), 3, 3))
    M = np.empty((3, 3))
    bad = 0
    for f in range(len(FN)):
        c0, c1, c2 = FN[f, 0], FN[f, 1], FN[f, 2]
        for d in range(3):
            M[d, 0] = Q[c1, d] - Q[c0, d]
            M[d, 1] = Q[c2, d] - Q[c0, d]
        n0 = M[1, 0] * M[2, 1] - M[2, 0] * M[1, 1]
        n1 = M[2, 0] * M[0, 1] - M[0, 0] * M[2, 1]
        n2 = M[0, 0] * M[1, 1] - M[1, 0] * M[0, 1]
        dbl = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if not (dbl > 0 and np.isfinite(dbl)):
            bad += 1
            continue
        M[0, 2], M[1, 2], M[2, 2] = n0 / dbl, n1 / dbl, n2 / dbl
        for a in range(3):
            for b in range(3):
                J[f, a, b] = (M[a, 0] * Minv[f, 0, b] + M[a, 1] * Minv[f, 1, b]) + M[a, 2] * Minv[f, 2, b]
    if bad:
        return bad
    acc = np.empty(9)
    for k in range(len(out)):
        acc[:] = 0.0
        for j in range(ptr[k], ptr[k + 1]):
            f, v = idx[j], val[j]
            for a in range(3):
                for b in range(3):
                    acc[3 * a + b] += v * J[f, a, b]
        s = w[k] if w[k] > 0 else 1.0
        for a in range(3):
            for b in range(3):
                out[k, a, b] = acc[3 * a + b] / s
    return 0


def smooth_offsets(V: np.ndarray, tri: np.ndarray, bary: np.ndarray | None, VN: np.ndarray,
                   FN: np.ndarray) -> np.ndarray:
    """The rest-pose part of :func:`smooth_decode` at each high-res vertex: the vector its
    three corners' gradients are applied to, ``g = v - a / 2`` (a the anchor, at rest).
    The module formula regrouped per corner: ``v' = sum_k b_k (t_k + J_k g)`` with
    ``t_k = N'_k - J_k N_k / 2`` (:func:`corner_maps`), since ``sum_k b_k = 1``.

    Parameters
    ----------
    V : (n, 3) float64 high-res rest positions. tri : (n,) int triangle P(v).
    bary : (n, 3) float64 the anchor's barycentric coordinates, or None for the
        barycenter. VN : (k, 3) float64 rest low-res positions. FN : (t, 3) int64.

    Returns
    -------
    (n, 3) float64, C-contiguous: known before the targets, made once by
    :func:`sshade.prepare` and given to :func:`smooth_decode_with` every frame.
    """
    return _from_rest(_NO_MAPS, V, tri, bary, VN, FN, _OFFSETS)


def corner_maps(Jv: np.ndarray, VN: np.ndarray, VN_def: np.ndarray) -> np.ndarray:
    """Each low-res vertex's affine map of :func:`smooth_decode`: ``[J_k | t_k]`` with
    ``t_k = N'_k - J_k N_k / 2`` (:func:`smooth_offsets`), made once per deformed mesh.

    Parameters
    ----------
    Jv : (k, 3, 3) float64 :func:`vertex_jacobians`. VN, VN_def : (k, 3) float64 rest /
        deformed low-res positions.

    Returns
    -------
    (k, 3, 4) float64, C-contiguous.
    """
    A = np.empty((len(VN), 3, 4))
    A[:, :, :3] = Jv
    A[:, :, 3] = VN_def - 0.5 * np.einsum("kde,ke->kd", Jv, VN)
    return A


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
    (n, 3) float64 deformed positions: :func:`smooth_decode_with` of :func:`corner_maps`
    and :func:`smooth_offsets`. A rigid motion of the low-res mesh is reproduced to
    rounding; a vertex at a low-res vertex goes to its deformed position.
    """
    if Jv is None:
        Jv = vertex_jacobians(VN, VN_def, FN)
    return _from_rest(corner_maps(Jv, VN, VN_def), V, tri, bary, VN, FN, _FROM_REST)


def _from_rest(A, V, tri, bary, VN, FN, mode) -> np.ndarray:
    """:func:`_smooth_kernel` over every high-res vertex from the rest positions (``mode``
    :data:`_OFFSETS` or :data:`_FROM_REST`; arrays as :func:`smooth_decode`'s, ``A`` the
    corners' maps): a new (n, 3) float64 array."""
    out = np.empty((len(tri), 3))
    _smooth_kernel(A, np.ascontiguousarray(V, np.float64), np.ascontiguousarray(VN, np.float64), mode,
                   np.ascontiguousarray(tri, np.int32), *anchor_weights(bary), np.ascontiguousarray(FN, np.int64),
                   0, len(tri), False, out)
    return out


def smooth_decode_with(A: np.ndarray, g: np.ndarray, tri: np.ndarray, bary: np.ndarray | None,
                       FN: np.ndarray, *, rows=None, out: np.ndarray | None = None,
                       add: bool = False) -> np.ndarray:
    """:func:`smooth_decode` with the corners' maps and the rest offsets given, for some
    rows, into or onto ``out`` (as :func:`sshade.lrf.decode_with_frames`).

    Parameters
    ----------
    A : (k, 3, 4) float64 :func:`corner_maps`. g : (n, 3) float64
        :func:`smooth_offsets`. tri : (n,) int triangle P(v). bary : (n, 3) float64 or
        None, as given to :func:`smooth_offsets`. FN : (t, 3) int64.
    rows, out, add : as :func:`sshade.lrf.decode_with_frames` (None, a slice with step 1
        or (r,) int indices; None or an (r, 3) C-contiguous float64 array; add onto it).

    Returns
    -------
    ``out`` (r, 3), r the number of rows. The kernel releases the GIL.

    Raises
    ------
    SShaDeError when ``out`` has the wrong shape or layout, ``add`` without ``out``, or a
    slice of rows with a step (:func:`sshade.lrf.decode_rows`).
    """
    idx, lo, hi, out = decode_rows(rows, len(tri), out, add, "smooth_decode_with")
    g_, tri_, bary_ = (g, tri, bary) if idx is None else (g[idx], tri[idx], None if bary is None else bary[idx])
    w, per_vertex = anchor_weights(bary_)
    _smooth_kernel(np.ascontiguousarray(A, np.float64), np.ascontiguousarray(g_, np.float64), _NO_REST, _GIVEN,
                   np.ascontiguousarray(tri_, np.int32), w, per_vertex, np.ascontiguousarray(FN, np.int64),
                   lo, hi, add, out)
    return out


@njit(cache=True, nogil=True, inline="always")
def _corners(i, tri, bary, per_vertex, FN):
    """The corners of vertex ``i``'s triangle ``tri[i]`` and its anchor weights (``bary[i]``
    when ``per_vertex``, else ``bary[0]``): ``(c0, c1, c2, w0, w1, w2)``."""
    t = tri[i]
    r = i if per_vertex else 0
    return FN[t, 0], FN[t, 1], FN[t, 2], bary[r, 0], bary[r, 1], bary[r, 2]


@njit(cache=True, nogil=True)
def _smooth_kernel(A, X, P, mode, tri, bary, per_vertex, FN, lo, hi, add, out):
    """For ``lo <= i < hi`` (c_k the corners of ``tri[i]``, ``w = bary[i]`` or ``bary[0]``):
    ``g = X[i]`` (``mode`` :data:`_GIVEN`) or ``g = X[i] - a / 2``, ``a = sum_k w_k P[c_k]``
    (:data:`_FROM_REST`, :data:`_OFFSETS`); then ``out[i - lo] (+)= sum_k w_k (A[c_k, :, 3]
    + A[c_k, :, :3] g)``, or ``out[i - lo] = g`` (:data:`_OFFSETS`): :func:`smooth_offsets`
    and :func:`smooth_decode_with` in one pass, in scalars, corner 0, 1, 2 in order."""
    for i in range(lo, hi):
        c0, c1, c2, w0, w1, w2 = _corners(i, tri, bary, per_vertex, FN)
        g0, g1, g2 = X[i, 0], X[i, 1], X[i, 2]
        if mode != _GIVEN:
            g0 -= 0.5 * (((0.0 + w0 * P[c0, 0]) + w1 * P[c1, 0]) + w2 * P[c2, 0])
            g1 -= 0.5 * (((0.0 + w0 * P[c0, 1]) + w1 * P[c1, 1]) + w2 * P[c2, 1])
            g2 -= 0.5 * (((0.0 + w0 * P[c0, 2]) + w1 * P[c1, 2]) + w2 * P[c2, 2])
        if mode == _OFFSETS:
            out[i - lo, 0], out[i - lo, 1], out[i - lo, 2] = g0, g1, g2
            continue
        for d in range(3):
            v = w0 * (((A[c0, d, 3] + A[c0, d, 0] * g0) + A[c0, d, 1] * g1) + A[c0, d, 2] * g2)
            v += w1 * (((A[c1, d, 3] + A[c1, d, 0] * g0) + A[c1, d, 1] * g1) + A[c1, d, 2] * g2)
            v += w2 * (((A[c2, d, 3] + A[c2, d, 0] * g0) + A[c2, d, 1] * g1) + A[c2, d, 2] * g2)
            if add:
                out[i - lo, d] += v
            else:
                out[i - lo, d] = v


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

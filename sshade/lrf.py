"""Per-triangle local reference frames and the deformation transfer (paper §3.2,
Algorithm 1 "LRFT").

For a low-res triangle t, L_t = (g_t, w_t, n_t): g_t the gradient on t of a rest-pose
coordinate (as in the paper with ``gradient="raw"``, of unit length with
``"normalized"``), n_t the unit normal, w_t = g_t x n_t. A high-res vertex v with
P(v) = t is stored as v_t = L_t^-1 (v - a(v)) and rebuilt as v' = L'_t v_t + a'(v), the
anchor a(v) the barycenter b_t (``anchor="barycenter"``, paper) or v's projection onto t
(``"projection"``, the default; docs/differences.md). Details: docs/implementation.md
("Implementation notes: sshade/lrf.py").
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .errors import SShaDeError

__all__ = ["frame_functions", "triangle_gradients", "local_frames", "anchor_points", "encode", "decode",
           "deformed_frames", "decode_with_frames", "decode_rows", "anchor_weights",
           "transfer", "GRADIENTS", "ANCHORS"]

GRADIENTS = ("normalized", "raw")
#: Where a high-res vertex is anchored in its triangle: its projection (default) or the
#: barycenter b_t (paper Alg. 1).
ANCHORS = ("projection", "barycenter")


def frame_functions(VN: np.ndarray, FN: np.ndarray, *, primary: int = 0, min_gradient: float = 0.5) -> np.ndarray:
    """Per-triangle scalar function f: which rest coordinate (0=x, 1=y, 2=z) is used.

    Parameters
    ----------
    VN : (k, 3) float64 rest low-res positions. FN : (t, 3) int64.
    primary : int, the coordinate used where its gradient is large enough.
    min_gradient : float in (0, 1): |grad x_a| on a triangle is sin(angle(axis a, n_t));
        below this the coordinate with the largest gradient is used (paper §3.2 fallback).

    Returns
    -------
    axis : (t,) int64.
    """
    n = np.cross(VN[FN[:, 1]] - VN[FN[:, 0]], VN[FN[:, 2]] - VN[FN[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    gmag = np.sqrt(np.clip(1.0 - n * n, 0.0, None))  # |grad of coordinate a| on each triangle
    axis = np.full(len(FN), primary, np.int64)
    weak = gmag[:, primary] < min_gradient
    axis[weak] = gmag[weak].argmax(axis=1)
    return axis


def triangle_gradients(P: np.ndarray, FN: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gradient of a piecewise-linear function on each triangle, unit normals, barycenters.

    Parameters
    ----------
    P : (k, 3) float64 positions. FN : (t, 3) int64. f : (t, 3) float64, the function's
        values at each triangle's three corners.

    Returns
    -------
    g : (t, 3) gradients (units of f per mesh unit); n : (t, 3) unit normals;
    b : (t, 3) barycenters.

    Raises
    ------
    SShaDeError on a degenerate (zero-area) triangle.
    """
    a, b_, c = P[FN[:, 0]], P[FN[:, 1]], P[FN[:, 2]]
    nn = np.cross(b_ - a, c - a)
    dbl = np.linalg.norm(nn, axis=1)
    if (dbl <= 0).any() or not np.isfinite(dbl).all():
        raise SShaDeError(f"LRF: {int((dbl <= 0).sum())} degenerate low-res triangles (zero area)")
    n = nn / dbl[:, None]
    # grad phi_i = n x e_i / (2A), e_i the edge opposite corner i (counter-clockwise)
    e0, e1, e2 = c - b_, a - c, b_ - a
    g = (f[:, 0:1] * np.cross(n, e0) + f[:, 1:2] * np.cross(n, e1) + f[:, 2:3] * np.cross(n, e2)) / dbl[:, None]
    return g, n, (a + b_ + c) / 3.0


def local_frames(P: np.ndarray, FN: np.ndarray, f: np.ndarray,
                 gradient: str = "normalized") -> tuple[np.ndarray, np.ndarray]:
    """L_t = (g_t, g_t x n_t, n_t) per triangle (paper §3.2 eq. for L_t).

    Parameters
    ----------
    P : (k, 3) positions (N or N'). FN : (t, 3). f : (t, 3) corner values of the frame
        function (the same values for N and N': carried by the correspondence).
    gradient : ``"normalized"`` (orthonormal frames) or ``"raw"`` (paper).

    Returns
    -------
    L : (t, 3, 3) with columns g, w, n. b : (t, 3) barycenters.
    """
    if gradient not in GRADIENTS:
        raise SShaDeError(f"unknown gradient mode {gradient!r}; use one of {GRADIENTS}")
    g, n, b = triangle_gradients(P, FN, f)
    if gradient == "normalized":
        gl = np.linalg.norm(g, axis=1, keepdims=True)
        if (gl <= 1e-300).any():
            raise SShaDeError("LRF: zero gradient on a triangle (frame function constant there)")
        g = g / gl
    w = np.cross(g, n)
    return np.stack([g, w, n], axis=2), b


def _corner_values(VN_rest: np.ndarray, FN: np.ndarray, axis: np.ndarray) -> np.ndarray:
    return VN_rest[FN, axis[:, None]]  # (t, 3): rest coordinate `axis[t]` at each corner


def anchor_points(P: np.ndarray, FN: np.ndarray, tri: np.ndarray, bary: np.ndarray | None) -> np.ndarray:
    """The anchor of each high-res vertex in its triangle, on positions ``P``.

    Parameters
    ----------
    P : (k, 3) low-res positions (N or N'). FN : (t, 3). tri : (n,) int triangle P(v).
    bary : (n, 3) barycentric coordinates of each anchor in its triangle (the
        projection's, ``anchor="projection"``), or None for the barycenters b_t (paper).

    Returns
    -------
    (n, 3) float64 points ``sum_i bary[:, i] * P[FN[tri, i]]``.
    """
    C = P[FN[tri]]  # (n, 3 corners, 3)
    if bary is None:
        return C.mean(axis=1)
    return np.einsum("ni,nij->nj", bary, C)


def encode(V: np.ndarray, tri: np.ndarray, VN: np.ndarray, FN: np.ndarray, axis: np.ndarray,
           gradient: str = "normalized", bary: np.ndarray | None = None) -> np.ndarray:
    """Local coordinates v_t = L_t^-1 (v - a(v)) of each high-res vertex (Alg. 1, line 11,
    where the anchor a(v) is the barycenter b_t).

    Parameters
    ----------
    V : (n, 3) high-res positions. tri : (n,) int64 triangle P(v).
    VN : (k, 3) rest low-res positions. FN : (t, 3). axis : (t,) frame function per triangle.
    bary : (n, 3) or None, the anchor's barycentric coordinates (:func:`anchor_points`;
        None: the barycenter, as the paper).

    Returns
    -------
    C : (n, 3) float64 local coordinates.
    """
    L, _ = local_frames(VN, FN, _corner_values(VN, FN, axis), gradient)
    Linv = np.linalg.inv(L) if gradient == "raw" else np.transpose(L, (0, 2, 1))
    out = np.empty((len(tri), 3))
    _encode_kernel(np.ascontiguousarray(Linv, np.float64), np.ascontiguousarray(V, np.float64),
                   np.ascontiguousarray(tri, np.int32), *anchor_weights(bary),
                   np.ascontiguousarray(VN, np.float64), np.ascontiguousarray(FN, np.int64), out)
    return out


def anchor_weights(bary: np.ndarray | None) -> tuple[np.ndarray, bool]:
    """The decoding kernels' anchor weights (§3.2, the anchor a(v) of :func:`anchor_points`).

    Parameters
    ----------
    bary : (n, 3) float64 barycentric coordinates, or None for the barycenter (Alg. 1).

    Returns
    -------
    ``(bary (n, 3) C-contiguous float64, True)``, or the barycenter's thirds ``((1, 3),
    False)`` when ``bary`` is None (the flag: one row per vertex).
    """
    if bary is None:
        return np.full((1, 3), 1.0 / 3.0), False
    return np.ascontiguousarray(bary, np.float64), True


@njit(cache=True, nogil=True)
def _encode_kernel(Li, V, tri, bary, per_vertex, P, FN, out):
    """``out[i] = Li[tri[i]] @ (V[i] - sum_k w_k P[FN[tri[i], k]])`` with ``w = bary[i]``
    (``per_vertex``) or ``bary[0]``: :func:`encode` in one pass, without the (n, 3, 3)
    gather of ``Li[tri]`` nor the (n, 3, 3) corners of :func:`anchor_points`."""
    for i in range(len(tri)):
        t = tri[i]
        r = i if per_vertex else 0
        a, b, c = FN[t, 0], FN[t, 1], FN[t, 2]
        w0, w1, w2 = bary[r, 0], bary[r, 1], bary[r, 2]
        x0 = V[i, 0] - (w0 * P[a, 0] + w1 * P[b, 0] + w2 * P[c, 0])
        x1 = V[i, 1] - (w0 * P[a, 1] + w1 * P[b, 1] + w2 * P[c, 1])
        x2 = V[i, 2] - (w0 * P[a, 2] + w1 * P[b, 2] + w2 * P[c, 2])
        for d in range(3):
            out[i, d] = Li[t, d, 0] * x0 + Li[t, d, 1] * x1 + Li[t, d, 2] * x2


def decode(C: np.ndarray, tri: np.ndarray, VN_rest: np.ndarray, VN_def: np.ndarray, FN: np.ndarray,
           axis: np.ndarray, gradient: str = "normalized", bary: np.ndarray | None = None) -> np.ndarray:
    """Rebuild positions v' = L'_t v_t + a'(v) on the deformed low-res mesh (Alg. 1, line 12).

    Parameters
    ----------
    C : (n, 3) local coordinates from :func:`encode`. tri : (n,) int64.
    VN_rest : (k, 3) rest low-res positions (the frame function's values).
    VN_def : (k, 3) deformed low-res positions (N'). FN : (t, 3). axis : (t,).
    bary : (n, 3) or None, as given to :func:`encode`.

    Returns
    -------
    (n, 3) float64 deformed high-res positions: :func:`decode_with_frames` with
    :func:`deformed_frames`.
    """
    return decode_with_frames(deformed_frames(VN_rest, VN_def, FN, axis, gradient), C, tri, VN_def, FN, bary)


def deformed_frames(VN_rest: np.ndarray, VN_def: np.ndarray, FN: np.ndarray, axis: np.ndarray,
                    gradient: str = "normalized") -> np.ndarray:
    """The frames L'_t of the deformed low-res mesh (§3.2; the frame function's values are
    the rest coordinates ``VN_rest`` (k, 3) chosen by ``axis`` (t,)): (t, 3, 3) float64,
    C-contiguous, for :func:`decode_with_frames`."""
    L, _ = local_frames(VN_def, FN, _corner_values(VN_rest, FN, axis), gradient)
    return np.ascontiguousarray(L, np.float64)


def decode_with_frames(L: np.ndarray, C: np.ndarray, tri: np.ndarray, VN_def: np.ndarray, FN: np.ndarray,
                       bary: np.ndarray | None = None, *, rows=None, out: np.ndarray | None = None,
                       add: bool = False) -> np.ndarray:
    """:func:`decode` with the deformed frames ``L`` given, for some rows, into or onto ``out``.

    Parameters
    ----------
    L : (t, 3, 3) float64 from :func:`deformed_frames`. C, tri, bary : as :func:`decode`
        ((n, 3), (n,), (n, 3) or None). VN_def : (k, 3) deformed low-res positions. FN : (t, 3).
    rows : None (every vertex), a ``slice(lo, hi)`` with step 1 (no copy), or (r,) int
        vertex indices.
    out : (r, 3) float64 C-contiguous, or None for a new array.
    add : add the rebuilt positions to ``out`` instead of writing them (the samplings'
        sum of :func:`sshade.sampling.average`, term by term the same additions).

    Returns
    -------
    ``out`` (r, 3), r the number of rows. The kernel releases the GIL (threads may
    decode disjoint rows side by side).

    Raises
    ------
    SShaDeError when ``out`` has the wrong shape or layout, or ``add`` without ``out``.
    """
    idx, lo, hi, out = decode_rows(rows, len(tri), out, add, "decode_with_frames")
    C_, tri_, bary_ = (C, tri, bary) if idx is None else (C[idx], tri[idx], None if bary is None else bary[idx])
    w, per_vertex = anchor_weights(bary_)
    _decode_kernel(L, np.ascontiguousarray(C_, np.float64), np.ascontiguousarray(tri_, np.int32), w,
                   np.ascontiguousarray(VN_def, np.float64), np.ascontiguousarray(FN, np.int64), per_vertex,
                   lo, hi, add, out)
    return out


def decode_rows(rows, n: int, out: np.ndarray | None, add: bool, who: str) -> tuple:
    """The rows a decoding kernel runs over and the array it writes: the ``rows``, ``out``
    and ``add`` arguments of :func:`decode_with_frames` checked (also those of
    :func:`sshade.smooth_transfer.smooth_decode_with`).

    Parameters
    ----------
    rows : None (all ``n``), a ``slice`` with step 1, or (r,) int indices. n : int, the
    vertices. out : (r, 3) float64 C-contiguous or None. add : bool. who : str, the
    caller's name in the messages.

    Returns
    -------
    ``(idx, lo, hi, out)``: ``idx`` (r,) int64 indices to gather the per-vertex arrays at
    (then ``lo, hi = 0, r``), or None with ``lo:hi`` the slice; ``out`` as given, or a new
    (r, 3) array.

    Raises
    ------
    SShaDeError on a slice with another step, ``out`` of the wrong shape, dtype or
    layout, ``add`` without ``out``.
    """
    idx = None
    if rows is None or isinstance(rows, slice):
        lo, hi, step = (0, n, 1) if rows is None else rows.indices(n)
        if step != 1:
            raise SShaDeError(f"{who}: a slice of rows must have step 1")
    else:
        idx = np.asarray(rows, np.int64)
        lo, hi = 0, len(idx)
    r = max(hi - lo, 0)
    if out is None:
        if add:
            raise SShaDeError(f"{who}: add=True needs an out array")
        out = np.empty((r, 3))
    elif out.shape != (r, 3) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise SShaDeError(f"{who}: out must be a C-contiguous ({r}, 3) float64 array")
    return idx, lo, hi, out


@njit(cache=True, nogil=True)
def _decode_kernel(L, C, tri, bary, P, FN, per_vertex, lo, hi, add, out):
    """``out[i - lo] (+)= L[tri[i]] @ C[i] + sum_k w_k P[FN[tri[i], k]]`` for ``lo <= i <
    hi`` with ``w = bary[i]`` (``per_vertex``) or ``bary[0]`` (the barycenter's thirds):
    :func:`decode` in one pass, without the (n, 3, 3) gather of ``L[tri]``."""
    for i in range(lo, hi):
        t = tri[i]
        r = i if per_vertex else 0
        a, b, c = FN[t, 0], FN[t, 1], FN[t, 2]
        w0, w1, w2 = bary[r, 0], bary[r, 1], bary[r, 2]
        c0, c1, c2 = C[i, 0], C[i, 1], C[i, 2]
        for d in range(3):
            v = (L[t, d, 0] * c0 + L[t, d, 1] * c1 + L[t, d, 2] * c2
                 + (w0 * P[a, d] + w1 * P[b, d] + w2 * P[c, d]))
            if add:
                out[i - lo, d] += v
            else:
                out[i - lo, d] = v


def transfer(V: np.ndarray, tri: np.ndarray, VN_rest: np.ndarray, VN_def: np.ndarray, FN: np.ndarray,
             *, gradient: str = "normalized", axis: np.ndarray | None = None,
             bary: np.ndarray | None = None) -> np.ndarray:
    """Algorithm 1 (LRFT): deform high-res ``V`` following ``N -> N'``.

    Parameters
    ----------
    V : (n, 3) float64 high-res rest positions. tri : (n,) int64 P(v).
    VN_rest, VN_def : (k, 3) float64 low-res rest / deformed positions. FN : (t, 3) int64.
    gradient : ``"normalized"`` or ``"raw"``. axis : (t,) frame function per triangle,
        default :func:`frame_functions` on ``VN_rest``.
    bary : (n, 3) float64 or None: anchor each vertex at these barycentric coordinates of
        its triangle (the projection's, ``anchor="projection"``); None anchors it at the
        barycenter b_t as Alg. 1 does.

    Returns
    -------
    (n, 3) float64 deformed positions. A rigid motion of N is reproduced exactly on M,
    with either anchor; with the projection's ``bary``, a vertex lying on its triangle
    follows the triangle's affine map exactly, whatever N' is.

    Examples
    --------
    Example::

        Vd = transfer(V, proj.tri, V[rm.seeds], VN_def, rm.F, bary=proj.bary)
    """
    if axis is None:
        axis = frame_functions(VN_rest, FN)
    C = encode(V, tri, VN_rest, FN, axis, gradient, bary)
    return decode(C, tri, VN_rest, VN_def, FN, axis, gradient, bary)

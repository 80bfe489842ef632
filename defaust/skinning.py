"""Linear blend skinning (:func:`lbs`, :func:`blend_transforms`, :func:`apply_blended`) and
the transfer of skinning weights to another mesh of the same surface
(:func:`transfer_weights`, :func:`subdivision_weights`, :func:`high_res_weights`), so that
"the same skinning" (the same per-joint transforms) poses a DeFAUST subject's
high-resolution rest mesh (:mod:`defaust.highres`) and its high-resolution target is exact
ground truth for it. Generic; used by the sources :mod:`defaust.anny_source` and
:mod:`defaust.synthetic`. Pure functions over arrays; no file I/O. The arithmetic is in a
fixed order (:mod:`defaust.fixed_order`: no BLAS, the same bytes on every machine).
"""
from __future__ import annotations

import numpy as np

from sshade.errors import SShaDeError

from . import fixed_order as fo
from .highres import ls3_loop

__all__ = ["lbs", "blend_transforms", "apply_blended", "transfer_weights", "closest_barycentric", "barycentric",
           "subdivision_weights", "high_res_weights"]


def lbs(V, W, R, t) -> np.ndarray:
    """Linear blend skinning ``v' = sum_j W[v, j] (R[j] v + t[j])``, the joints added in
    ascending order (each ``R[j] v + t[j]`` by :func:`defaust.fixed_order.apply_affine`).

    Parameters
    ----------
    V : (n, 3) rest positions; W : (n, k) weights; R : (k, 3, 3); t : (k, 3).

    Returns
    -------
    (n, 3) float64 posed positions (same units as V).

    Examples
    --------
    >>> lbs(np.zeros((1, 3)), np.ones((1, 1)), np.eye(3)[None], np.ones((1, 3)))
    array([[1., 1., 1.]])
    """
    V = np.asarray(V, np.float64)
    W = np.asarray(W, np.float64)
    M = np.concatenate([np.asarray(R, np.float64), np.asarray(t, np.float64)[:, :, None]], axis=2)
    out = np.zeros_like(V)
    for j in range(W.shape[1]):
        w = W[:, j]
        nz = w > 0
        if nz.any():
            out[nz] += w[nz, None] * fo.apply_affine(M[j], V[nz])
    return out


def blend_transforms(W, T) -> np.ndarray:
    """Per-vertex blended affine maps of linear blend skinning, ``M_v = sum_j W[v, j] T[j]``.

    ``apply_blended(blend_transforms(W, T), V)`` is LBS (:func:`lbs`) with
    ``T[j] = [R[j] | t[j]]``; the joints are added in ascending order
    (:func:`defaust.fixed_order.blend`).

    Parameters
    ----------
    W : (n, k) weights; T : (k, 3, 4) affine maps ``x -> T[:, :3] x + T[:, 3]``.

    Returns
    -------
    (n, 3, 4) float64.

    Raises
    ------
    SShaDeError on mismatched shapes.

    Examples
    --------
    >>> T = np.concatenate([np.eye(3), np.ones((3, 1))], axis=1)[None]
    >>> blend_transforms(np.ones((2, 1)), T).shape
    (2, 3, 4)
    """
    W = np.asarray(W, np.float64)
    T = np.asarray(T, np.float64)
    if W.ndim != 2 or T.shape != (W.shape[1], 3, 4):
        raise SShaDeError(f"blend_transforms: need W (n, k) and T (k, 3, 4), got {W.shape} and {T.shape}")
    return fo.blend(W, T)


def apply_blended(M, X, *, inverse: bool = False) -> np.ndarray:
    """Apply per-point affine maps (or their inverses) to points.

    Parameters
    ----------
    M : (n, 3, 4) maps ``x -> M[:, :3] x + M[:, 3]`` (:func:`blend_transforms`).
    X : (n, 3) points. inverse : apply ``M^-1`` instead (solves the 3x3 systems by
        Cramer's rule, :func:`defaust.fixed_order.solve3`; a blend of nearby rotations is
        well conditioned).

    Returns
    -------
    (n, 3) float64.

    Raises
    ------
    SShaDeError on mismatched shapes or a singular map (``inverse=True``: a solution that
    is not finite).

    Examples
    --------
    >>> M = np.concatenate([2 * np.eye(3), np.ones((3, 1))], axis=1)[None]
    >>> apply_blended(M, [[1.0, 1.0, 1.0]]), apply_blended(M, [[3.0, 3.0, 3.0]], inverse=True)
    (array([[3., 3., 3.]]), array([[1., 1., 1.]]))
    """
    M = np.asarray(M, np.float64)
    X = np.asarray(X, np.float64)
    if M.ndim != 3 or M.shape[1:] != (3, 4) or X.shape != (len(M), 3):
        raise SShaDeError(f"apply_blended: need M (n, 3, 4) and X (n, 3), got {M.shape} and {X.shape}")
    if not inverse:
        return fo.apply_affine(M, X)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = fo.solve3(M[:, :, :3], X - M[:, :, 3])
    if not np.isfinite(out).all():
        raise SShaDeError("apply_blended: a blended skinning map is singular (weights blending opposite "
                          "rotations)")
    return out


def transfer_weights(V_src, F_src, W_src, P) -> np.ndarray:
    """Interpolate per-vertex weights at the closest points of ``P`` on a source mesh.

    Parameters
    ----------
    V_src : (n, 3) float64; F_src : (m, 3) int64; W_src : (n, k) weights.
    P : (p, 3) query points (e.g. the vertices of a remesh of the same surface).

    Returns
    -------
    (p, k) float64, barycentric interpolation on the closest triangle
    (``igl.point_mesh_squared_distance``), rows renormalised to sum to 1 (each row's sum
    taken in ascending column order).

    Raises
    ------
    SShaDeError on mismatched shapes.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
    >>> transfer_weights(V, F, np.eye(3), [[0.5, 0.0, 0.1]]).round(3)
    array([[0.5, 0.5, 0. ]])
    """
    V_src = np.asarray(V_src, np.float64)
    F_src = np.asarray(F_src, np.int64)
    W = np.asarray(W_src, np.float64)
    P = np.ascontiguousarray(np.asarray(P, np.float64).reshape(-1, 3))
    if V_src.ndim != 2 or V_src.shape[1] != 3 or W.ndim != 2 or len(W) != len(V_src):
        raise SShaDeError(f"transfer_weights: need V_src (n, 3) and W_src (n, k), got {V_src.shape} and {W.shape}")
    fi, bc = closest_barycentric(V_src, F_src, P)
    return _interpolate(_sparse_rows(W) or W, W.shape[1], F_src[fi], bc)


# ------------------------------------------------------------------ weights as sparse rows
# An ANNY body's rows have a few nonzero joints of about 150, so the weights are carried as
# rows of (column, value) pairs: the same products and sums as the dense arithmetic, in the
# same order, on the nonzero entries only. A weight of +0.0 left out adds bc * (+0.0) = +0.0
# (bc >= 0), which leaves a partial sum unchanged; rows with -0.0, NaN or inf weights (or
# barycentric coordinates that are not finite) take the dense arithmetic instead, so every
# output byte is the dense one's (tests/test_defaust_skinning.py holds them equal).

def _sparse_rows(W):
    """``(indptr (n+1,), cols (e,), vals (e,))`` of the nonzero entries of ``W`` (n, k)
    float64, each row's columns ascending; None when ``W`` holds a -0.0, NaN or inf (there
    a left-out entry would not be the +0.0 the dense arithmetic adds)."""
    if not np.isfinite(W).all() or (np.signbit(W) & (W == 0)).any():
        return None
    rows, cols = np.nonzero(W)
    indptr = np.zeros(len(W) + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=len(W)), out=indptr[1:])
    return indptr, cols.astype(np.int64), W[rows, cols]


def _gather(S, r):
    """The entries of rows ``r`` (q,) of sparse rows ``S``: ``(owner (e,), cols, vals)``,
    ``owner`` the position in ``r`` each entry belongs to, in ``r``'s order."""
    indptr, cols, vals = S
    start, count = indptr[r], indptr[r + 1] - indptr[r]
    owner = np.repeat(np.arange(len(r)), count)
    first = np.cumsum(count) - count
    idx = np.repeat(start - first, count) + np.arange(int(count.sum()))
    return owner, cols[idx], vals[idx]


def _interpolate(W, k: int, corners, bc) -> np.ndarray:
    """``max(bc0 W[c0] + bc1 W[c1] + bc2 W[c2], 0)`` per row, normalised by its sum in
    ascending column order: (p, k) float64. ``W`` dense (n, k) or sparse rows
    (:func:`_sparse_rows`); ``corners`` (p, 3) int64 rows of ``W``, ``bc`` (p, 3)."""
    if isinstance(W, np.ndarray) or not np.isfinite(bc).all():
        W = W if isinstance(W, np.ndarray) else _dense(W, k)
        out = bc[:, 0:1] * W[corners[:, 0]] + bc[:, 1:2] * W[corners[:, 1]] + bc[:, 2:3] * W[corners[:, 2]]
    else:
        out = np.zeros((len(corners), k), np.float64)
        for c in range(3):  # ((bc0 w0 + bc1 w1) + bc2 w2), the terms with w = +0 left out
            owner, cols, vals = _gather(W, corners[:, c])
            out[owner, cols] += bc[owner, c] * vals  # one entry per (row, column) for each corner
    np.maximum(out, 0.0, out=out)
    out /= fo.sum_ascending(out, axis=1)[:, None]
    return out


def _dense(S, k: int) -> np.ndarray:
    """Sparse rows ``S`` as a dense (n, k) float64 array (left-out entries +0.0)."""
    indptr, cols, vals = S
    out = np.zeros((len(indptr) - 1, k), np.float64)
    out[np.repeat(np.arange(len(indptr) - 1), np.diff(indptr)), cols] = vals
    return out


def _mean_rows(S, a, b):
    """Sparse rows ``0.5 * (S[a] + S[b])`` for the row pairs ``a``, ``b`` (q,): the dense
    arithmetic's values, an entry missing on one side added as +0.0."""
    oa, ca, va = _gather(S, a)
    ob, cb, vb = _gather(S, b)
    owner, cols = np.concatenate([oa, ob]), np.concatenate([ca, cb])
    vals = np.concatenate([va, vb])
    order = np.lexsort((cols, owner))
    owner, cols, vals = owner[order], cols[order], vals[order]
    head = np.ones(len(owner), bool)
    head[1:] = (owner[1:] != owner[:-1]) | (cols[1:] != cols[:-1])
    starts = np.flatnonzero(head)
    summed = np.add.reduceat(vals, starts) if len(starts) else vals[:0]  # at most two terms: x + y, or x + 0.0
    summed = 0.5 * (summed + 0.0)
    indptr = np.zeros(len(a) + 1, np.int64)
    np.cumsum(np.bincount(owner[starts], minlength=len(a)), out=indptr[1:])
    return indptr, cols[starts], summed


def _stack(S, T):
    """Sparse rows ``S`` followed by the rows ``T``."""
    return (np.concatenate([S[0], T[0][1:] + S[0][-1]]), np.concatenate([S[1], T[1]]), np.concatenate([S[2], T[2]]))


def closest_barycentric(V, F, P) -> tuple[np.ndarray, np.ndarray]:
    """The closest point of each query point on a triangle mesh, as a triangle and its
    barycentric coordinates (``igl.point_mesh_squared_distance``, then :func:`barycentric`).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; P : (p, 3) float64 query points (same units).

    Returns
    -------
    face : (p,) int64 index into ``F`` of the closest triangle; bc : (p, 3) float64 the
    closest point's barycentric coordinates in it (clipped to [0, 1], as
    :func:`barycentric`).

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]]); F = np.array([[0, 1, 2]])
    >>> face, bc = closest_barycentric(V, F, np.array([[0.5, 0.0, 0.1]]))
    >>> face, bc.round(3)
    (array([0]), array([[0.5, 0.5, 0. ]]))
    """
    import igl

    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    P = np.ascontiguousarray(np.asarray(P, np.float64).reshape(-1, 3))
    _, fi, C = igl.point_mesh_squared_distance(P, V, F)
    fi = np.asarray(fi, np.int64)
    A, B, Cc = V[F[fi, 0]], V[F[fi, 1]], V[F[fi, 2]]
    return fi, barycentric(np.asarray(C, np.float64), A, B, Cc)


def barycentric(P, A, B, C) -> np.ndarray:
    """Barycentric coordinates of points in their triangles, clipped to [0, 1].

    Parameters
    ----------
    P, A, B, C : (p, 3) float64, the points and the corners of their triangles.

    Returns
    -------
    (p, 3) float64 (a degenerate triangle gives the first corner's weight 1).

    Examples
    --------
    >>> barycentric(np.array([[0.25, 0.25, 0]]), np.zeros((1, 3)), np.array([[1., 0, 0]]),
    ...             np.array([[0., 1, 0]])).round(2)
    array([[0.5 , 0.25, 0.25]])
    """
    v0, v1, v2 = B - A, C - A, P - A
    d00, d01, d11 = fo.dot3(v0, v0), fo.dot3(v0, v1), fo.dot3(v1, v1)
    d20, d21 = fo.dot3(v2, v0), fo.dot3(v2, v1)
    den = d00 * d11 - d01 * d01
    den = np.where(den == 0, 1.0, den)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    bc = np.stack([1 - v - w, v, w], axis=1)
    return np.clip(bc, 0.0, 1.0)


def subdivision_weights(V, F, W, iterations: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """LS3 Loop subdivision of a mesh (:func:`defaust.highres.ls3_loop`) with per-vertex
    weights carried along its topology.

    pymeshlab's subdivision keeps the old vertices first and appends one vertex per edge,
    connected to exactly the edge's two ends among the older vertices; that vertex gets
    their mean weights (iteration by iteration).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64, closed triangle mesh; W : (n, k) weights;
    iterations : int >= 1 (as :func:`defaust.highres.subdivide_remesh` used).

    Returns
    -------
    Vs : (N, 3) float64 and Fs : (M, 3) int64, ``ls3_loop(V, F, iterations)`` (the
    surface the high-res remesh was made from); Ws : (N, k) float64 weights.

    Raises
    ------
    SShaDeError if the subdivision's topology is not the expected 1-to-4 split.

    Examples
    --------
    Example::

        Vs, Fs, Ws = subdivision_weights(V, F, W, 2)
        np.array_equal(Ws[:len(W)], W)
        # -> True
    """
    W = np.asarray(W, np.float64)
    Vs, Fs, Ws = _subdivision_rows(V, F, W, iterations)
    return Vs, Fs, (Ws if isinstance(Ws, np.ndarray) else _dense(Ws, W.shape[1]))


def _subdivision_rows(V, F, W, iterations):
    """:func:`subdivision_weights` with the weights as sparse rows (:func:`_sparse_rows`;
    dense where ``W`` holds -0.0, NaN or inf): ``(Vs, Fs, Ws)``. The levels below the last
    take their topology from single iterations; the last takes it from the one call that
    gives the positions (:func:`_split_edges` checks each level against the one before)."""
    iterations = int(iterations)
    if iterations < 1:
        raise SShaDeError(f"subdivision iterations must be >= 1, got {iterations}")
    Ws = _sparse_rows(W) or W
    Vs, Fs = ls3_loop(V, F, iterations)  # positions exactly as subdivide_remesh made them
    Vt, Ft = np.asarray(V, np.float64), np.asarray(F, np.int64)
    n = len(W)
    for level in range(iterations):
        V_next, F_next = (Vs, Fs) if level == iterations - 1 else ls3_loop(Vt, Ft, 1)
        a, b = _split_edges(Ft, n, F_next, len(V_next))
        if isinstance(Ws, np.ndarray):
            Ws = np.concatenate([Ws, 0.5 * (Ws[a] + Ws[b])])
        else:
            Ws = _stack(Ws, _mean_rows(Ws, a, b))
        Vt, Ft, n = V_next, F_next, len(V_next)
    return Vs, Fs, Ws


def _split_edges(F, n: int, F_next, n_next: int) -> tuple[np.ndarray, np.ndarray]:
    """The two ends ``(a, b)`` (each (n_next - n,) int64, ``a < b``) of the edge of ``F``
    (faces into ``n`` vertices) that each new vertex ``n, n + 1, ...`` of its LS3 Loop
    subdivision ``F_next`` (into ``n_next``) splits: the new vertex's two neighbours among
    the older ones. SShaDeError unless every new vertex has exactly two older neighbours
    and the pairs are exactly the edges of ``F``, each once (pymeshlab keeps the old
    vertices first and appends one vertex per edge)."""
    key = _edge_keys(F_next, n_next)
    E = np.stack([key // n_next, key % n_next], axis=1)
    E = E[(E[:, 0] < n) & (E[:, 1] >= n)]  # (older end, new vertex)
    new = n_next - n
    if len(E) != 2 * new or not np.array_equal(np.bincount(E[:, 1] - n, minlength=new), np.full(new, 2)):
        raise SShaDeError("LS3 Loop subdivision: unexpected topology (a new vertex is not on one old edge)")
    E = E[np.argsort(E[:, 1], kind="stable")]
    a, b = E[0::2, 0], E[1::2, 0]
    if not np.array_equal(_edge_keys(F, n), np.sort(a * n + b)):
        raise SShaDeError("LS3 Loop subdivision: the split edges are not the edges of the level before")
    return a, b


def _edge_keys(F, n: int) -> np.ndarray:
    """(e,) int64 ascending: ``i n + j`` for each undirected edge ``i < j`` of the faces
    ``F`` (m, 3) into ``n`` vertices, once (np.unique's values, without its hash pass)."""
    E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    key = np.sort(E[:, 0] * n + E[:, 1])
    return key[np.concatenate([[True], key[1:] != key[:-1]])]


def high_res_weights(V, F, W, V_high, iterations: int) -> np.ndarray:
    """Skinning weights of the vertices of a high-res remesh of ``(V, F)``.

    Parameters
    ----------
    V, F, W : the low-res rest mesh and its (n, k) weights.
    V_high : (p, 3) vertices of :func:`defaust.highres.subdivide_remesh` of ``(V, F)``.
    iterations : its LS3 iterations (``HighResResult.iterations``; the build records
        them as ``ls3_iterations``).

    Returns
    -------
    (p, k) float64, rows summing to 1: the weights of :func:`subdivision_weights` at the
    closest points on the subdivided surface (:func:`defaust.skinning.transfer_weights`).

    Examples
    --------
    Example::

        Wh = high_res_weights(sub.V, sub.F, sub.W, Vh, 2)
    """
    W = np.asarray(W, np.float64)
    if W.ndim != 2 or len(W) != len(V):
        raise SShaDeError(f"high_res_weights: need V (n, 3) and W (n, k), got {np.shape(V)} and {W.shape}")
    Vs, Fs, Ws = _subdivision_rows(V, F, W, iterations)
    fi, bc = closest_barycentric(Vs, Fs, V_high)
    return _interpolate(Ws, W.shape[1], Fs[fi], bc)

"""Arithmetic whose bytes do not depend on the machine, for the DeFAUST builder: every
float64 result here is made of IEEE-754 elementwise ``+ - * /`` and ``sqrt`` (each
correctly rounded, none fused into a multiply-add), in an order the code fixes; no BLAS or
LAPACK (whose sums depend on the library, its kernels and its thread count), no numpy
reduction of more than one term, no CPU-dispatched SIMD math. The transcendentals
(:func:`sin`, :func:`cos`, :func:`atan2`) are computed in decimal arithmetic (Python's
:mod:`decimal`, 40 significant digits) and rounded once to float64, so they do not
depend on the C library either. Products of small matrices (:func:`matmul`,
:func:`apply_affine`, :func:`rigid_inverse`, :func:`solve3`), per-row weighted sums
(:func:`blend`), sums in ascending order (:func:`sum_ascending`), norms, dots and cross products of
3-vectors, a symmetric 3 x 3 eigensolver (:func:`eigh3`), Rodrigues' rotation
(:func:`rotvec_to_matrix`) and back (:func:`matrix_to_rotvec`). Why: docs/defaust.md, "The same bytes on every machine".
"""
from __future__ import annotations

import decimal
import math
from decimal import Decimal

import numpy as np

__all__ = ["matmul", "apply_affine", "rigid_inverse", "norm3", "dot3", "cross3", "blend", "sum_ascending", "solve3",
           "eigh3", "sin", "cos", "atan2", "rotvec_to_matrix", "matrix_to_rotvec"]

_CTX = decimal.Context(prec=40, rounding=decimal.ROUND_HALF_EVEN, Emin=-999999, Emax=999999)
_PI = Decimal("3.141592653589793238462643383279502884197169399375105820974944592")
_EPS = Decimal("1e-45")


def matmul(A, B) -> np.ndarray:
    """``A @ B`` summed over the inner index in ascending order.

    Parameters
    ----------
    A : (..., i, k) float; B : (..., k, j) float (batch axes broadcast).

    Returns
    -------
    (..., i, j) float64: ``sum_k A[..., i, k] * B[..., k, j]``, the terms added left to
    right (``((a0 b0 + a1 b1) + a2 b2) + ...``).

    Examples
    --------
    >>> matmul(np.eye(2), [[1.0, 2.0], [3.0, 4.0]])
    array([[1., 2.],
           [3., 4.]])
    """
    A = np.asarray(A, np.float64)
    B = np.asarray(B, np.float64)
    if A.shape[-1] != B.shape[-2]:
        raise ValueError(f"matmul: inner sizes differ ({A.shape} and {B.shape})")
    out = A[..., :, 0, None] * B[..., None, 0, :]
    for k in range(1, A.shape[-1]):
        out = out + A[..., :, k, None] * B[..., None, k, :]
    return out


def apply_affine(M, X) -> np.ndarray:
    """Points ``X`` mapped by the affine maps ``M``: ``M[:3, :3] x + M[:3, 3]``.

    Parameters
    ----------
    M : (..., 3, 4) or (..., 4, 4) float; X : (..., 3) float (batch axes broadcast).

    Returns
    -------
    (..., 3) float64, row ``r`` = ``((M[r,0] x0 + M[r,1] x1) + M[r,2] x2) + M[r,3]``.
    """
    M = np.asarray(M, np.float64)
    X = np.asarray(X, np.float64)
    rows = [((M[..., r, 0] * X[..., 0] + M[..., r, 1] * X[..., 1]) + M[..., r, 2] * X[..., 2]) + M[..., r, 3]
            for r in range(3)]
    return np.stack(rows, axis=-1)


def rigid_inverse(T) -> np.ndarray:
    """The inverses of rigid maps ``T = [R | t]``: ``[R^T | -R^T t]`` (exact transpose;
    :func:`apply_affine`'s order for ``R^T t``).

    Parameters
    ----------
    T : (..., 4, 4) float, rotation part orthonormal (not checked).

    Returns
    -------
    (..., 4, 4) float64, last row ``[0, 0, 0, 1]``.
    """
    T = np.asarray(T, np.float64)
    out = np.zeros(T.shape, np.float64)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    t = T[..., :3, 3]
    out[..., :3, 3] = -(((Rt[..., :, 0] * t[..., 0, None] + Rt[..., :, 1] * t[..., 1, None])
                         + Rt[..., :, 2] * t[..., 2, None]))
    out[..., 3, 3] = 1.0
    return out


def norm3(v) -> np.ndarray:
    """Euclidean norms of 3-vectors, ``sqrt((x*x + y*y) + z*z)``.

    Parameters
    ----------
    v : (..., 3) float.

    Returns
    -------
    (...,) float64.

    >>> float(norm3([3.0, 4.0, 12.0]))
    13.0
    """
    v = np.asarray(v, np.float64)
    return np.sqrt((v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1]) + v[..., 2] * v[..., 2])


def dot3(a, b) -> np.ndarray:
    """Dot products of 3-vectors, ``(a0 b0 + a1 b1) + a2 b2``.

    Parameters
    ----------
    a, b : (..., 3) float (broadcast).

    Returns
    -------
    (...,) float64.
    """
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]) + a[..., 2] * b[..., 2]


def blend(W, T) -> np.ndarray:
    """Per-row weighted sums ``sum_j W[v, j] T[j]``, added over ``j`` in ascending order
    (a zero weight adds nothing and is skipped: for finite ``T`` the sum is the same).

    Parameters
    ----------
    W : (n, k) float weights; T : (k, ...) float, the items blended (e.g. (k, 3, 4)
        affine maps or (k, 3) offsets).

    Returns
    -------
    (n, ...) float64.
    """
    W = np.asarray(W, np.float64)
    T = np.asarray(T, np.float64)
    if W.ndim != 2 or T.shape[0] != W.shape[1]:
        raise ValueError(f"blend: W must be (n, k) and T (k, ...), got {W.shape} and {T.shape}")
    tail = T.shape[1:]
    flat = T.reshape(len(T), -1)
    out = np.zeros((W.shape[0], flat.shape[1]), np.float64)
    # A zero weight adds 0 * x (a signed zero for finite x), which leaves a partial sum
    # started at +0.0 unchanged: a joint's column is added to its nonzero rows only, or to
    # every row where more than a fifth are nonzero (a pass over every row is faster
    # there); each row gets the same terms in the same ascending order either way.
    nnz = np.count_nonzero(W, axis=0)
    sparse = nnz <= W.shape[0] // 5
    if (sparse & (nnz > 0)).any():
        rows, cols = np.nonzero(W)
        keep = sparse[cols]
        by_col = np.argsort(cols[keep], kind="stable")  # rows ascending within each column
        rows, ptr = rows[keep][by_col], np.searchsorted(cols[keep][by_col], np.arange(W.shape[1] + 1))
    for j in np.flatnonzero(nnz).tolist():
        if sparse[j]:
            r = rows[ptr[j]:ptr[j + 1]]  # unique: one term per row
            out[r] += W[r, j, None] * flat[j]
        else:
            out += W[:, j, None] * flat[j]
    return out.reshape((W.shape[0],) + tail)


def sum_ascending(X, axis: int = 0) -> np.ndarray:
    """The sum of ``X`` along ``axis``, its terms added in ascending index order
    (``((x0 + x1) + x2) + ...``), where numpy's ``sum`` adds pairwise in blocks.

    Parameters
    ----------
    X : (..., n, ...) float, ``n >= 1`` terms along ``axis``.

    Returns
    -------
    X's shape without ``axis``, float64 (a 0-d array for a 1-d ``X``).

    Raises
    ------
    ValueError if ``X`` has no term along ``axis``.

    >>> float(sum_ascending([1e16, 1.0, -1e16, 1.0]))
    1.0
    """
    X = np.moveaxis(np.asarray(X, np.float64), axis, 0)
    if not len(X):
        raise ValueError("sum_ascending: no term to add")
    if X.ndim == 1:  # one Python float addition per term: no array per term
        terms = X.tolist()
        acc = terms[0]
        for t in terms[1:]:
            acc = acc + t
        return np.asarray(acc, np.float64)
    acc = X[0].copy()
    for k in range(1, len(X)):
        acc = acc + X[k]
    return acc


def solve3(M, y) -> np.ndarray:
    """Solutions ``x`` of the 3 x 3 systems ``M x = y`` by Cramer's rule (cofactors and
    determinant in a fixed order); for well-conditioned ``M`` (near rotations), where it
    is as accurate as a factorisation.

    Parameters
    ----------
    M : (..., 3, 3) float; y : (..., 3) float.

    Returns
    -------
    (..., 3) float64 (inf or nan where ``M`` is singular).
    """
    M = np.asarray(M, np.float64)
    y = np.asarray(y, np.float64)
    c0 = cross3(M[..., :, 1], M[..., :, 2])  # cofactor rows of the adjugate
    c1 = cross3(M[..., :, 2], M[..., :, 0])
    c2 = cross3(M[..., :, 0], M[..., :, 1])
    det = dot3(M[..., :, 0], c0)
    return np.stack([dot3(c0, y) / det, dot3(c1, y) / det, dot3(c2, y) / det], axis=-1)


def eigh3(C) -> tuple[list, list]:
    """Eigenpairs of a symmetric 3 x 3 matrix by cyclic Jacobi rotations (Golub & Van
    Loan, Matrix Computations, §8.5), in Python floats: ``+ - * /`` and ``sqrt`` in a
    fixed order, the same bits on every machine (LAPACK's depend on its kernels).

    Parameters
    ----------
    C : (3, 3) finite float, symmetric (both triangles are read: they must agree).

    Returns
    -------
    values : list of 3 floats, descending (ties in index order); vectors : list of 3
    lists of 3 floats, the unit eigenvectors in the same order (their signs as the
    rotations leave them).

    >>> eigh3([[2.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 1.0]])[0]
    [3.0, 2.0, 1.0]
    """
    a = [[float(C[i][j]) for j in range(3)] for i in range(3)]
    v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    for _ in range(64):  # quadratic convergence: a handful of sweeps reach exact zeros
        if a[0][1] == 0.0 and a[0][2] == 0.0 and a[1][2] == 0.0:
            break
        for p, q in ((0, 1), (0, 2), (1, 2)):
            apq = a[p][q]
            if apq == 0.0:
                continue
            g = 100.0 * abs(apq)
            if abs(a[p][p]) + g == abs(a[p][p]) and abs(a[q][q]) + g == abs(a[q][q]):
                a[p][q] = a[q][p] = 0.0  # below the diagonal's rounding: annihilated
                continue
            theta = (a[q][q] - a[p][p]) / (2.0 * apq)
            t = 0.5 / theta if abs(theta) > 1e150 else \
                math.copysign(1.0, theta) / (abs(theta) + math.sqrt(theta * theta + 1.0))
            c = 1.0 / math.sqrt(t * t + 1.0)
            s = t * c
            for m in (a, v):  # columns p, q: M J
                for k in range(3):
                    mp, mq = m[k][p], m[k][q]
                    m[k][p], m[k][q] = c * mp - s * mq, s * mp + c * mq
            for k in range(3):  # rows p, q: J^T A
                ap, aq = a[p][k], a[q][k]
                a[p][k], a[q][k] = c * ap - s * aq, s * ap + c * aq
            a[p][q] = a[q][p] = 0.0  # zero by construction, exactly
    order = sorted(range(3), key=lambda i: -a[i][i])  # stable: ties keep index order
    return [a[i][i] for i in order], [[v[k][i] for k in range(3)] for i in order]


def cross3(a, b) -> np.ndarray:
    """Cross products of 3-vectors, each component one difference of two products
    (``a1 b2 - a2 b1``, ``a2 b0 - a0 b2``, ``a0 b1 - a1 b0``).

    Parameters
    ----------
    a, b : (..., 3) float (broadcast).

    Returns
    -------
    (..., 3) float64.
    """
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1], a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _reduced(x: float) -> Decimal:
    """``x`` (a finite float) minus the multiple of 2 pi nearest it, in decimal."""
    d = Decimal(x)
    two_pi = 2 * _PI
    return d - (d / two_pi).to_integral_value(rounding=decimal.ROUND_HALF_EVEN) * two_pi


def _sin_cos_decimal(x: float) -> tuple[Decimal, Decimal]:
    """Sine and cosine of the float ``x`` by their Taylor series after reduction to
    [-pi, pi], in :data:`_CTX`."""
    with decimal.localcontext(_CTX):
        r = _reduced(x)
        r2 = r * r
        s, c, term_s, term_c, n = r, Decimal(1), r, Decimal(1), 1
        while abs(term_s) > _EPS or abs(term_c) > _EPS:
            term_s = -term_s * r2 / ((2 * n) * (2 * n + 1))
            term_c = -term_c * r2 / ((2 * n - 1) * (2 * n))
            s, c, n = s + term_s, c + term_c, n + 1
        return +s, +c


def _map(f, x) -> np.ndarray:
    """``f`` (float -> float) applied to every element of ``x``, float64 out."""
    a = np.asarray(x, np.float64)
    if not np.isfinite(a).all():
        raise ValueError("fixed_order: a transcendental of a non-finite value")
    return np.array([f(float(v)) for v in a.ravel()], np.float64).reshape(a.shape)


def sin(x) -> np.ndarray:
    """Sine (radians), computed in decimal and rounded once to float64: the same bytes on
    every machine. x : (...) finite float. Returns (...) float64. ValueError on inf/nan.

    >>> float(sin(1.0))
    0.8414709848078965
    """
    return _map(lambda v: float(_sin_cos_decimal(v)[0]), x)


def cos(x) -> np.ndarray:
    """Cosine (radians), as :func:`sin`. x : (...) finite float. Returns (...) float64.

    >>> float(cos(1.0))
    0.5403023058681398
    """
    return _map(lambda v: float(_sin_cos_decimal(v)[1]), x)


def _atan_unit(t: Decimal) -> Decimal:
    """arctan of ``t`` in [0, 1], in :data:`_CTX`: halved twice
    (``atan t = 2 atan(t / (1 + sqrt(1 + t^2)))``), then its Taylor series."""
    k = 0
    while t > Decimal("0.2"):
        t = t / (1 + (1 + t * t).sqrt())
        k += 1
    t2, term, s, n = t * t, t, t, 1
    while abs(term) > _EPS:
        term = -term * t2
        s += term / (2 * n + 1)
        n += 1
    return s * (2 ** k)


def _atan2_one(y: float, x: float) -> float:
    """atan2 of one pair of finite floats, as C's ``atan2`` defines its quadrants and
    signed zeros, computed in decimal."""
    if y == 0.0 and x == 0.0:
        return float(np.arctan2(y, x))  # +-0 or +-pi by the signs: exact constants
    with decimal.localcontext(_CTX):
        ay, ax = abs(Decimal(y)), abs(Decimal(x))
        a = _atan_unit(ay / ax) if ay <= ax else _PI / 2 - _atan_unit(ax / ay)
        if x < 0:
            a = _PI - a
        return float(a if (y > 0 or (y == 0.0 and np.copysign(1.0, y) > 0)) else -a)


def atan2(y, x) -> np.ndarray:
    """Four-quadrant arctangent of ``y / x`` (radians, in [-pi, pi]), computed in decimal
    and rounded once to float64.

    Parameters
    ----------
    y, x : (...) finite float (broadcast).

    Returns
    -------
    (...) float64. ValueError on inf/nan.

    >>> float(atan2(1.0, 1.0))
    0.7853981633974483
    """
    y, x = np.broadcast_arrays(np.asarray(y, np.float64), np.asarray(x, np.float64))
    if not (np.isfinite(y).all() and np.isfinite(x).all()):
        raise ValueError("fixed_order: atan2 of a non-finite value")
    out = [_atan2_one(float(a), float(b)) for a, b in zip(y.ravel(), x.ravel())]
    return np.array(out, np.float64).reshape(y.shape)


def rotvec_to_matrix(rv) -> np.ndarray:
    """Rotation matrices of rotation vectors (axis times angle, radians), Rodrigues'
    formula ``R = cos t I + sin t [k]x + (1 - cos t) k k^T`` with ``k = rv / t``,
    ``t = |rv|`` (:func:`norm3`); the identity where ``t = 0``.

    Parameters
    ----------
    rv : (..., 3) finite float.

    Returns
    -------
    (..., 3, 3) float64.
    """
    rv = np.asarray(rv, np.float64)
    t = norm3(rv)
    zero = t == 0.0
    k = rv / np.where(zero, 1.0, t)[..., None]
    s, c = sin(t), cos(t)
    C = 1.0 - c
    out = np.empty(rv.shape[:-1] + (3, 3), np.float64)
    x, y, z = k[..., 0], k[..., 1], k[..., 2]
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = c + C * x * x, C * x * y - s * z, C * x * z + s * y
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = C * y * x + s * z, c + C * y * y, C * y * z - s * x
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = C * z * x - s * y, C * z * y + s * x, c + C * z * z
    out[zero] = np.eye(3)
    return out


def matrix_to_rotvec(R) -> np.ndarray:
    """Rotation vectors (axis times angle in [0, pi], radians) of rotation matrices, in a
    fixed order: the quaternion by the largest of its four squared components (Shepperd's
    method, one ``sqrt``), ``w >= 0``, angle ``2 atan2(|v|, w)``
    (:func:`atan2`).

    R : (..., 3, 3) float, rotations. Returns (..., 3) float64 (zero for the identity).
    """
    R = np.asarray(R, np.float64)
    m = R.reshape(-1, 3, 3)
    tr = (m[:, 0, 0] + m[:, 1, 1]) + m[:, 2, 2]
    cand = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=-1)
    which = np.argmax(cand, axis=-1)
    q = np.empty((len(m), 4), np.float64)  # (w, x, y, z)
    for i in range(4):
        sel = which == i
        a = m[sel]
        if i == 0:
            r = np.sqrt(1.0 + tr[sel])
            q[sel] = np.stack([r, (a[:, 2, 1] - a[:, 1, 2]) / r, (a[:, 0, 2] - a[:, 2, 0]) / r,
                               (a[:, 1, 0] - a[:, 0, 1]) / r], axis=-1)
        else:
            u, v, t = i - 1, i % 3, (i + 1) % 3  # the largest axis u, then the cyclic others
            r = np.sqrt(((1.0 + a[:, u, u]) - a[:, v, v]) - a[:, t, t])
            qq = np.empty((len(a), 4), np.float64)
            qq[:, 0] = (a[:, t, v] - a[:, v, t]) / r
            qq[:, 1 + u], qq[:, 1 + v], qq[:, 1 + t] = r, (a[:, v, u] + a[:, u, v]) / r, (a[:, t, u] + a[:, u, t]) / r
            q[sel] = qq
    q = np.where((q[:, 0] < 0)[:, None], -q, q)  # 2x the quaternion, w >= 0
    vn = norm3(q[:, 1:])
    angle = 2.0 * atan2(vn, q[:, 0])
    out = q[:, 1:] * (angle / np.where(vn > 0, vn, 1.0))[:, None]
    return out.reshape(R.shape[:-2] + (3,))

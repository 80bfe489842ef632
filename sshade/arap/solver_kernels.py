"""Numba kernels of the solver's loop (:mod:`sshade.arap.solver`) and of its accelerators
(:mod:`sshade.arap.accelerate`), with their lazy compilation.

``set_rows``, ``max_move``, ``grad`` (the stopping test's gradient in CSR, kept for the
L-BFGS direction), ``push`` /
``mix`` (Anderson's history and mixing; sums over fixed chunks of :data:`CHUNK`, so the
same floats whatever the thread count), :func:`lbfgs_two_loop`, :func:`lbfgs_pair`.
:func:`loop_kernels` compiles (or loads from numba's cache) the serial or parallel
variants on first use; :func:`warmup_kernels` every serial kernel of the solver,
:mod:`sshade.arap.kernels` included.
"""
from __future__ import annotations

import numpy as np

from .kernels import warmup_energy_kernels
from .threads import note_launch

try:  # numba is a dependency of the package; without it the numpy paths are used
    import numba as nb
except ImportError:  # pragma: no cover
    nb = None

__all__ = ["CHUNK", "loop_kernels", "lbfgs_two_loop", "lbfgs_pair", "warmup_kernels"]

#: Anderson's dot products are summed over fixed chunks of CHUNK entries, then over the
#: chunks: the same floats whatever the number of threads.
CHUNK = 8192

if nb is not None:
    _prange = nb.prange
    _njit = nb.njit(cache=True, nogil=True, error_model="numpy")
    _njit_par = nb.njit(cache=True, nogil=True, error_model="numpy", parallel=True)

    @_njit
    def _set_rows(U, rows, x):
        """``U[rows] = x`` for (r, 3) ``x``."""
        for i in range(rows.shape[0]):
            r = rows[i]
            U[r, 0] = x[i, 0]; U[r, 1] = x[i, 1]; U[r, 2] = x[i, 2]

    @_njit
    def _max_move(a, b):
        """``max_i ||a_i - b_i||^2`` over the rows of two (r, 3) arrays."""
        m = 0.0
        for i in range(a.shape[0]):
            d0 = a[i, 0] - b[i, 0]; d1 = a[i, 1] - b[i, 1]; d2 = a[i, 2] - b[i, 2]
            v = d0 * d0 + d1 * d1 + d2 * d2
            if v > m:
                m = v
        return m

    @_njit
    def _grad_rows(r0, r1, ptr, idx, val, x, g, mass, q, out):
        """Rows ``r0:r1`` of the gradient ``2 A (x - g)`` (``A`` in CSR, scipy's order of
        summation) into ``out`` (r, 3): ``q[i] = ||grad_i||^2 / (4 mass[i])``."""
        for i in range(r0, r1):
            a0 = 0.0; a1 = 0.0; a2 = 0.0
            for jj in range(ptr[i], ptr[i + 1]):
                j = idx[jj]
                v = val[jj]
                a0 += v * (x[j, 0] - g[j, 0]); a1 += v * (x[j, 1] - g[j, 1]); a2 += v * (x[j, 2] - g[j, 2])
            a0 = 2.0 * a0; a1 = 2.0 * a1; a2 = 2.0 * a2
            out[i, 0] = a0; out[i, 1] = a1; out[i, 2] = a2
            q[i] = (a0 * a0 + a1 * a1 + a2 * a2) / (4.0 * mass[i])

    @_njit
    def _grad_serial(ptr, idx, val, x, g, mass, q, out):
        _grad_rows(0, q.shape[0], ptr, idx, val, x, g, mass, q, out)

    @_njit_par
    def _grad_parallel(ptr, idx, val, x, g, mass, q, out):
        n = q.shape[0]
        for c in _prange((n + 2047) // 2048):
            _grad_rows(c * 2048, min(n, (c + 1) * 2048), ptr, idx, val, x, g, mass, q, out)

    @nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "nsz"})
    def _dot(a, b, n):
        """``sum_{i < n} a_i b_i``, vectorised (the summation order is fixed by ``n`` and
        the machine's vector width: the same floats for the same chunk, whatever the
        number of threads)."""
        s = 0.0
        for i in range(n):
            s += a[i] * b[i]
        return s

    @_njit
    def _push_chunk(c, x, g, x_prev, g_prev, DF, DG, slot, nh, part):
        """Chunk ``c`` (entries ``c CHUNK ...``) of the Anderson update with the accepted
        ``(x, g)`` after ``(x_prev, g_prev)`` (flat (N,) arrays), ``f = g - x``:
        ``DF[slot] = f - f_prev``, ``DG[slot] = g - g_prev``, and the chunk's partial dot
        products ``part[c, j] = DF[slot] . DF[j]``, ``part[c, m + j] = DF[j] . f``
        (``j < nh``)."""
        N = x.shape[0]
        i0 = c * CHUNK
        n = min(N, i0 + CHUNK) - i0
        f = np.empty(n)
        for i in range(n):
            k = i0 + i
            fi = g[k] - x[k]
            f[i] = fi
            DF[slot, k] = fi - (g_prev[k] - x_prev[k])
            DG[slot, k] = g[k] - g_prev[k]
        m = DF.shape[0]
        new = DF[slot, i0:i0 + n]
        for j in range(nh):
            row = DF[j, i0:i0 + n]
            part[c, j] = _dot(new, row, n)
            part[c, m + j] = _dot(row, f, n)

    @_njit
    def _push_serial(x, g, x_prev, g_prev, DF, DG, slot, nh, part):
        for c in range(part.shape[0]):
            _push_chunk(c, x, g, x_prev, g_prev, DF, DG, slot, nh, part)

    @_njit_par
    def _push_parallel(x, g, x_prev, g_prev, DF, DG, slot, nh, part):
        for c in _prange(part.shape[0]):  # prange counts in uint64: one callee signature
            _push_chunk(np.int64(c), x, g, x_prev, g_prev, DF, DG, slot, nh, part)

    @_njit
    def _mix_range(i0, i1, g, DG, theta, nh, out):
        """``out = g - sum_{j < nh} theta_j DG[j]`` on entries ``i0:i1``, the sum taken
        row by row of ``DG`` (contiguous reads; each entry's terms added in ``j`` order)."""
        for i in range(i0, i1):
            out[i] = 0.0
        for j in range(nh):
            tj = theta[j]
            for i in range(i0, i1):
                out[i] += tj * DG[j, i]
        for i in range(i0, i1):
            out[i] = g[i] - out[i]

    @_njit
    def _mix_serial(g, DG, theta, nh, out):
        _mix_range(0, out.shape[0], g, DG, theta, nh, out)

    @_njit_par
    def _mix_parallel(g, DG, theta, nh, out):
        N = out.shape[0]
        for c in _prange((N + CHUNK - 1) // CHUNK):
            _mix_range(c * CHUNK, min(N, (c + 1) * CHUNK), g, DG, theta, nh, out)


if nb is not None:
    @_njit
    def lbfgs_two_loop(S, Y, Z, rho, order, grad, z, gamma, q, r, alpha):
        """L-BFGS two-loop recursion (Nocedal & Wright, Alg. 7.4) with the initial Hessian
        ``gamma H0``, ``H0 y_i = Z_i`` and ``H0 grad = z``: writes the quasi-Newton step
        ``r = H grad`` (N,) and returns ``grad . r``. ``order``: ring slots, newest first.
        Each pass updates the vectors with one pair and sums the next pair's dot product
        (the same sums, in the same order, as one pass each). Serial and deterministic."""
        N = grad.shape[0]
        k = order.shape[0]
        if k == 0:
            sl = 0.0
            for j in range(N):
                r[j] = z[j]
                sl += grad[j] * z[j]
            return sl
        i = order[0]
        a = 0.0
        for j in range(N):
            q[j] = grad[j]
            r[j] = gamma * z[j]
            a += S[i, j] * grad[j]
        for t in range(k):
            i = order[t]
            a *= rho[i]
            alpha[t] = a
            ga = gamma * a
            if t + 1 < k:
                nxt = order[t + 1]
                a2 = 0.0
                for j in range(N):
                    qj = q[j] - a * Y[i, j]
                    q[j] = qj
                    r[j] -= ga * Z[i, j]
                    a2 += S[nxt, j] * qj
                a = a2
            else:
                for j in range(N):
                    r[j] -= ga * Z[i, j]
        i = order[k - 1]
        b = 0.0
        for j in range(N):
            b += Y[i, j] * r[j]
        sl = 0.0
        for t in range(k - 1, -1, -1):
            i = order[t]
            c = alpha[t] - rho[i] * b
            if t > 0:
                nxt = order[t - 1]
                b = 0.0
                for j in range(N):
                    rj = r[j] + c * S[i, j]
                    r[j] = rj
                    b += Y[nxt, j] * rj
            else:
                for j in range(N):
                    rj = r[j] + c * S[i, j]
                    r[j] = rj
                    sl += grad[j] * rj
        return sl

    @_njit
    def lbfgs_pair(x, grad, z, x_prev, grad_prev, z_prev, s, y, zz):
        """New curvature pair into (s, y, zz) and the previous point updated to
        (x, grad, z); returns (s.y, s.s, y.y, y.zz)."""
        sy = 0.0
        ss = 0.0
        yy = 0.0
        yz = 0.0
        for j in range(x.shape[0]):
            a = x[j] - x_prev[j]
            b = grad[j] - grad_prev[j]
            c = z[j] - z_prev[j]
            s[j] = a
            y[j] = b
            zz[j] = c
            sy += a * b
            ss += a * a
            yy += b * b
            yz += b * c
            x_prev[j] = x[j]
            grad_prev[j] = grad[j]
            z_prev[j] = z[j]
        return sy, ss, yy, yz


else:  # pragma: no cover - numpy versions of the two L-BFGS kernels
    def lbfgs_two_loop(S, Y, Z, rho, order, grad, z, gamma, q, r, alpha):
        q[:] = grad
        r[:] = z if len(order) == 0 else gamma * z
        for t, i in enumerate(order):
            alpha[t] = rho[i] * np.einsum("j,j->", S[i], q)
            q -= alpha[t] * Y[i]
            r -= (gamma * alpha[t]) * Z[i]
        for t in range(len(order) - 1, -1, -1):
            i = order[t]
            r += (alpha[t] - rho[i] * np.einsum("j,j->", Y[i], r)) * S[i]
        return float(np.einsum("j,j->", grad, r))

    def lbfgs_pair(x, grad, z, x_prev, grad_prev, z_prev, s, y, zz):
        np.subtract(x, x_prev, out=s)
        np.subtract(grad, grad_prev, out=y)
        np.subtract(z, z_prev, out=zz)
        x_prev[:] = x
        grad_prev[:] = grad
        z_prev[:] = z
        return (float(np.einsum("j,j->", s, y)), float(np.einsum("j,j->", s, s)),
                float(np.einsum("j,j->", y, y)), float(np.einsum("j,j->", y, zz)))


_LOOP = {1: None, 2: None}  # None: not tried; False: unusable; else the kernels


def loop_kernels(parallel: bool):
    """``dict`` of the compiled loop kernels (serial or parallel variants: ``"set_rows"``,
    ``"max_move"``, ``"grad"``, ``"push"``, ``"mix"``), or False when numba is unusable.
    Compiling the parallel variants starts numba's thread pool."""
    key = 2 if parallel else 1
    if _LOOP[key] is None:
        try:
            if parallel:
                note_launch()
            k = {"set_rows": _set_rows, "max_move": _max_move,
                 "grad": _grad_parallel if parallel else _grad_serial,
                 "push": _push_parallel if parallel else _push_serial,
                 "mix": _mix_parallel if parallel else _mix_serial}
            x = np.zeros((2, 3))
            xf = x.reshape(-1)
            k["set_rows"](np.zeros((2, 3)), np.arange(2, dtype=np.uint32), x)
            k["max_move"](x, x)
            k["grad"](np.array([0, 1, 2], np.uint64), np.array([0, 1], np.uint32), np.ones(2), x, x, np.ones(2),
                      np.empty(2), np.empty((2, 3)))
            DF = np.zeros((2, 6))
            part = np.empty((1, 4))
            k["push"](xf, xf, xf, xf, DF, DF.copy(), 0, 1, part)
            k["mix"](xf, DF, np.zeros(2), 1, np.empty(6))
            _LOOP[key] = k
        except Exception:  # pragma: no cover - numba missing or broken
            _LOOP[key] = False
    return _LOOP[key]


def warmup_kernels() -> bool:
    """Compile (or load from numba's cache) the serial kernels of the solver and of
    :mod:`sshade.arap.kernels`, e.g. before forking worker processes. Returns whether numba
    is usable."""
    ok = bool(warmup_energy_kernels() and loop_kernels(False))
    if ok:  # the L-BFGS kernels
        N, z = 3, np.zeros(3)
        lbfgs_pair(z, z, z, z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy())
        lbfgs_two_loop(np.zeros((1, N)), np.zeros((1, N)), np.zeros((1, N)), np.zeros(1), np.zeros(1, np.int64),
                       z, z, 1.0, np.empty(N), np.empty(N), np.empty(1))
    return ok

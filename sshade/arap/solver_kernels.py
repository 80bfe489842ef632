"""Numba kernels of the solver's loop (:mod:`sshade.arap.solver`) and of its accelerators
(:mod:`sshade.arap.accelerate`), with their lazy compilation.

``set_rows``, ``max_move``, ``grad`` (the stopping test's gradient in CSR, kept for the
L-BFGS direction), ``push`` /
``mix`` (Anderson's history and mixing; sums over fixed chunks of :data:`CHUNK`, so the
same floats whatever the thread count), :func:`lbfgs_update` and
:func:`lbfgs_direction` (L-BFGS's compact form).
:func:`loop_kernels` and :func:`anderson_kernels` compile (or load from numba's cache)
the serial or parallel variants on first use; :func:`warmup_kernels` the serial kernels
of an L-BFGS solve, :mod:`sshade.arap.kernels` included.
"""
from __future__ import annotations

import numpy as np

from .kernels import warmup_energy_kernels
from .threads import note_launch

try:  # numba is a dependency of the package; without it the numpy paths are used
    import numba as nb
except ImportError:  # pragma: no cover
    nb = None

__all__ = ["CHUNK", "LBFGS_BLOCK", "LBFGS_HISTORY_DTYPE", "loop_kernels", "anderson_kernels", "lbfgs_update",
           "lbfgs_direction", "warmup_kernels", "warmup_step_kernels", "warmup_lbfgs_kernels"]

#: the storage of L-BFGS's history ``S``, ``Z`` (:class:`sshade.arap.accelerate.LBFGS`): each
#: pair is rounded once to float32 when it is stored, and every inner product and direction
#: uses the stored (rounded) pair in float64 arithmetic, so the quasi-Newton matrix is that of
#: the rounded pairs. Half the bytes of the two passes over the history, which are bound by
#: memory at full resolution.
LBFGS_HISTORY_DTYPE = np.float32

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


#: L-BFGS's passes run over blocks of LBFGS_BLOCK entries (their dot products summed per
#: block, then over the blocks: the same floats whatever the caller, for one machine's
#: vector width).
LBFGS_BLOCK = 2048

if nb is not None:
    # reassociated sums (vectorised): the order is fixed by the block and the vector width
    _njit_fm = nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "nsz"})

    @_njit_fm
    def lbfgs_update(x, g, grad, prev, hist, slot, new, old, dots):
        """One pass of L-BFGS's compact form (Byrd, Nocedal & Schnabel 1994): the plain
        step's ``z = x - g``, the new pair (if ``new``) ``s = x - x_prev``, ``y = grad -
        grad_prev``, ``H0 y = z - z_prev`` into ``S[slot]``, ``Z[slot]``, the previous
        point set to ``(x, grad, z)``, and the inner products with the kept pairs ``old``
        (k,) (slots) into ``dots`` (4, m) by slot: ``S_i . grad``, ``Z_i . grad``,
        ``S_i . y``, ``Z_i . y`` (the last two only if ``new``; the new pair's own at
        ``slot``). ``x``, ``g``, ``grad``: flat (N,) vectors; ``prev`` (3, N): the rows
        ``x_prev``, ``grad_prev``, ``z_prev``; ``hist`` (2, m, N) float32 or float64: the
        histories ``S``, ``Z``; the new pair's products use its stored (rounded) values.
        Returns ``(s.s, y.y)``."""
        S = hist[0]; Z = hist[1]
        x_prev = prev[0]; grad_prev = prev[1]; z_prev = prev[2]
        N = x.shape[0]
        k = old.shape[0]
        for a in range(4):
            for i in range(dots.shape[1]):
                dots[a, i] = 0.0
        ss = 0.0
        yy = 0.0
        yb = np.empty(LBFGS_BLOCK)
        for c0 in range(0, N, LBFGS_BLOCK):  # block views: contiguous loops that vectorise
            c1 = min(N, c0 + LBFGS_BLOCK)
            n = c1 - c0
            xc = x[c0:c1]; gc = g[c0:c1]; grc = grad[c0:c1]
            xp = x_prev[c0:c1]; gp = grad_prev[c0:c1]; zp = z_prev[c0:c1]
            if new:
                sc = S[slot, c0:c1]; hc = Z[slot, c0:c1]
                p0 = 0.0; p1 = 0.0; p2 = 0.0; p3 = 0.0; p4 = 0.0; p5 = 0.0
                for i in range(n):
                    zj = xc[i] - gc[i]
                    yj = grc[i] - gp[i]
                    sc[i] = xc[i] - xp[i]; hc[i] = zj - zp[i]; yb[i] = yj
                    sj = np.float64(sc[i]); hj = np.float64(hc[i])  # the stored pair, rounded to its dtype
                    xp[i] = xc[i]; gp[i] = grc[i]; zp[i] = zj
                    p0 += sj * grc[i]; p1 += hj * grc[i]; p2 += sj * yj; p3 += hj * yj
                    p4 += sj * sj; p5 += yj * yj
                dots[0, slot] += p0; dots[1, slot] += p1; dots[2, slot] += p2; dots[3, slot] += p3
                ss += p4
                yy += p5
            else:
                for i in range(n):
                    xp[i] = xc[i]; gp[i] = grc[i]; zp[i] = xc[i] - gc[i]
            for t in range(k):
                r = old[t]
                sr = S[r, c0:c1]; zr = Z[r, c0:c1]
                p0 = 0.0; p1 = 0.0; p2 = 0.0; p3 = 0.0
                if new:
                    for i in range(n):
                        sv = sr[i]; zv = zr[i]; gj = grc[i]; yj = yb[i]
                        p0 += sv * gj; p1 += zv * gj; p2 += sv * yj; p3 += zv * yj
                else:
                    for i in range(n):
                        p0 += sr[i] * grc[i]; p1 += zr[i] * grc[i]
                dots[0, r] += p0; dots[1, r] += p1; dots[2, r] += p2; dots[3, r] += p3
        return ss, yy

    # inlined into its one caller (numba IR): a kernel called from another kernel is also
    # linked into the caller's machine code as a weak symbol, and which copy runs would
    # then depend on whether the callee was compiled in this process or the caller was
    # loaded from numba's cache (the copies round differently in the fastmath caller)
    @nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")
    def _compact_coefficients(SY, YZ, Sg, Zg, idx, gamma, cs, cz):
        """The compact form's coefficients (Byrd, Nocedal & Schnabel 1994, eq. 2.6; pairs
        ``idx`` oldest first): ``H grad = gamma z + S^T cs + Z^T cz`` with ``R`` the upper
        triangle of ``S^T Y``, ``D`` its diagonal, ``u = S^T grad``, ``v = gamma Z^T grad``:
        ``p = R^-1 u``, ``cs = R^-T ((D + gamma Y^T Z) p - v)``, ``cz = -gamma p``."""
        k = idx.shape[0]
        p = np.empty(k)
        for a in range(k - 1, -1, -1):  # back substitution: R p = u
            acc = Sg[idx[a]]
            for b in range(a + 1, k):
                acc -= SY[idx[a], idx[b]] * p[b]
            p[a] = acc / SY[idx[a], idx[a]]
        w = np.empty(k)
        for a in range(k):
            acc = SY[idx[a], idx[a]] * p[a] - gamma * Zg[idx[a]]
            for b in range(k):
                acc += gamma * YZ[idx[a], idx[b]] * p[b]
            w[a] = acc
        for a in range(k):  # forward substitution: R^T cs = w
            acc = w[a]
            for b in range(a):
                acc -= SY[idx[b], idx[a]] * cs[b]
            cs[a] = acc / SY[idx[a], idx[a]]
            cz[a] = -gamma * p[a]

    @_njit_fm
    def lbfgs_direction(hist, prods, dots, idx, gamma, z, grad, d):
        """The L-BFGS direction ``d = -H grad`` (N,) from the compact form (pairs ``idx``
        (k,), slots oldest first; :func:`_compact_coefficients`) with the initial Hessian
        ``gamma H0``, ``H0 grad = z``, ``H0 y_i = Z_i`` (``H0`` unscaled without pairs);
        returns the slope ``grad . d``. ``hist`` (2, m, N): ``S``, ``Z``; ``prods`` (2, m,
        m): ``SY``, ``YZ``; ``dots`` (4, m): :func:`lbfgs_update`'s, rows 0 and 1
        (``S_i . grad``, ``Z_i . grad``) read. One pass over the kept pairs, block by block."""
        S = hist[0]; Z = hist[1]
        N = z.shape[0]
        k = idx.shape[0]
        if k == 0:
            gamma = 1.0
        cs = np.empty(k)
        cz = np.empty(k)
        _compact_coefficients(prods[0], prods[1], dots[0], dots[1], idx, gamma, cs, cz)
        acc = np.empty(LBFGS_BLOCK)
        slope = 0.0
        for c0 in range(0, N, LBFGS_BLOCK):  # block views: contiguous loops that vectorise
            c1 = min(N, c0 + LBFGS_BLOCK)
            n = c1 - c0
            zc = z[c0:c1]
            for i in range(n):
                acc[i] = gamma * zc[i]
            for t in range(k):
                a = cs[t]
                b = cz[t]
                sr = S[idx[t], c0:c1]; zr = Z[idx[t], c0:c1]
                for i in range(n):
                    acc[i] += a * sr[i] + b * zr[i]
            dc = d[c0:c1]; gc = grad[c0:c1]
            part = 0.0
            for i in range(n):
                v = -acc[i]
                dc[i] = v
                part += gc[i] * v
            slope += part
        return slope


def _numpy_lbfgs_update(x, g, grad, prev, hist, slot, new, old, dots):
    """:func:`lbfgs_update` in numpy (numba unusable)."""
    S, Z = hist
    x_prev, grad_prev, z_prev = prev
    z = x - g
    dots[:] = 0.0
    ss = yy = 0.0
    if new:
        y = grad - grad_prev
        np.subtract(x, x_prev, out=S[slot])  # rounded to the history's dtype
        np.subtract(z, z_prev, out=Z[slot])
        s, h = S[slot].astype(np.float64), Z[slot].astype(np.float64)
        dots[:, slot] = (s @ grad, h @ grad, s @ y, h @ y)
        ss, yy = float(s @ s), float(y @ y)
    x_prev[:] = x
    grad_prev[:] = grad
    z_prev[:] = z
    for r in old:
        dots[0, r], dots[1, r] = S[r] @ grad, Z[r] @ grad
        if new:
            dots[2, r], dots[3, r] = S[r] @ y, Z[r] @ y
    return ss, yy


def _numpy_lbfgs_direction(hist, prods, dots, idx, gamma, z, grad, d):
    """:func:`lbfgs_direction` in numpy (numba unusable)."""
    S, Z = hist
    SY, YZ = prods
    Sg, Zg = dots[0], dots[1]
    if len(idx) == 0:
        np.negative(z, out=d)
        return float(grad @ d)
    R = np.triu(SY[np.ix_(idx, idx)])
    p = np.linalg.solve(R, Sg[idx])
    w = (np.diag(np.diag(R)) + gamma * YZ[np.ix_(idx, idx)]) @ p - gamma * Zg[idx]
    cs = np.linalg.solve(R.T, w)
    d[:] = -(gamma * z + cs @ S[idx] - gamma * (p @ Z[idx]))
    return float(grad @ d)


if nb is None:  # pragma: no cover - numba unusable
    lbfgs_update, lbfgs_direction = _numpy_lbfgs_update, _numpy_lbfgs_direction


_LOOP = {1: None, 2: None}  # None: not tried; False: unusable; else the kernels
_ANDERSON = {1: None, 2: None}


def _compiled(cache: dict, parallel: bool, make):
    """``cache``'s kernels for ``parallel`` (``make(parallel)`` on first use: compiles,
    or loads from numba's cache, and calls them once), or False when numba is unusable.
    The parallel variants start numba's thread pool."""
    key = 2 if parallel else 1
    if cache[key] is None:
        try:
            if parallel:
                note_launch()
            cache[key] = make(parallel)
        except Exception:  # pragma: no cover - numba missing or broken
            cache[key] = False
    return cache[key]


def _make_loop(parallel: bool) -> dict:
    k = {"set_rows": _set_rows, "max_move": _max_move, "grad": _grad_parallel if parallel else _grad_serial}
    x = np.zeros((2, 3))
    k["set_rows"](np.zeros((2, 3)), np.arange(2, dtype=np.uint32), x)
    k["max_move"](x, x)
    k["grad"](np.array([0, 1, 2], np.uint64), np.array([0, 1], np.uint32), np.ones(2), x, x, np.ones(2),
              np.empty(2), np.empty((2, 3)))
    return k


def _make_anderson(parallel: bool) -> dict:
    k = {"push": _push_parallel if parallel else _push_serial, "mix": _mix_parallel if parallel else _mix_serial}
    xf = np.zeros(6)
    DF = np.zeros((2, 6))
    k["push"](xf, xf, xf, xf, DF, DF.copy(), 0, 1, np.empty((1, 4)))
    k["mix"](xf, DF, np.zeros(2), 1, np.empty(6))
    return k


def loop_kernels(parallel: bool):
    """``dict`` of the compiled loop kernels (serial or parallel variants: ``"set_rows"``,
    ``"max_move"``, ``"grad"``), or False when numba is unusable. Compiling the parallel
    variants starts numba's thread pool."""
    return _compiled(_LOOP, parallel, _make_loop)


def anderson_kernels(parallel: bool):
    """``dict`` of Anderson's compiled kernels (serial or parallel variants: ``"push"``,
    ``"mix"``), or False when numba is unusable; compiled on first use only, since the
    default L-BFGS (and so SShaDe's first call) never runs them."""
    return _compiled(_ANDERSON, parallel, _make_anderson)


def warmup_kernels() -> bool:
    """Compile (or load from numba's cache) the serial kernels of the solver and of
    :mod:`sshade.arap.kernels` (:func:`warmup_step_kernels`, :func:`warmup_lbfgs_kernels`),
    e.g. before forking worker processes. Returns whether numba is usable."""
    return warmup_step_kernels() and warmup_lbfgs_kernels()


def warmup_step_kernels() -> bool:
    """Compile (or load) the energy, local-step, right-hand-side and gradient kernels (serial).
    Returns whether numba is usable."""
    return bool(warmup_energy_kernels() and loop_kernels(False))


def warmup_lbfgs_kernels() -> bool:
    """Compile (or load) L-BFGS's update and direction kernels. Returns whether numba is usable."""
    if nb is None:  # pragma: no cover
        return False
    N, z = 3, np.zeros(3)
    hist, dots = np.zeros((2, 1, N), LBFGS_HISTORY_DTYPE), np.zeros((4, 1))
    one = np.zeros(1, np.int64)
    lbfgs_update(z, z, z, np.zeros((3, N)), hist, 0, True, one[:0], dots)
    lbfgs_direction(hist, np.ones((2, 1, 1)), dots, one, 1.0, z, z, np.empty(N))
    return True

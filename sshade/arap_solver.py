"""Converged ARAP: local/global with one prefactored Laplacian, Anderson acceleration and
an energy safeguard, stopped by an energy-and-gradient criterion.

Energy and operators: :mod:`sshade.arap_energy` (libigl's "spokes" and
"spokes_and_rims" with libigl's cotangent weights, so one plain iteration here equals one
``igl.arap_solve`` iteration up to libigl's single-precision rotation fit).

Algorithm
---------
* Default iteration (``accelerate="lbfgs"``): L-BFGS on the free vertices with the global
  step's matrix as initial Hessian (Liu, Bouaziz & Kavan 2017) and Armijo backtracking;
  see :class:`_LBFGS`. The Anderson variant is described below.
* Fixed-point map ``G`` on the free vertices ``x``: local step (optimal rotations
  ``R*(x)``, batched 3x3 polar decomposition) then global step
  ``L_ff G(x) = K(R*(x))_f - L_fb t`` with ONE sparse Cholesky factorisation of the
  free-free block of the cotangent Laplacian, reused by every iteration and solved for
  the 3 coordinate columns at once.
* Anderson acceleration with window ``m`` (Peng, Deng, Zhang, Liu, "Anderson Acceleration
  for Geometry Optimization and Physics Simulation", ACM TOG 37(4), SIGGRAPH 2018,
  Algorithm 2): ``x+ = G(x_k) - dG theta`` with ``theta = argmin ||f_k - dF theta||``,
  ``f = G(x) - x``, over the last ``m`` differences of accepted iterates. Safeguard (same
  paper): the accelerated point is accepted only if its energy is below the energy of
  the last accepted iterate; otherwise the plain step ``G(x_k)`` (already computed) is
  taken and the history is reset. Accepted energies are therefore monotonically
  non-increasing (local/global never increases the energy).
* Stopping (:class:`Criterion`): both the relative energy decrease over the last
  accepted iteration and a scale-free gradient norm are below their thresholds.

Linear solvers measured on the 173k-vertex subdivided armadillo (free-free block of the
cotangent Laplacian, 172,766 unknowns, 2 cores; factorisation / solve with 3 right-hand
sides / extra resident memory): cholespy 2.2 (CHOLMOD) 1.6 s / 0.02 s / 125 MB;
scipy ``splu`` (COLAMD) 1.6 s / 0.06 s / 270 MB; scipy ``factorized`` 1.6 s / 0.10 s;
libigl ``min_quad_with_fixed`` 0.7 s / 0.06 s / 170 MB; sksparse-minimal 0.6 s / 0.06 s;
qdldl 0.8 s / 0.06 s; pypardiso 0.7 s / 0.16 s (pulls ~940 MB of MKL). scikit-sparse has
no binary wheel. The default is cholespy (fastest solve, which is paid every iteration)
with scipy's ``splu`` as the fallback when cholespy cannot be imported.

Cost of one iteration
---------------------
Everything per iteration runs in preallocated arrays: the fused local step and the
``K(R)`` kernel of :mod:`sshade.arap_energy`, CHOLMOD's solve, a numba CSR kernel for the
stopping test's gradient ``2 L_ff (x - G(x))``, and Anderson's history (``DF``/``DG`` ring
buffers; the Gram matrix gains one row per iteration, computed in the same pass that
writes the new differences and ``DF f``, with the dot products summed over fixed chunks so
that the floats do not depend on the number of threads). From 20k vertices the iteration
runs in a cache-friendly vertex numbering (:func:`sshade.arap_energy.locality_order`) and
the numba kernels use ``threads`` (default automatic: 1 or ``NUMBA_NUM_THREADS``, serial
below 20k vertices and inside worker processes). On the 200k-vertex armadillo (spokes-and-rims,
2-core machine, ``benchmarks/arap_iteration.py``), seconds per accelerated iteration:

===========================  =======  ======  ======  ========  ========  =====
                             local    K(R)    solve   gradient  Anderson  total
===========================  =======  ======  ======  ========  ========  =====
before these kernels         0.134    0.031   0.035   0.002     (0.037)   0.239
1 thread                     0.046    0.009   0.034   0.004     0.007     0.102
2 threads (quiet machine)    0.026    0.005   0.034   0.003     0.005     0.074
libigl ``arap_solve``                                                     0.311
===========================  =======  ======  ======  ========  ========  =====

With L-BFGS (the default iteration; its direction, in the "Anderson" column, is the
two-loop recursion with memory 10 in serial kernels), quiet machine, same mesh: 0.130 s
(1 thread) / 0.108 s (automatic threads; direction 0.034 s) per iteration, against
Anderson's 0.094 / 0.070 s and libigl's 0.309 s; it needs far fewer iterations on human
bodies (see :func:`solve_arap`, ``accelerate``).

(before: local = covariances 0.019 + polar 0.069 + energy 0.046; the gradient's sparse
product and Anderson's einsums were in the 0.037 of loop glue.) With the other core busy,
2 threads made the iterations slower, not faster (straggling parallel regions, and
OpenMP workers spinning during the serial solve): the automatic mode (``threads=None``)
therefore times both and keeps the faster (:class:`_ThreadPicker`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .arap import ArapResult, rigid_fit
from .arap_energy import (ENERGIES, ArapOperators, _fused, _note_launch, _numba_threads, build_operators,
                          resolve_threads)
from .errors import SShaDeError

__all__ = ["Criterion", "DEFAULT_CRITERION", "DEEP_CRITERION", "LaplacianSolver", "solve_arap", "warmup_kernels",
           "gradient_norm", "LINEAR_SOLVERS", "ACCELERATIONS"]

LINEAR_SOLVERS = ("auto", "cholespy", "scipy", "igl")
#: the iterations of :func:`solve_arap` (``accelerate``)
ACCELERATIONS = ("lbfgs", "anderson", "none")

# ------------------------------------------------------------- numba helpers of the loop
try:  # numba is a dependency of the package; without it the numpy paths are used
    import numba as _nb
except ImportError:  # pragma: no cover
    _nb = None

#: vertices from which :func:`solve_arap` renumbers the mesh for locality by default
#: (:func:`sshade.arap_energy.locality_order`; below, everything fits in the L2 cache).
REORDER_MIN_VERTICES = 20_000

# The Anderson dot products are summed over fixed chunks of _CHUNK entries, then over the
# chunks: the same floats whatever the number of threads.
_CHUNK = 8192

if _nb is not None:
    _prange = _nb.prange
    _njit = _nb.njit(cache=True, nogil=True, error_model="numpy")
    _njit_par = _nb.njit(cache=True, nogil=True, error_model="numpy", parallel=True)

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
    def _grad_rows(r0, r1, ptr, idx, val, x, g, mass, q):
        """Rows ``r0:r1`` of the gradient ``2 A (x - g)`` (``A`` in CSR, scipy's order of
        summation): ``q[i] = ||grad_i||^2 / (4 mass[i])``."""
        for i in range(r0, r1):
            a0 = 0.0; a1 = 0.0; a2 = 0.0
            for jj in range(ptr[i], ptr[i + 1]):
                j = idx[jj]
                v = val[jj]
                a0 += v * (x[j, 0] - g[j, 0]); a1 += v * (x[j, 1] - g[j, 1]); a2 += v * (x[j, 2] - g[j, 2])
            a0 = 2.0 * a0; a1 = 2.0 * a1; a2 = 2.0 * a2
            q[i] = (a0 * a0 + a1 * a1 + a2 * a2) / (4.0 * mass[i])

    @_njit
    def _grad_serial(ptr, idx, val, x, g, mass, q):
        _grad_rows(0, q.shape[0], ptr, idx, val, x, g, mass, q)

    @_njit_par
    def _grad_parallel(ptr, idx, val, x, g, mass, q):
        n = q.shape[0]
        for c in _prange((n + 2047) // 2048):
            _grad_rows(c * 2048, min(n, (c + 1) * 2048), ptr, idx, val, x, g, mass, q)

    @_nb.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "nsz"})
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
        """Chunk ``c`` (entries ``c _CHUNK ...``) of the Anderson update with the accepted
        ``(x, g)`` after ``(x_prev, g_prev)`` (flat (N,) arrays), ``f = g - x``:
        ``DF[slot] = f - f_prev``, ``DG[slot] = g - g_prev``, and the chunk's partial dot
        products ``part[c, j] = DF[slot] . DF[j]``, ``part[c, m + j] = DF[j] . f``
        (``j < nh``)."""
        N = x.shape[0]
        i0 = c * _CHUNK
        n = min(N, i0 + _CHUNK) - i0
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
        for c in _prange(part.shape[0]):
            _push_chunk(c, x, g, x_prev, g_prev, DF, DG, slot, nh, part)

    @_njit
    def _mix_range(i0, i1, g, DG, theta, nh, out):
        """``out = g - sum_{j < nh} theta_j DG[j]`` on entries ``i0:i1``."""
        for i in range(i0, i1):
            t = 0.0
            for j in range(nh):
                t += theta[j] * DG[j, i]
            out[i] = g[i] - t

    @_njit
    def _mix_serial(g, DG, theta, nh, out):
        _mix_range(0, out.shape[0], g, DG, theta, nh, out)

    @_njit_par
    def _mix_parallel(g, DG, theta, nh, out):
        N = out.shape[0]
        for c in _prange((N + _CHUNK - 1) // _CHUNK):
            _mix_range(c * _CHUNK, min(N, (c + 1) * _CHUNK), g, DG, theta, nh, out)


_HELPERS = {1: None, 2: None}  # None: not tried; False: unusable; else the kernels


if _nb is not None:
    @_njit
    def _lbfgs_two_loop(S, Y, Z, rho, order, grad, z, q, r, alpha):
        """L-BFGS two-loop recursion (Nocedal & Wright, Alg. 7.4) with ``H0 y_i = Z_i``
        and ``H0 grad = z``: writes the quasi-Newton step ``r = H grad`` (N,) and returns
        ``grad . r``. ``order``: ring slots, newest first. Serial and deterministic."""
        N = grad.shape[0]
        for j in range(N):
            q[j] = grad[j]
            r[j] = z[j]
        for t in range(order.shape[0]):
            i = order[t]
            a = 0.0
            for j in range(N):
                a += S[i, j] * q[j]
            a *= rho[i]
            alpha[t] = a
            for j in range(N):
                q[j] -= a * Y[i, j]
                r[j] -= a * Z[i, j]
        for t in range(order.shape[0] - 1, -1, -1):
            i = order[t]
            b = 0.0
            for j in range(N):
                b += Y[i, j] * r[j]
            c = alpha[t] - rho[i] * b
            for j in range(N):
                r[j] += c * S[i, j]
        sl = 0.0
        for j in range(N):
            sl += grad[j] * r[j]
        return sl

    @_njit
    def _lbfgs_pair(x, grad, z, x_prev, grad_prev, z_prev, s, y, zz):
        """New curvature pair into (s, y, zz) and the previous point updated to
        (x, grad, z); returns (s.y, s.s, y.y)."""
        sy = 0.0
        ss = 0.0
        yy = 0.0
        for j in range(x.shape[0]):
            a = x[j] - x_prev[j]
            b = grad[j] - grad_prev[j]
            s[j] = a
            y[j] = b
            zz[j] = z[j] - z_prev[j]
            sy += a * b
            ss += a * a
            yy += b * b
            x_prev[j] = x[j]
            grad_prev[j] = grad[j]
            z_prev[j] = z[j]
        return sy, ss, yy


else:  # pragma: no cover - numpy versions of the two L-BFGS kernels
    def _lbfgs_two_loop(S, Y, Z, rho, order, grad, z, q, r, alpha):
        q[:] = grad
        r[:] = z
        for t, i in enumerate(order):
            alpha[t] = rho[i] * np.einsum("j,j->", S[i], q)
            q -= alpha[t] * Y[i]
            r -= alpha[t] * Z[i]
        for t in range(len(order) - 1, -1, -1):
            i = order[t]
            r += (alpha[t] - rho[i] * np.einsum("j,j->", Y[i], r)) * S[i]
        return float(np.einsum("j,j->", grad, r))

    def _lbfgs_pair(x, grad, z, x_prev, grad_prev, z_prev, s, y, zz):
        np.subtract(x, x_prev, out=s)
        np.subtract(grad, grad_prev, out=y)
        np.subtract(z, z_prev, out=zz)
        x_prev[:] = x
        grad_prev[:] = grad
        z_prev[:] = z
        return (float(np.einsum("j,j->", s, y)), float(np.einsum("j,j->", s, s)),
                float(np.einsum("j,j->", y, y)))


def _helpers(parallel: bool):
    """``dict`` of the compiled loop kernels (serial or parallel variants), or False."""
    key = 2 if parallel else 1
    if _HELPERS[key] is None:
        try:
            if parallel:
                _note_launch()
            k = {"set_rows": _set_rows, "max_move": _max_move,
                 "grad": _grad_parallel if parallel else _grad_serial,
                 "push": _push_parallel if parallel else _push_serial,
                 "mix": _mix_parallel if parallel else _mix_serial}
            x = np.zeros((2, 3)); xf = x.reshape(-1)
            k["set_rows"](np.zeros((2, 3)), np.arange(2, dtype=np.uint32), x)
            k["max_move"](x, x)
            k["grad"](np.array([0, 1, 2], np.uint64), np.array([0, 1], np.uint32), np.ones(2), x, x, np.ones(2),
                      np.empty(2))
            DF = np.zeros((2, 6)); part = np.empty((1, 4))
            k["push"](xf, xf, xf, xf, DF, DF.copy(), 0, 1, part)
            k["mix"](xf, DF, np.zeros(2), 1, np.empty(6))
            _HELPERS[key] = k
        except Exception:  # pragma: no cover - numba missing or broken
            _HELPERS[key] = False
    return _HELPERS[key]


def warmup_kernels() -> bool:
    """Compile (or load from numba's cache) the serial kernels of the solver and of
    :mod:`sshade.arap_energy`, e.g. before forking worker processes. Returns whether numba
    is usable."""
    from .arap_energy import warmup_kernels as _warm_energy
    ok = bool(_warm_energy() and _helpers(False))
    if ok:  # the L-BFGS kernels
        N, z = 3, np.zeros(3)
        _lbfgs_pair(z, z, z, z.copy(), z.copy(), z.copy(), z.copy(), z.copy(), z.copy())
        _lbfgs_two_loop(np.zeros((1, N)), np.zeros((1, N)), np.zeros((1, N)), np.zeros(1), np.zeros(1, np.int64),
                        z, z, np.empty(N), np.empty(N), np.empty(1))
    return ok


class _ThreadPicker:
    """Threads of the loop's kernels in the automatic mode: 1 or ``tmax``, whichever ran
    the iterations faster (the results are the same to the bit). The other choice is
    re-timed every ``probe`` iterations, so that the pick follows the load of a shared
    machine: there a parallel region waits for its slowest thread, and numba's OpenMP
    workers spin after each region, taking CPU from the serial Cholesky solve (measured
    on the 2-core machine with one other job running: 2.6x slower iterations with 2
    threads than with 1).
    """

    def __init__(self, tmax: int, probe: int = 16):
        self.tmax, self.probe = tmax, probe
        self.cost = {tmax: None, 1: None}  # smoothed seconds per local step
        self.cur, self.best, self.count, self.n_par = tmax, tmax, 0, 0

    def record(self, t: int, dt: float) -> None:
        """Account an iteration run with ``t`` threads in ``dt`` seconds; pick the next."""
        c = self.cost[t]
        self.cost[t] = dt if c is None else 0.5 * (c + dt)
        self.count += 1
        self.n_par += t > 1
        other = 1 if t > 1 else self.tmax
        if self.cost[other] is None:
            self.cur = other
            return
        self.best = min(self.cost, key=self.cost.get)
        worse = 1 if self.best > 1 else self.tmax
        self.cur = worse if self.count % self.probe == 0 else self.best


class _Anderson:
    """Anderson acceleration's history in preallocated arrays (Peng et al. 2018, Alg. 2).

    ``DF``/``DG`` (m, N) hold the last ``m`` differences of ``f = G(x) - x`` and of
    ``G(x)`` between consecutive accepted iterates (ring buffer, slot ``pos``); the Gram
    matrix ``DF DF^T`` is updated one row per iteration instead of recomputed, in the
    same pass as the new differences and ``DF f``. The previous accepted ``(x, g)`` are
    kept by reference (never overwritten: the candidates go to two alternating buffers,
    the one not holding the current ``x``). ``kerns``: ``{threads: kernels}``
    (:func:`_helpers`) or None (numpy); ``threads`` may change between steps.
    """

    def __init__(self, m: int, N: int, kerns, threads: int):
        self.m, self.N, self.kerns, self.threads = m, N, kerns, threads
        self.kern = kerns[1] if kerns else None
        self.DF = np.empty((m, N))
        self.DG = np.empty((m, N))
        self.gram = np.zeros((m, m))
        self.part = np.empty(((N + _CHUNK - 1) // _CHUNK, 2 * m))
        self.buf = (np.empty(N), np.empty(N))
        self.reset()

    def reset(self):
        """Forget the history (after a rejected accelerated step)."""
        self.n_hist, self.pos, self.prev = 0, 0, None

    def _run(self, name, *args):
        if self.threads > 1:
            with _numba_threads(self.threads):
                return self.kerns[self.threads][name](*args)
        return self.kern[name](*args)

    def step(self, x: np.ndarray, g: np.ndarray) -> np.ndarray | None:
        """Push the accepted iterate ``x`` and its plain step ``g = G(x)`` ((nf, 3) each,
        C-contiguous, not modified afterwards); return the accelerated candidate
        ``G(x) - dG theta`` ((nf, 3), in a buffer of this object, never aliasing ``x``)
        or None (no history yet, or a degenerate one)."""
        m, xv, gv = self.m, x.reshape(-1), g.reshape(-1)
        prev, self.prev = self.prev, (xv, gv)
        if prev is None:
            return None
        slot = self.pos
        nh = min(self.n_hist + 1, m)
        self.pos = (slot + 1) % m
        self.n_hist = nh
        dF = self.DF[:nh]
        if self.kern:
            self._run("push", xv, gv, prev[0], prev[1], self.DF, self.DG, slot, nh, self.part)
            sums = self.part.sum(0)
            row, fdot = sums[:nh], sums[m:m + nh]
        else:  # einsum rather than BLAS: single-threaded, no thread-spinning outliers
            f = gv - xv
            np.subtract(f, prev[1] - prev[0], out=self.DF[slot])
            np.subtract(gv, prev[1], out=self.DG[slot])
            row = np.einsum("ik,k->i", dF, self.DF[slot])
            fdot = np.einsum("ij,j->i", dF, f)
        self.gram[slot, :nh] = row
        self.gram[:nh, slot] = row
        G = self.gram[:nh, :nh]
        s = np.sqrt(np.diag(G))
        if not (s > 0).all():
            return None
        theta = np.linalg.lstsq(G / np.outer(s, s), fdot / s, rcond=1e-12)[0] / s
        if not np.isfinite(theta).all():
            return None
        out = self.buf[1] if np.may_share_memory(x, self.buf[0]) else self.buf[0]
        if self.kern:
            self._run("mix", gv, self.DG, np.ascontiguousarray(theta), nh, out)
        else:
            np.subtract(gv, np.einsum("i,ij->j", theta, self.DG[:nh]), out=out)
        return out.reshape(x.shape)


class _LBFGS:
    """L-BFGS two-loop recursion with the global step's matrix as initial Hessian
    (Liu, Bouaziz, Kavan, "Quasi-Newton Methods for Real-time Simulation of Hyperelastic
    Materials", ACM TOG 36(3), 2017; Nocedal & Wright, Algorithm 7.4): ``H0 = (2 L_ff)^-1``,
    so ``H0 grad(x) = z = x - G(x)`` and ``H0 y_i`` is the difference of two ``z``: no solve
    beyond the global step's own. History in (m, N) ring buffers, ``N = 3 n_free``; the
    recursion runs in serial numba kernels (BLAS calls were 100x slower on a loaded
    2-core machine: their threads spin), about ``4 m + 4`` passes over ``N`` numbers.
    """

    def __init__(self, m: int, Lff):
        self.m, self.L = m, Lff.tocsr()
        N = 3 * Lff.shape[0]
        self.S, self.Y, self.Z = np.zeros((m, N)), np.zeros((m, N)), np.zeros((m, N))
        self.rho = np.zeros(m)
        self.x_prev, self.grad_prev, self.z_prev = np.zeros(N), np.zeros(N), np.zeros(N)
        self.q, self.alpha = np.empty(N), np.empty(m)
        self.reset()

    def reset(self):
        """Forget the curvature pairs (the next direction is the plain step's)."""
        self.n_hist, self.pos, self.have_prev = 0, 0, False

    def direction(self, x: np.ndarray, g: np.ndarray):
        """Descent direction ``d`` ((nf, 3), new array) at the accepted iterate ``x`` whose
        plain step is ``g = G(x)``, and the slope ``grad(x) . d < 0``."""
        m = self.m
        z = np.subtract(x, g)
        grad = (self.L @ z).reshape(-1)
        grad *= 2.0
        z = z.reshape(-1)
        xv = np.ascontiguousarray(x).reshape(-1)
        k = self.pos
        if self.have_prev:  # new curvature pair (s, y, H0 y) into the ring
            sy, ss, yy = _lbfgs_pair(xv, grad, z, self.x_prev, self.grad_prev, self.z_prev,
                                     self.S[k], self.Y[k], self.Z[k])
            if sy > 1e-12 * np.sqrt(ss * yy):  # curvature condition
                self.rho[k] = 1.0 / sy
                self.pos = (k + 1) % m
                self.n_hist = min(self.n_hist + 1, m)
            elif self.n_hist == m:  # the rejected pair overwrote the oldest one
                self.n_hist -= 1
        else:
            self.x_prev[:] = xv
            self.grad_prev[:] = grad
            self.z_prev[:] = z
            self.have_prev = True
        order = np.array([(self.pos - 1 - i) % m for i in range(self.n_hist)], np.int64)
        r = np.empty_like(z)
        slope = -_lbfgs_two_loop(self.S, self.Y, self.Z, self.rho, order, grad, z, self.q, r, self.alpha)
        if not slope < 0:  # not a descent direction: plain step, fresh history
            self.n_hist, self.pos = 0, 0
            r = z
            slope = -float(grad @ z)
        return (-r).reshape(x.shape), slope


@dataclass(frozen=True)
class Criterion:
    """Convergence criterion of :func:`solve_arap`: stop when BOTH hold at an accepted
    iterate ``U_k``.

    * energy: ``(E_{k-1} - E_k) / E_k < etol`` (relative decrease over the last accepted
      iteration; an energy below ``1e-12 * sum_e w_e ||e_e||^2``, i.e. a rigid motion up to
      rounding, satisfies it);
    * gradient: ``gnorm(U_k) < gtol`` with the scale-free norm of :func:`gradient_norm`.

    Attributes
    ----------
    etol : float >= 0, relative energy decrease threshold (dimensionless).
    gtol : float >= 0, scale-free gradient threshold (dimensionless).

    Defaults (:data:`DEFAULT_CRITERION`: ``etol = 1e-7``, ``gtol = 1e-3``) were chosen by
    measurement so that a result reported converged lies within 0.05 % (mean) and 0.5 %
    (max) of the bounding-box diagonal from a deep reference (this solver run until the
    energy stops decreasing in float64, ``gnorm ~ 1e-8``; plain local/global run for
    thousands of iterations lands within 1e-5 % of it) on the cases of
    :mod:`sshade.arap_cases` (twisted bar 135 deg, bent cylinder 90 deg, lifted plane 20 %,
    both energies), for the accelerated AND the plain iteration. Distance of the first
    iterate meeting the criterion (mean / max, % of diag), accelerated | plain:

    ==================  ===============  =================  =================
    case                energy           accelerated        plain
    ==================  ===============  =================  =================
    twisted bar 5k      spokes_and_rims  0.002 / 0.006      0.006 / 0.017
    twisted bar 5k      spokes           0.0007 / 0.0025    0.006 / 0.015
    bent cylinder 2.5k  spokes_and_rims  0.007-0.014 / 0.05-0.12  0.021 / 0.18
    bent cylinder 2.5k  spokes           0.002 / 0.009      0.004 / 0.013
    lifted plane 40k    both             0.0001 / 0.0013    0.0008 / 0.016
    ==================  ===============  =================  =================

    The L-BFGS iteration (the default, calibrated after the table above) meets the same
    bound on the same cases, and on human bodies (its first converged iterate, mean / max):
    twisted bar 0.0020 / 0.0053, bent cylinder (spokes and rims) 0.0011 / 0.011, lifted
    plane 0.0001 / 0.0008, FAUST s1_p3 (6,890 vertices) 0.0002 / 0.0027, DeFAUST s00_p01
    (168,897 vertices) 0.0008 / 0.013. (On the bent cylinder with the spokes energy it
    converges to another, lower minimum than Anderson: energy 0.3141 against 0.3216.)

    ``gtol`` is the binding condition; 3e-3 already fails on the plain iteration of the
    bent cylinder (0.075 / 0.76), where local/global crawls for hundreds of iterations
    along a plateau (``gnorm`` ~ 8e-3, relative decrease ~ 2e-6) before reaching the
    minimum; ``etol = 1e-7`` keeps a 10x margin below that plateau's decrease.

    What it certifies: closeness to the stationary point the iteration is converging to.
    ARAP is not convex: from the same start, plain and accelerated iterations can end at
    different stationary points (seen on a finer bent cylinder, 6.5k vertices, where plain
    local/global stops at a mirror-symmetric local minimum 2 % above the one Anderson
    reaches, and on a coarse 1.2k-vertex bar twisted by 135 deg, where Anderson converges
    to the symmetric saddle that plain local/global leaves after ~4000 iterations).
    """

    etol: float = 1e-7
    gtol: float = 1e-3

    def __post_init__(self):
        if not (self.etol >= 0 and self.gtol >= 0):
            raise SShaDeError(f"criterion thresholds must be >= 0, got etol={self.etol}, gtol={self.gtol}")


DEFAULT_CRITERION = Criterion()
#: for references: stop only when the energy stops changing in float64
DEEP_CRITERION = Criterion(etol=1e-15, gtol=1e-10)


def gradient_norm(grad_f: np.ndarray, mass_f: np.ndarray, diag: float) -> float:
    """Scale-free norm of the ARAP gradient on the free vertices.

    ``gnorm = diag * sqrt( sum_i ||g_i||^2 / (4 m_i) / sum_i m_i )``, i.e. the area-weighted
    RMS over the free vertices of the force density ``g_i / (2 m_i)`` (``g = dE/dU``,
    ``m_i`` the Voronoi area of vertex ``i``), times the bounding-box diagonal.

    Why: the cotangent weights are dimensionless, so ``g / 2 = L U - K(R)`` is a length,
    and ``(L u)_i ~ -m_i (Laplace u)(x_i)``; ``g_i / (2 m_i)`` is thus a discrete
    ``Laplace(delta)`` of the residual displacement ``delta``, independent of the mesh
    resolution for a smooth residual, with units 1/length. Multiplying by ``diag`` makes
    it invariant to the scale of the shape: a smooth residual of amplitude ``a`` varying
    over the size of the shape gives ``gnorm ~ a / diag`` (times a shape factor).

    Parameters
    ----------
    grad_f : (n_f, 3) float64 gradient rows of the free vertices (mesh units).
    mass_f : (n_f,) float64 > 0 Voronoi areas of those vertices (mesh units^2).
    diag : float > 0, bounding-box diagonal of the rest mesh (mesh units).

    Returns
    -------
    float, dimensionless (0 when there is no free vertex).
    """
    if len(grad_f) == 0:
        return 0.0
    return float(diag * np.sqrt((np.einsum("ij,ij->i", grad_f, grad_f) / (4.0 * mass_f)).sum() / mass_f.sum()))


class LaplacianSolver:
    """One sparse factorisation of ``A = L[free][:, free]`` (SPD), reused for every solve.

    Parameters
    ----------
    A : (n_f, n_f) scipy.sparse matrix, symmetric positive definite.
    backend : ``"auto"`` (cholespy, else scipy), ``"cholespy"`` (CHOLMOD via the cholespy
        wheel), ``"scipy"`` (``scipy.sparse.linalg.splu`` with COLAMD ordering) or
        ``"igl"`` (libigl's ``min_quad_with_fixed``, Eigen's sparse LLT).

    Attributes
    ----------
    backend : str, the backend in use. factor_s : float, seconds spent factorising.

    Raises
    ------
    SShaDeError on an unknown backend, ``"cholespy"`` requested but not importable, or a
    matrix that is not positive definite (e.g. a connected component without a handle).
    """

    def __init__(self, A, backend: str = "auto"):
        if backend not in LINEAR_SOLVERS:
            raise SShaDeError(f"unknown linear solver {backend!r}; use one of {LINEAR_SOLVERS}")
        A = sp.csc_matrix(A)
        A.sort_indices()
        self.n = A.shape[0]
        t0 = time.perf_counter()
        if backend in ("auto", "cholespy"):
            try:
                from cholespy import CholeskySolverD, MatrixType
            except ImportError:
                if backend == "cholespy":
                    raise SShaDeError("linear solver 'cholespy' requested but the cholespy package is not installed")
                backend = "scipy"
            else:
                backend = "cholespy"
                try:
                    self._f = CholeskySolverD(self.n, A.indptr.astype(np.int32), A.indices.astype(np.int32),
                                              np.ascontiguousarray(A.data, np.float64), MatrixType.CSC)
                except ValueError as e:
                    raise SShaDeError(f"the free-vertex Laplacian is not positive definite ({e}); "
                                      "is there a connected component without a handle?") from e
        if backend == "scipy":
            from scipy.sparse.linalg import splu
            try:
                self._f = splu(A, permc_spec="COLAMD")
            except RuntimeError as e:
                raise SShaDeError(f"the free-vertex Laplacian is singular ({e}); "
                                  "is there a connected component without a handle?") from e
        elif backend == "igl":
            import igl
            self._f = igl.min_quad_with_fixed_data()
            igl.min_quad_with_fixed_precompute(A, np.zeros(0, np.int64), sp.csc_matrix((0, self.n)), True, self._f)
        self.backend = backend
        self.factor_s = time.perf_counter() - t0

    def solve(self, B: np.ndarray) -> np.ndarray:
        """Solve ``A X = B``.

        Parameters
        ----------
        B : (n_f, k) float64.

        Returns
        -------
        X : (n_f, k) float64.
        """
        B = np.ascontiguousarray(B, np.float64)
        if self.backend == "cholespy":
            X = np.empty_like(B)
            self._f.solve(B, X)
            return X
        if self.backend == "scipy":
            return self._f.solve(B)
        import igl
        return igl.min_quad_with_fixed_solve(self._f, -B, np.zeros((0, B.shape[1])), np.zeros((0, B.shape[1])))


def solve_arap(V: np.ndarray, F: np.ndarray, handles, targets, *, energy: str = "spokes_and_rims",
               U0: np.ndarray | None = None, criterion: Criterion | None = None, max_iter: int = 5000,
               accelerate: bool | str = "lbfgs", anderson_m: int | None = None, time_budget_s: float | None = None,
               callback=None, linear_solver: str = "auto",
               operators: ArapOperators | None = None, threads: int | None = None,
               reorder: bool | None = None) -> ArapResult:
    """Handle-driven ARAP deformation run to a certified convergence.

    Parameters
    ----------
    V : (n, 3) float64 rest positions (mesh units). F : (m, 3) int faces.
    handles : (h,) int unique vertex indices; targets : (h, 3) float64 their positions.
    energy : ``"spokes"`` (Sorkine & Alexa 2007) or ``"spokes_and_rims"`` (Chao et al.
        2010), libigl's definitions (:mod:`sshade.arap_energy`).
    U0 : (n, 3) float64 or None, start; default the best rigid fit of the handles
        (:func:`sshade.arap.rigid_fit`) applied to ``V`` (so a rigid handle motion is
        reproduced exactly). The handle rows are overwritten by ``targets``.
    criterion : :class:`Criterion` or None (:data:`DEFAULT_CRITERION`).
    max_iter : int >= 0, cap on accepted iterations (global solves).
    accelerate : ``"lbfgs"`` (default), ``"anderson"`` (``True`` is the same), or
        ``False`` / ``"none"``: plain local/global, i.e. libigl's iteration in float64.
        ``"lbfgs"``: L-BFGS on the free vertices with the global step's matrix as initial
        Hessian (Liu, Bouaziz & Kavan 2017), i.e. a quasi-Newton correction of the
        local/global step, with Armijo backtracking (every accepted step lowers the
        energy); its memory pairs with non-positive curvature are skipped. ``"anderson"``:
        Anderson acceleration with the energy safeguard (Peng et al. 2018). Measured
        (iterations to the criterion; distance of the result to the deep reference, mean %
        of the diagonal): DeFAUST s00_p01, 168,897 vertices, spokes-and-rims: L-BFGS 792
        iterations, 0.0008 %; Anderson not converged after 1,648 iterations (150 s),
        0.26 %. FAUST s1_p3 (6,890 vertices): L-BFGS 157, Anderson 1,265 (566 safeguard
        rejections). Bent cylinder 90 deg: 206 against 533; twisted bar 135 deg: 55
        against 57; lifted plane 40k: 49 against 38.
    anderson_m : int >= 1 or None, history window: Anderson's (Peng et al. use 5-6;
        default 5) or L-BFGS's memory (default 10).
    time_budget_s : float or None, stop (unconverged, status ``"time_budget"``) once the
        iterations have taken this many seconds.
    callback : callable or None, ``callback(k, U, E, gnorm) -> bool`` after every accepted
        iterate ``k`` (``U`` (n, 3) must not be modified); a true return value stops
        (status ``"callback"``).
    linear_solver : ``"auto"``, ``"cholespy"``, ``"scipy"`` or ``"igl"``
        (:class:`LaplacianSolver`).
    operators : :class:`sshade.arap_energy.ArapOperators` or None, precomputed for
        ``(V, F, energy)`` to reuse across calls (then ``V``/``F`` are not re-read).
    threads : int >= 1 or None, threads of the numba kernels (local step, right-hand
        side, gradient, Anderson products; the Cholesky solve is CHOLMOD's own). None:
        1 below 20k vertices or inside a worker process, else 1 or ``NUMBA_NUM_THREADS``
        (:func:`sshade.arap_energy.resolve_threads`), whichever runs the iterations
        faster, re-timed every 16 iterations (on a loaded machine parallel regions can be
        much slower than one thread: :class:`_ThreadPicker`). The iterates do not depend
        on it.
    reorder : bool or None, iterate in a cache-friendly vertex numbering
        (:func:`sshade.arap_energy.locality_order`; the result is returned in the mesh's
        numbering). None: from :data:`REORDER_MIN_VERTICES` vertices when numba is
        usable. Same iterates up to rounding (the Cholesky factor of the renumbered
        matrix rounds differently).

    Returns
    -------
    :class:`sshade.arap.ArapResult` with ``V`` (n, 3) the last accepted iterate (the one
    the reported energy and gradient belong to), ``iterations`` (accepted iterations =
    global solves), ``converged`` (the criterion was met), ``last_move`` (largest vertex
    move of the last accepted iteration, mesh units), ``precompute_s`` (operators +
    factorisation), ``solve_s`` and ``info``: ``energy`` (final E, mesh units^2),
    ``gnorm``, ``rel_decrease``, ``energy_history`` / ``gnorm_history`` (lists over accepted
    iterates, starting at ``U0``), ``n_local`` (local steps), ``n_fallback`` (rejected
    Anderson steps), ``status`` (``"converged"``, ``"max_iter"``, ``"time_budget"``,
    ``"stalled"`` = the energy no longer decreases in float64, ``"callback"``,
    ``"rigid"``), ``linear_solver``, ``factor_s``, ``etol``, ``gtol``, ``accelerate``,
    ``anderson_m``, ``energy_type``, ``threads`` (the most threads used), ``reordered``,
    ``stage_s`` (seconds spent in the local steps, right-hand sides, Cholesky solves,
    gradient norms and Anderson bookkeeping), ``parallel_fraction`` (automatic threads
    only: the fraction of iterations run with ``threads`` threads).

    Raises
    ------
    SShaDeError
        Unknown energy or linear solver, bad mesh / handles / targets / ``U0`` shapes or
        values, ``operators`` built for another energy, a connected component without a
        handle.

    Examples
    --------
    >>> from sshade.arap_cases import twisted_bar
    >>> V, F, h, T = twisted_bar(90.0, h=0.25)
    >>> res = solve_arap(V, F, h, T, energy="spokes")
    >>> res.converged
    True
    """
    from .validate import validate_handles

    t_start = time.perf_counter()
    if energy not in ENERGIES:
        raise SShaDeError(f"unknown ARAP energy {energy!r}; use one of {ENERGIES}")
    crit = DEFAULT_CRITERION if criterion is None else criterion
    if not isinstance(crit, Criterion):
        raise SShaDeError(f"criterion must be a Criterion, got {type(crit).__name__}")
    acc = {True: "anderson", False: "none", None: "none"}.get(accelerate, accelerate) \
        if isinstance(accelerate, (bool, type(None))) else str(accelerate)
    if acc not in ACCELERATIONS:
        raise SShaDeError(f"accelerate must be one of {ACCELERATIONS} (or True/False), got {accelerate!r}")
    if anderson_m is None:
        anderson_m = 10 if acc == "lbfgs" else 5
    if int(anderson_m) < 1:
        raise SShaDeError(f"anderson_m must be >= 1, got {anderson_m}")
    if int(max_iter) < 0:
        raise SShaDeError(f"max_iter must be >= 0, got {max_iter}")
    ops = operators if operators is not None else build_operators(V, F, energy)
    if ops.energy_type != energy:
        raise SShaDeError(f"operators were built for {ops.energy_type!r}, not {energy!r}")
    V = ops.V
    n = ops.n
    h, T = validate_handles(V, handles, targets)
    free = np.setdiff1d(np.arange(n), h)
    diag = ops.diag
    zero_E = 1e-12 * ops.rest_term

    if U0 is None:
        Rr, tr_ = rigid_fit(V[h], T)
        U = V @ Rr.T + tr_
    else:
        U = np.array(U0, dtype=np.float64)
        if U.shape != (n, 3) or not np.isfinite(U).all():
            raise SShaDeError(f"U0 must be a finite (n, 3) array with n={n}, got shape {U.shape}")
    U[h] = T

    info = {"energy_type": energy, "etol": crit.etol, "gtol": crit.gtol, "accelerate": acc,
            "anderson_m": int(anderson_m), "n_local": 0, "n_fallback": 0}
    if len(free) == 0:
        info.update(status="converged", energy=ops.energy(U), gnorm=0.0, rel_decrease=0.0,
                    energy_history=[], gnorm_history=[], linear_solver=None, factor_s=0.0)
        return ArapResult(V=U, iterations=0, converged=True, last_move=0.0,
                          precompute_s=time.perf_counter() - t_start, solve_s=0.0, info=info)

    from scipy.sparse.csgraph import connected_components
    ncomp, label = connected_components(ops.L, directed=False)
    if ncomp > 1:
        lacking = np.setdiff1d(np.arange(ncomp), label[h])
        if len(lacking):
            raise SShaDeError(f"{len(lacking)} of the mesh's {ncomp} connected components hold no handle "
                              f"(e.g. the one with vertex {int(np.flatnonzero(label == lacking[0])[0])}); "
                              "their position is undetermined")
    # ---- numbering: the mesh's, or a cache-friendly one (everything below lives in it)
    nthreads = resolve_threads(threads, n)
    kern = _helpers(False) if _fused(1) else False
    if not kern or (nthreads > 1 and not (_fused(nthreads) and _helpers(True))):
        nthreads = 1  # numpy paths, or parallel kernels unusable
    kerns = {1: kern, nthreads: _helpers(True)} if kern and nthreads > 1 else {1: kern}
    picker = _ThreadPicker(nthreads) if threads is None and nthreads > 1 else None
    cur = [nthreads]  # threads of the next kernel calls
    if reorder is None:
        reorder = n >= REORDER_MIN_VERTICES
    reorder = bool(reorder) and bool(kern)
    kdata = ops.kernel_data(reorder) if kern else None
    perm = None if kdata is None else kdata.perm
    if perm is not None:
        Lp = ops.L[perm][:, perm].tocsr()
        hp = kdata.inv[h]
        U = np.ascontiguousarray(U[perm])
        mass = ops.mass[perm]
    else:
        Lp, hp, mass = ops.L, h, ops.mass
    free = np.setdiff1d(np.arange(n), hp)
    Lf = Lp[free]
    Lff = Lf[:, free].tocsc()
    Lfb = Lf[:, hp]
    lin = LaplacianSolver(Lff, linear_solver)
    c_f = np.ascontiguousarray(Lfb @ T)  # (n_f, 3)
    mass_f = mass[free]
    mass_sum = mass_f.sum()
    info.update(linear_solver=lin.backend, factor_s=lin.factor_s, threads=nthreads, reordered=perm is not None)
    if kern:
        Lc = Lff.tocsr()
        Lc.sort_indices()
        L_ptr, L_idx = Lc.indptr.astype(np.uint64), Lc.indices.astype(np.uint32)
        L_val = np.ascontiguousarray(Lc.data, np.float64)
        free_u = free.astype(np.uint32)
    t_iter = time.perf_counter()
    precompute_s = t_iter - t_start

    nf = len(free)
    m = int(anderson_m)

    def run(name, *args):
        t = cur[0]
        if t > 1:
            with _numba_threads(t):
                return kerns[t][name](*args)
        return kern[name](*args)

    def to_mesh(Ux):
        """Positions in the mesh's numbering."""
        return Ux if perm is None else Ux[kdata.inv]

    warm = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()  # polar kernel warm start
    R = np.empty((n, 3, 3))  # rotations of the last local step (one buffer: see the loop)
    Ek = np.empty(n)
    B = np.empty((nf, 3))
    q = np.empty(nf)

    tm = dict.fromkeys(("local", "rhs", "solve", "gradient", "anderson"), 0.0)  # seconds per stage
    clock = time.perf_counter

    def local(x):
        """Rotations (into R) and energy at free positions x (nf, 3)."""
        t0 = clock()
        if kern:
            kern["set_rows"](U, free_u, x)
        else:
            U[free] = x
        info["n_local"] += 1
        E = ops.local_step(U, R, Ek, warm, cur[0], kdata)
        tm["local"] += clock() - t0
        return E

    def glob():
        """Global step with the rotations in R: the plain iterate G(x) (nf, 3)."""
        t0 = clock()
        ops.rhs_rows(R, free_u if kern else free, c_f, B, cur[0], kdata)
        t1 = clock()
        X = np.ascontiguousarray(lin.solve(B))
        tm["rhs"] += t1 - t0
        tm["solve"] += clock() - t1
        return X

    def gnorm(x, g):
        """Scale-free gradient norm at x, whose plain step is g (grad = 2 Lff (x - g))."""
        t0 = clock()
        if kern:
            run("grad", L_ptr, L_idx, L_val, x, g, mass_f, q)
            gn = float(diag * np.sqrt(q.sum() / mass_sum))
        else:
            gn = gradient_norm(2.0 * (Lff @ (x - g)), mass_f, diag)
        tm["gradient"] += clock() - t0
        return gn

    def max_move(a, b):
        """Largest vertex move between two (nf, 3) iterates (mesh units)."""
        if kern:
            return float(np.sqrt(kern["max_move"](a, b)))
        return float(np.sqrt(((a - b) ** 2).sum(1).max()))

    def tick(t_pass):
        """Automatic threads: time the iteration just done, pick the next mode."""
        if picker is None:
            return t_pass
        now = clock()
        picker.record(cur[0], now - t_pass)
        cur[0] = picker.cur
        if anderson is not None:
            anderson.threads = cur[0]
        return now

    # ---- start point
    lbfgs = _LBFGS(m, Lff) if acc == "lbfgs" else None
    anderson = _Anderson(m, 3 * nf, kerns if kern else None, nthreads) if acc == "anderson" else None
    x = U[free].copy()
    E = local(x)
    g = glob()
    E_hist, G_hist = [E], []
    E_prev = np.inf
    it, last_move, status = 0, 0.0, None
    t_pass = clock()

    while True:
        # ---- convergence test at the accepted iterate x (energy E, plain step g = G(x))
        gn = gnorm(x, g)
        G_hist.append(gn)
        if E <= zero_E:
            rel = 0.0
        else:
            rel = (E_prev - E) / E if np.isfinite(E_prev) else np.inf
        if rel < crit.etol and gn < crit.gtol:
            status = "converged" if it > 0 or E > zero_E else "rigid"
            break
        if callback is not None and it > 0:
            U[free] = x
            if callback(it, to_mesh(U), E, gn):
                status = "callback"
                break
        if it >= max_iter:
            status = "max_iter"
            break
        if time_budget_s is not None and time.perf_counter() - t_iter > time_budget_s:
            status = "time_budget"
            break
        if lbfgs is not None:  # ---- quasi-Newton step with Armijo backtracking
            t0 = clock()
            d, slope = lbfgs.direction(x, g)
            tm["anderson"] += clock() - t0
            alpha, E_new = 1.0, None
            while True:
                x_new = x + alpha * d
                E_try = local(x_new)
                if E_try <= E + 1e-4 * alpha * slope:
                    E_new = E_try
                    break
                if alpha < 1e-6:
                    break
                alpha *= 0.5
            if E_new is None:
                if lbfgs.n_hist:  # a bad quasi-Newton direction: forget it, plain step
                    info["n_fallback"] += 1
                    lbfgs.reset()
                    continue
                U[free] = x
                status = "stalled"
                break
            if alpha < 1.0:
                info["n_fallback"] += 1
        else:  # ---- Anderson history update with the accepted (x, g), candidate
            t0 = clock()
            x_new = anderson.step(x, g) if anderson is not None else None
            tm["anderson"] += clock() - t0
            accelerated = x_new is not None
            if not accelerated:
                x_new = g
            # R is overwritten by every local step: it holds the rotations of the last
            # evaluated candidate, which is the accepted one when glob() runs below
            E_new = local(x_new)
            if accelerated and not E_new < E:
                # safeguard: plain step from the last accepted point, reset the history
                info["n_fallback"] += 1
                anderson.reset()
                x_new = g
                E_new = local(x_new)
                accelerated = False
            if not accelerated and E_new > E:
                # a plain local/global step cannot increase E: only rounding does -> stop
                U[free] = x
                status = "stalled"
                break
        # ---- accept x_new (energy E_new; R holds its rotations)
        t0 = clock()
        last_move = max_move(x_new, x)
        tm["anderson"] += clock() - t0
        E_prev, E = E, E_new
        x = x_new
        g = glob()
        it += 1
        E_hist.append(E)
        t_pass = tick(t_pass)

    U[free] = x
    if status == "stalled":
        converged = bool(G_hist[-1] < crit.gtol)
    else:
        converged = status in ("converged", "rigid")
    if picker is not None:
        info["parallel_fraction"] = picker.n_par / max(picker.count, 1)
    info.update(status=status, energy=float(E), gnorm=float(G_hist[-1]),
                rel_decrease=float(rel) if status != "stalled" else 0.0,
                energy_history=[float(e) for e in E_hist], gnorm_history=[float(v) for v in G_hist],
                stage_s=tm)
    return ArapResult(V=np.array(to_mesh(U)), iterations=it, converged=converged, last_move=last_move,
                      precompute_s=precompute_s, solve_s=time.perf_counter() - t_iter, info=info)

"""Accelerators of the local/global iteration of :func:`sshade.arap.solver.solve_arap`.

* :class:`LBFGS` (the default): L-BFGS on the free vertices, the global step's matrix as
  initial Hessian (Liu, Bouaziz & Kavan, ACM TOG 36(3), 2017); the solver backtracks (Armijo).
* :class:`Anderson`: Anderson acceleration with window ``m`` (Peng, Deng, Zhang, Liu,
  ACM TOG 37(4), SIGGRAPH 2018, Algorithm 2); the solver applies the energy safeguard.

Histories in preallocated ring buffers; their passes over the ``N = 3 n_free`` numbers run
in :mod:`sshade.arap.solver_kernels`. Formulas: docs/implementation.md ("Implementation notes:
sshade/arap/accelerate.py").
"""
from __future__ import annotations

import numpy as np

from .solver_kernels import CHUNK, LBFGS_HISTORY_DTYPE, anderson_kernels, lbfgs_direction, lbfgs_update
from .threads import numba_threads

__all__ = ["Anderson", "LBFGS", "LBFGS_HISTORY_DTYPE"]


class Anderson:
    """Anderson acceleration's history in preallocated arrays (Peng et al. 2018, Alg. 2).

    ``DF``/``DG`` (m, N) hold the last ``m`` differences of ``f = G(x) - x`` and of
    ``G(x)`` between consecutive accepted iterates (ring buffer, slot ``pos``); the Gram
    matrix ``DF DF^T`` is updated one row per iteration instead of recomputed, in the
    same pass as the new differences and ``DF f``. The previous accepted ``(x, g)`` are
    kept by reference (never overwritten: the candidates go to two alternating buffers,
    the one not holding the current ``x``). ``kerns``: ``{threads: kernels}``
    (:func:`sshade.arap.solver_kernels.loop_kernels`: numba usable, the passes run in
    :func:`sshade.arap.solver_kernels.anderson_kernels`) or None (numpy); ``threads`` may
    change between steps.
    """

    def __init__(self, m: int, N: int, kerns, threads: int):
        self.m, self.N, self.threads = m, N, threads
        self.kern = anderson_kernels(False) if kerns else None
        self.DF = np.empty((m, N))
        self.DG = np.empty((m, N))
        self.gram = np.zeros((m, m))
        self.part = np.zeros(((N + CHUNK - 1) // CHUNK, 2 * m))  # unwritten columns stay finite
        self.buf = (np.empty(N), np.empty(N))
        self.reset()

    def reset(self):
        """Forget the history (after a rejected accelerated step)."""
        self.n_hist, self.pos, self.prev = 0, 0, None

    def restart(self):
        """A new problem on the same free vertices and ``L_ff`` (other targets): keep the
        differences and their Gram matrix (differences within one problem, where the
        targets' term of ``G`` cancels) and forget the last iterate (a difference across
        two problems would mix their targets)."""
        self.prev = None

    def _run(self, name, *args):
        par = anderson_kernels(True) if self.threads > 1 else None
        if par:  # the same floats as the serial kernels (sums over fixed chunks)
            with numba_threads(self.threads):
                return par[name](*args)
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


class LBFGS:
    """L-BFGS with the global step's matrix as initial Hessian (Liu, Bouaziz, Kavan,
    "Quasi-Newton Methods for Real-time Simulation of Hyperelastic Materials", ACM TOG
    36(3), 2017), in the compact form of Byrd, Nocedal & Schnabel ("Representations of
    quasi-Newton matrices and their use in limited memory methods", Math. Programming 63,
    1994, eq. 2.6): the matrix of Nocedal & Wright's two-loop recursion (Algorithm 7.4)
    applied in two passes that read about ``4 m`` vectors of the history, where the
    recursion reads and writes about ``11 m``. ``H0 = (2 L_ff)^-1``, so ``H0 grad(x) =
    z = x - G(x)`` and ``H0 y_i`` is the difference of two ``z``: no solve beyond the
    global step's own. ``H0`` is scaled by ``gamma = s.y / (y . H0 y)`` of the newest pair
    (Nocedal & Wright, eq. 7.20, with ``H0`` in place of the identity), which Liu et al. do
    not scale: the rotations make the energy softer than ``2 L_ff`` along the slow modes,
    where the scaled steps take fewer iterations (measured:
    benchmarks/records/lbfgs_scaling.md; docs/implementation.md, "Implementation notes:
    sshade/arap/accelerate.py"). Without history the direction is the plain step ``-z``.
    History: ``S`` and ``Z = H0 Y`` in (m, N) ring buffers, ``hist`` (2, m, N), ``N = 3
    n_free`` (``Y`` is needed only through its products, kept in ``prods`` (2, m, m):
    ``SY``, ``s_i . y_j``, and ``YZ``, ``y_i . H0 y_j``); the passes run in the serial numba kernels
    :func:`sshade.arap.solver_kernels.lbfgs_update` and ``lbfgs_direction``.
    """

    def __init__(self, m: int, Lff):
        self.m, self.L = m, Lff.tocsr()
        N = 3 * Lff.shape[0]
        self.hist = np.zeros((2, m, N), LBFGS_HISTORY_DTYPE)  # S, Z
        self.prods = np.zeros((2, m, m))  # SY, YZ
        self.prods[0] = 1.0
        self.dots = np.zeros((4, m))
        self.prev = np.zeros((3, N))  # x_prev, grad_prev, z_prev
        self.reset()

    def reset(self):
        """Forget the curvature pairs (the next direction is the plain step's)."""
        self.n_hist, self.pos, self.have_prev, self.gamma = 0, 0, False, 1.0

    def restart(self):
        """A new problem on the same free vertices and ``L_ff`` (other targets): keep the
        curvature pairs, which hold differences of positions, gradients and plain steps
        within one problem (the targets' term cancels in each), and forget the last
        iterate (a pair across two problems would mix their targets)."""
        self.have_prev = False

    def _slots(self) -> np.ndarray:
        """The kept pairs' ring slots, oldest first."""
        return np.array([(self.pos - self.n_hist + i) % self.m for i in range(self.n_hist)], np.int64)

    def direction(self, x: np.ndarray, g: np.ndarray, grad: np.ndarray | None = None):
        """Descent direction ``d`` ((nf, 3), new array) at the accepted iterate ``x`` whose
        plain step is ``g = G(x)``, and the slope ``grad(x) . d < 0``. ``grad``: (nf, 3)
        C-contiguous ``2 L_ff (x - g)`` when the caller has it (the same floats as this
        method's own product; read, not kept)."""
        m, k = self.m, self.pos
        xv, gv = np.ascontiguousarray(x).reshape(-1), np.ascontiguousarray(g).reshape(-1)
        if grad is None:
            grad = (self.L @ (x - g)).reshape(-1)
            grad *= 2.0
        else:
            grad = grad.reshape(-1)
        old = self._slots()
        new = self.have_prev
        if new and self.n_hist == m:  # the new pair takes the oldest one's slot
            old = old[1:]
        ss, yy = lbfgs_update(xv, gv, grad, self.prev, self.hist, k, new, old, self.dots)
        self.have_prev = True
        dots = self.dots
        if new:
            sy, yz = dots[2, k], dots[3, k]
            if sy > 1e-12 * np.sqrt(ss * yy) and yz > 0:  # curvature condition: keep the pair
                SY, YZ = self.prods
                SY[old, k] = dots[2, old]
                SY[k, k] = sy
                YZ[old, k] = YZ[k, old] = dots[3, old]
                YZ[k, k] = yz
                self.gamma = sy / yz
                self.pos = (k + 1) % m
                self.n_hist = min(self.n_hist + 1, m)
            elif self.n_hist == m:  # the rejected pair overwrote the oldest one
                self.n_hist -= 1
        z = self.prev[2]  # now this iterate's z
        d = np.empty_like(z)
        slope = lbfgs_direction(self.hist, self.prods, dots, self._slots(), self.gamma, z, grad, d)
        if not slope < 0:  # not a descent direction: plain step, fresh history
            self.n_hist, self.pos, self.gamma = 0, 0, 1.0
            np.negative(z, out=d)
            slope = float(grad @ d)
        return d.reshape(x.shape), slope

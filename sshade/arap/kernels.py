"""Numba kernels of the ARAP energies (the fused local step, the right-hand side ``K(R)``)
and their lazy compilation, for :mod:`sshade.arap.operators` on the arrays of
:class:`sshade.arap.kernel_data.KernelData`.

:func:`polar_kernel`, :func:`energy_kernel`, :func:`fused_kernels` (serial and parallel
apart) and :func:`fused` compile (or load from numba's cache) on first use and return
False when numba is unusable (the callers then take their numpy / scipy paths). No
result depends on the thread count. Design: docs/implementation.md ("Implementation notes:
sshade/arap/kernels.py").
"""
from __future__ import annotations

import numpy as np

from .threads import note_launch

try:  # numba is a dependency of the package; without it the numpy paths are used
    import numba as nb
except ImportError:  # pragma: no cover
    nb = None

__all__ = ["LANES", "polar_kernel", "energy_kernel", "fused_kernels", "fused", "sr_local_kernel",
           "warmup_energy_kernels"]

# Lanes of the polar kernel: LANES cells are decomposed together, every 3x3 quantity
# stored as a row of LANES values of a scratch vector, so that the Jacobi sweeps are
# loops over lanes that LLVM vectorises (AVX2/AVX-512: 4-8 cells per instruction; the
# scalar version is latency-bound on its chain of divisions and square roots). Scratch
# rows: 0-8 the matrix M, 9-17 A = M^T M, 18-26 the eigenvectors Q (then the new warm
# start), 27 the active flags, 28-36 the rotation R, 37 the trace.
LANES = 64
_SM, _SA, _SQ, _SACT, _SR, _STR = 0, 9 * LANES, 18 * LANES, 27 * LANES, 28 * LANES, 37 * LANES
_SCRATCH = 38 * LANES
# Each row's offset named (``_M01``: row 1 of M): one integer add per access instead of
# ``_SM + 1 * LANES + l``'s three, less IR for numba to type and lower (measured:
# benchmarks/records/lbfgs_compact.md); the arithmetic is the same.
(_M00, _M01, _M02, _M10, _M11, _M12, _M20, _M21, _M22) = (_SM + k * LANES for k in range(9))
(_A00, _A01, _A02, _A10, _A11, _A12, _A20, _A21, _A22) = (_SA + k * LANES for k in range(9))
(_Q00, _Q01, _Q02, _Q10, _Q11, _Q12, _Q20, _Q21, _Q22) = (_SQ + k * LANES for k in range(9))
(_R00, _R01, _R02, _R10, _R11, _R12, _R20, _R21, _R22) = (_SR + k * LANES for k in range(9))

if nb is not None:
    _prange = nb.prange
    # error_model="numpy": no ZeroDivisionError checks (they block vectorisation); none of
    # these kernels divides by zero on finite input (guarded below).
    _njit = nb.njit(cache=True, nogil=True, error_model="numpy")
    _njit_par = nb.njit(cache=True, nogil=True, error_model="numpy", parallel=True)

    @_njit
    def _polar_init(S, nl, W, k0, warm):
        """Lanes ``l < nl``: ``A = Q^T M^T M Q`` with ``Q = W[k0 + l]`` (warm) or ``Q = I``,
        from ``M`` in the scratch ``S``; lanes ``l >= nl``: ``M = A = Q = I`` (inert)."""
        for l in range(LANES):
            m00 = S[_M00 + l]; m01 = S[_M01 + l]; m02 = S[_M02 + l]
            m10 = S[_M10 + l]; m11 = S[_M11 + l]; m12 = S[_M12 + l]
            m20 = S[_M20 + l]; m21 = S[_M21 + l]; m22 = S[_M22 + l]
            q00 = 1.0; q01 = 0.0; q02 = 0.0
            q10 = 0.0; q11 = 1.0; q12 = 0.0
            q20 = 0.0; q21 = 0.0; q22 = 1.0
            if l >= nl:
                m00 = 1.0; m01 = 0.0; m02 = 0.0
                m10 = 0.0; m11 = 1.0; m12 = 0.0
                m20 = 0.0; m21 = 0.0; m22 = 1.0
                S[_M00 + l] = m00; S[_M01 + l] = m01; S[_M02 + l] = m02
                S[_M10 + l] = m10; S[_M11 + l] = m11; S[_M12 + l] = m12
                S[_M20 + l] = m20; S[_M21 + l] = m21; S[_M22 + l] = m22
            elif warm:
                k = k0 + l
                q00 = W[k, 0, 0]; q01 = W[k, 0, 1]; q02 = W[k, 0, 2]
                q10 = W[k, 1, 0]; q11 = W[k, 1, 1]; q12 = W[k, 1, 2]
                q20 = W[k, 2, 0]; q21 = W[k, 2, 1]; q22 = W[k, 2, 2]
            if warm and l < nl:  # B = M Q, A = B^T B
                b00 = m00 * q00 + m01 * q10 + m02 * q20
                b01 = m00 * q01 + m01 * q11 + m02 * q21
                b02 = m00 * q02 + m01 * q12 + m02 * q22
                b10 = m10 * q00 + m11 * q10 + m12 * q20
                b11 = m10 * q01 + m11 * q11 + m12 * q21
                b12 = m10 * q02 + m11 * q12 + m12 * q22
                b20 = m20 * q00 + m21 * q10 + m22 * q20
                b21 = m20 * q01 + m21 * q11 + m22 * q21
                b22 = m20 * q02 + m21 * q12 + m22 * q22
            else:
                b00 = m00; b01 = m01; b02 = m02
                b10 = m10; b11 = m11; b12 = m12
                b20 = m20; b21 = m21; b22 = m22
            S[_A00 + l] = b00 * b00 + b10 * b10 + b20 * b20
            S[_A01 + l] = b00 * b01 + b10 * b11 + b20 * b21
            S[_A02 + l] = b00 * b02 + b10 * b12 + b20 * b22
            S[_A10 + l] = b01 * b00 + b11 * b10 + b21 * b20
            S[_A11 + l] = b01 * b01 + b11 * b11 + b21 * b21
            S[_A12 + l] = b01 * b02 + b11 * b12 + b21 * b22
            S[_A20 + l] = b02 * b00 + b12 * b10 + b22 * b20
            S[_A21 + l] = b02 * b01 + b12 * b11 + b22 * b21
            S[_A22 + l] = b02 * b02 + b12 * b12 + b22 * b22
            S[_Q00 + l] = q00; S[_Q01 + l] = q01; S[_Q02 + l] = q02
            S[_Q10 + l] = q10; S[_Q11 + l] = q11; S[_Q12 + l] = q12
            S[_Q20 + l] = q20; S[_Q21 + l] = q21; S[_Q22 + l] = q22
            S[_SACT + l] = 1.0

    @_njit
    def _rot_coef(on, app, aqq, apq):
        """Jacobi rotation ``(c, s)`` zeroing ``apq``; ``(1, 0)`` (exact identity) if not ``on``."""
        theta = (aqq - app) / (2.0 * apq if on else 1.0)
        t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
        c = 1.0 / np.sqrt(t * t + 1.0)
        s = t * c
        return (c if on else 1.0), (s if on else 0.0)

    @_njit
    def _polar_jacobi(S):
        """Cyclic Jacobi sweeps on all lanes of ``S`` (``A`` diagonalised, ``Q`` accumulated).

        Per lane exactly the arithmetic of a scalar cyclic Jacobi: stop when ``off(A)^2 <=
        1e-34 diag(A)^2`` (at most 30 sweeps), planes (0,1), (0,2), (1,2), skipping a plane
        with ``a_pq = 0``, and updating the full ``A`` (columns, then rows). A finished or
        skipped lane gets the rotation ``(c, s) = (1, 0)``, which leaves it unchanged.
        """
        for _sweep in range(30):
            nact = 0
            for l in range(LANES):
                a00 = S[_A00 + l]; a01 = S[_A01 + l]; a02 = S[_A02 + l]
                a11 = S[_A11 + l]; a12 = S[_A12 + l]; a22 = S[_A22 + l]
                off = a01 * a01 + a02 * a02 + a12 * a12
                dg = a00 * a00 + a11 * a11 + a22 * a22
                act = S[_SACT + l] != 0.0 and off > 1e-34 * dg
                S[_SACT + l] = 1.0 if act else 0.0
                nact += 1 if act else 0
            if nact == 0:
                break
            for l in range(LANES):  # plane (0, 1)
                a00 = S[_A00 + l]; a01 = S[_A01 + l]; a02 = S[_A02 + l]
                a10 = S[_A10 + l]; a11 = S[_A11 + l]; a12 = S[_A12 + l]
                a20 = S[_A20 + l]; a21 = S[_A21 + l]
                c, s = _rot_coef(S[_SACT + l] != 0.0 and a01 != 0.0, a00, a11, a01)
                n00 = c * a00 - s * a01; n01 = s * a00 + c * a01
                n10 = c * a10 - s * a11; n11 = s * a10 + c * a11
                S[_A20 + l] = c * a20 - s * a21; S[_A21 + l] = s * a20 + c * a21
                S[_A00 + l] = c * n00 - s * n10; S[_A10 + l] = s * n00 + c * n10
                S[_A01 + l] = c * n01 - s * n11; S[_A11 + l] = s * n01 + c * n11
                S[_A02 + l] = c * a02 - s * a12; S[_A12 + l] = s * a02 + c * a12
                for r in range(3):
                    qp = S[_SQ + (3 * r + 0) * LANES + l]; qq = S[_SQ + (3 * r + 1) * LANES + l]
                    S[_SQ + (3 * r + 0) * LANES + l] = c * qp - s * qq
                    S[_SQ + (3 * r + 1) * LANES + l] = s * qp + c * qq
            for l in range(LANES):  # plane (0, 2)
                a00 = S[_A00 + l]; a01 = S[_A01 + l]; a02 = S[_A02 + l]
                a10 = S[_A10 + l]; a12 = S[_A12 + l]
                a20 = S[_A20 + l]; a21 = S[_A21 + l]; a22 = S[_A22 + l]
                c, s = _rot_coef(S[_SACT + l] != 0.0 and a02 != 0.0, a00, a22, a02)
                n00 = c * a00 - s * a02; n02 = s * a00 + c * a02
                n20 = c * a20 - s * a22; n22 = s * a20 + c * a22
                S[_A10 + l] = c * a10 - s * a12; S[_A12 + l] = s * a10 + c * a12
                S[_A00 + l] = c * n00 - s * n20; S[_A20 + l] = s * n00 + c * n20
                S[_A01 + l] = c * a01 - s * a21; S[_A21 + l] = s * a01 + c * a21
                S[_A02 + l] = c * n02 - s * n22; S[_A22 + l] = s * n02 + c * n22
                for r in range(3):
                    qp = S[_SQ + (3 * r + 0) * LANES + l]; qq = S[_SQ + (3 * r + 2) * LANES + l]
                    S[_SQ + (3 * r + 0) * LANES + l] = c * qp - s * qq
                    S[_SQ + (3 * r + 2) * LANES + l] = s * qp + c * qq
            for l in range(LANES):  # plane (1, 2)
                a01 = S[_A01 + l]; a02 = S[_A02 + l]
                a10 = S[_A10 + l]; a11 = S[_A11 + l]; a12 = S[_A12 + l]
                a20 = S[_A20 + l]; a21 = S[_A21 + l]; a22 = S[_A22 + l]
                c, s = _rot_coef(S[_SACT + l] != 0.0 and a12 != 0.0, a11, a22, a12)
                n11 = c * a11 - s * a12; n12 = s * a11 + c * a12
                n21 = c * a21 - s * a22; n22 = s * a21 + c * a22
                S[_A01 + l] = c * a01 - s * a02; S[_A02 + l] = s * a01 + c * a02
                S[_A10 + l] = c * a10 - s * a20; S[_A20 + l] = s * a10 + c * a20
                S[_A11 + l] = c * n11 - s * n21; S[_A21 + l] = s * n11 + c * n21
                S[_A12 + l] = c * n12 - s * n22; S[_A22 + l] = s * n12 + c * n22
                for r in range(3):
                    qp = S[_SQ + (3 * r + 1) * LANES + l]; qq = S[_SQ + (3 * r + 2) * LANES + l]
                    S[_SQ + (3 * r + 1) * LANES + l] = c * qp - s * qq
                    S[_SQ + (3 * r + 2) * LANES + l] = s * qp + c * qq

    @_njit
    def _polar_finish(S):
        """All lanes after :func:`_polar_jacobi`: ``R`` into rows ``_SR``, ``tr`` into row
        ``_STR`` and the new warm start (proper ``V``) into rows ``_SQ`` of ``S``.

        Eigenvalues sorted descending, ``V`` made proper (``v3 = v1 x v2``), then ``U``
        from Gram-Schmidt of the columns of ``M V`` with ``u3 = u1 x u2``; ``R = U V^T``
        maximises ``tr(R^T M)`` (reflection case included: the signed third singular value
        is ``u3 . (M v3)``) and ``tr = s1 + s2 + s3_signed``. Rank-one inputs get an
        arbitrary valid completion; ``M = 0`` gives the identity. Branch-free (selects), so
        that it vectorises over the lanes; the arithmetic is that of the scalar code.
        """
        for l in range(LANES):
            m00 = S[_M00 + l]; m01 = S[_M01 + l]; m02 = S[_M02 + l]
            m10 = S[_M10 + l]; m11 = S[_M11 + l]; m12 = S[_M12 + l]
            m20 = S[_M20 + l]; m21 = S[_M21 + l]; m22 = S[_M22 + l]
            q00 = S[_Q00 + l]; q01 = S[_Q01 + l]; q02 = S[_Q02 + l]
            q10 = S[_Q10 + l]; q11 = S[_Q11 + l]; q12 = S[_Q12 + l]
            q20 = S[_Q20 + l]; q21 = S[_Q21 + l]; q22 = S[_Q22 + l]
            # order of the eigenvalues (descending): columns i0, i1 of Q
            e0 = S[_A00 + l]; e1 = S[_A11 + l]; e2 = S[_A22 + l]
            i0 = 0; i1 = 1; i2 = 2
            sw = e0 < e1
            t = i0; i0 = i1 if sw else i0; i1 = t if sw else i1
            f = e0; e0 = e1 if sw else e0; e1 = f if sw else e1
            sw = e1 < e2
            t = i1; i1 = i2 if sw else i1; i2 = t if sw else i2
            f = e1; e1 = e2 if sw else e1; e2 = f if sw else e2
            sw = e0 < e1
            t = i0; i0 = i1 if sw else i0; i1 = t if sw else i1
            v00 = q00 if i0 == 0 else (q01 if i0 == 1 else q02)
            v10 = q10 if i0 == 0 else (q11 if i0 == 1 else q12)
            v20 = q20 if i0 == 0 else (q21 if i0 == 1 else q22)
            v01 = q00 if i1 == 0 else (q01 if i1 == 1 else q02)
            v11 = q10 if i1 == 0 else (q11 if i1 == 1 else q12)
            v21 = q20 if i1 == 0 else (q21 if i1 == 1 else q22)
            # proper third column: v2 = v0 x v1
            v02 = v10 * v21 - v20 * v11; v12 = v20 * v01 - v00 * v21; v22 = v00 * v11 - v10 * v01
            S[_Q00 + l] = v00; S[_Q01 + l] = v01; S[_Q02 + l] = v02
            S[_Q10 + l] = v10; S[_Q11 + l] = v11; S[_Q12 + l] = v12
            S[_Q20 + l] = v20; S[_Q21 + l] = v21; S[_Q22 + l] = v22
            # B = M @ [v0 v1 v2]
            b00 = m00 * v00 + m01 * v10 + m02 * v20
            b10 = m10 * v00 + m11 * v10 + m12 * v20
            b20 = m20 * v00 + m21 * v10 + m22 * v20
            b01 = m00 * v01 + m01 * v11 + m02 * v21
            b11 = m10 * v01 + m11 * v11 + m12 * v21
            b21 = m20 * v01 + m21 * v11 + m22 * v21
            b02 = m00 * v02 + m01 * v12 + m02 * v22
            b12 = m10 * v02 + m11 * v12 + m12 * v22
            b22 = m20 * v02 + m21 * v12 + m22 * v22
            n1 = np.sqrt(b00 * b00 + b10 * b10 + b20 * b20)
            u00 = b00 / n1; u10 = b10 / n1; u20 = b20 / n1
            dp = u00 * b01 + u10 * b11 + u20 * b21
            w0 = b01 - dp * u00; w1 = b11 - dp * u10; w2 = b21 - dp * u20
            n2 = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            # rank one: any unit vector orthogonal to u0
            alt = abs(u00) < 0.9
            x0 = 1.0 - u00 * u00 if alt else -u10 * u00
            x1 = -u00 * u10 if alt else 1.0 - u10 * u10
            x2 = -u00 * u20 if alt else -u10 * u20
            nx = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
            r1 = n2 <= 1e-13 * n1
            w0 = x0 if r1 else w0; w1 = x1 if r1 else w1; w2 = x2 if r1 else w2
            n2 = nx if r1 else n2
            u01 = w0 / n2; u11 = w1 / n2; u21 = w2 / n2
            u02 = u10 * u21 - u20 * u11; u12 = u20 * u01 - u00 * u21; u22 = u00 * u11 - u10 * u01
            s3 = u02 * b02 + u12 * b12 + u22 * b22
            z = n1 == 0.0  # M = 0: identity, trace 0
            S[_STR + l] = 0.0 if z else n1 + (u01 * b01 + u11 * b11 + u21 * b21) + s3
            S[_R00 + l] = 1.0 if z else u00 * v00 + u01 * v01 + u02 * v02
            S[_R01 + l] = 0.0 if z else u00 * v10 + u01 * v11 + u02 * v12
            S[_R02 + l] = 0.0 if z else u00 * v20 + u01 * v21 + u02 * v22
            S[_R10 + l] = 0.0 if z else u10 * v00 + u11 * v01 + u12 * v02
            S[_R11 + l] = 1.0 if z else u10 * v10 + u11 * v11 + u12 * v12
            S[_R12 + l] = 0.0 if z else u10 * v20 + u11 * v21 + u12 * v22
            S[_R20 + l] = 0.0 if z else u20 * v00 + u21 * v01 + u22 * v02
            S[_R21 + l] = 0.0 if z else u20 * v10 + u21 * v11 + u22 * v12
            S[_R22 + l] = 1.0 if z else u20 * v20 + u21 * v21 + u22 * v22

    @_njit
    def _polar_store(S, nl, k0, W, warm, R, tr):
        """Lanes ``l < nl`` of ``S`` out: ``R[k0 + l]``, ``W[k0 + l]`` (if ``warm``) and
        ``tr[k0 + l]`` (if ``tr`` is not empty)."""
        wtr = tr.shape[0] > 0
        for l in range(nl):
            k = k0 + l
            for i in range(3):
                for j in range(3):
                    R[k, i, j] = S[_SR + (3 * i + j) * LANES + l]
            if warm:
                for i in range(3):
                    for j in range(3):
                        W[k, i, j] = S[_SQ + (3 * i + j) * LANES + l]
            if wtr:
                tr[k] = S[_STR + l]

    @_njit
    def _polar_batch_nb(M, R, tr, W, warm):
        """Polar decompositions of ``M`` (k, 3, 3) into ``R`` (k, 3, 3) and ``tr`` (k,), in
        place, ``LANES`` matrices at a time (:func:`_polar_init`, :func:`_polar_jacobi`,
        :func:`_polar_finish`); ``W`` (k, 3, 3) is the warm start when ``warm``."""
        n = M.shape[0]
        S = np.empty(_SCRATCH)
        for k0 in range(0, n, LANES):
            nl = min(LANES, n - k0)
            for l in range(nl):
                for i in range(3):
                    for j in range(3):
                        S[_SM + (3 * i + j) * LANES + l] = M[k0 + l, i, j]
            _polar_init(S, nl, W, k0, warm)
            _polar_jacobi(S)
            _polar_finish(S)
            _polar_store(S, nl, k0, W, warm, R, tr)

    @_njit
    def _cell_energy(k, U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R):
        """ARAP energy of cell ``k``: ``sum_p a_p ||e'_p - R_k e_p||^2`` (pairs in order)."""
        r00 = R[k, 0, 0]; r01 = R[k, 0, 1]; r02 = R[k, 0, 2]
        r10 = R[k, 1, 0]; r11 = R[k, 1, 1]; r12 = R[k, 1, 2]
        r20 = R[k, 2, 0]; r21 = R[k, 2, 1]; r22 = R[k, 2, 2]
        acc = 0.0
        for p in range(cell_ptr[k], cell_ptr[k + 1]):
            e = pair_edge[p]
            s = edges[e, 0]; d = edges[e, 1]
            x = edge_vec[e, 0]; y = edge_vec[e, 1]; z = edge_vec[e, 2]
            d0 = (U[s, 0] - U[d, 0]) - (r00 * x + r01 * y + r02 * z)
            d1 = (U[s, 1] - U[d, 1]) - (r10 * x + r11 * y + r12 * z)
            d2 = (U[s, 2] - U[d, 2]) - (r20 * x + r21 * y + r22 * z)
            acc += pair_w[p] * (d0 * d0 + d1 * d1 + d2 * d2)
        return acc

    @_njit
    def _cell_energies_nb(U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R, out):
        """Per-cell ARAP energies ``out[k] = sum_p a_p ||e'_p - R_k e_p||^2`` (in place).

        ``U`` (n, 3); ``edges`` (ne, 2); ``edge_vec`` (ne, 3) rest ``v_s - v_d``; the pairs of
        cell ``k`` are ``cell_ptr[k]:cell_ptr[k + 1]`` of ``pair_edge`` (p,) / ``pair_w`` (p,);
        ``R`` (n, 3, 3); ``out`` (n,).
        """
        for k in range(R.shape[0]):
            out[k] = _cell_energy(k, U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R)

    @_njit
    def _block_edge_terms(b, nb, U, edges, edge_w, Et):
        """The trace form's edge terms ``Et[e] = w_e ||U_s - U_d||^2`` of block ``b``'s
        share of the edges (``b ne / nb`` to ``(b + 1) ne / nb``, ``nb`` blocks)."""
        ne = edges.shape[0]
        for e in range(b * ne // nb, (b + 1) * ne // nb):
            s = edges[e, 0]; d = edges[e, 1]
            a0 = U[s, 0] - U[d, 0]; a1 = U[s, 1] - U[d, 1]; a2 = U[s, 2] - U[d, 2]
            Et[e] = edge_w[e] * (a0 * a0 + a1 * a1 + a2 * a2)

    @_njit
    def _local_block(b, U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w,
                     W, warm, R, Ek, mode, edge_w, Et):
        """Local step of the cells ``b LANES ... (b + 1) LANES - 1``: covariances (rows of
        the CSR with 3-vector values ``kt_*``, ``M[c, d] = sum_j kt_val[j, d] U[j, c]``,
        summed in ``scipy``'s order, so equal to ``KT @ U`` to the bit), polar
        decompositions into ``R`` (warm start ``W``), then by ``mode``: 0, the cell
        energies into ``Ek``; 1 (the trace form), ``tr(R_k^T M_k)`` into ``Ek`` and the
        block's share of the edge terms into ``Et`` (:func:`_block_edge_terms`); 2, only
        the cell energies at the given ``R`` (no covariance, no polar decomposition)."""
        n = R.shape[0]
        k0 = b * LANES
        nl = min(LANES, n - k0)
        if mode != 2:
            S = np.empty(_SCRATCH)
            for l in range(nl):
                k = k0 + l
                m00 = 0.0; m01 = 0.0; m02 = 0.0
                m10 = 0.0; m11 = 0.0; m12 = 0.0
                m20 = 0.0; m21 = 0.0; m22 = 0.0
                for jj in range(kt_ptr[k], kt_ptr[k + 1]):
                    j = kt_idx[jj]
                    a0 = kt_val[jj, 0]; a1 = kt_val[jj, 1]; a2 = kt_val[jj, 2]
                    u0 = U[j, 0]; u1 = U[j, 1]; u2 = U[j, 2]
                    m00 += a0 * u0; m01 += a1 * u0; m02 += a2 * u0
                    m10 += a0 * u1; m11 += a1 * u1; m12 += a2 * u1
                    m20 += a0 * u2; m21 += a1 * u2; m22 += a2 * u2
                S[_M00 + l] = m00; S[_M01 + l] = m01; S[_M02 + l] = m02
                S[_M10 + l] = m10; S[_M11 + l] = m11; S[_M12 + l] = m12
                S[_M20 + l] = m20; S[_M21 + l] = m21; S[_M22 + l] = m22
            _polar_init(S, nl, W, k0, warm)
            _polar_jacobi(S)
            _polar_finish(S)
            _polar_store(S, nl, k0, W, warm, R, Ek[:] if mode == 1 else Ek[:0])
        if mode == 1:
            _block_edge_terms(b, (n + LANES - 1) // LANES, U, edges, edge_w, Et)
        else:
            for k in range(k0, k0 + nl):
                Ek[k] = _cell_energy(k, U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R)

    @_njit
    def _local_serial(U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W, warm, R, Ek,
                      mode, edge_w, Et):
        """Fused local step over all cells (:func:`_local_block`), one thread."""
        for b in range((R.shape[0] + LANES - 1) // LANES):
            _local_block(b, U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W, warm, R, Ek,
                         mode, edge_w, Et)

    @_njit_par
    def _local_parallel(U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W, warm, R, Ek,
                        mode, edge_w, Et):
        """Fused local step over all cells (:func:`_local_block`), blocks of cells split
        over threads (every block writes only its own outputs: the results are those of
        :func:`_local_serial`, whatever the number of threads)."""
        for b in _prange((R.shape[0] + LANES - 1) // LANES):  # prange counts in uint64: one callee signature
            _local_block(np.int64(b), U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W,
                         warm, R, Ek, mode, edge_w, Et)

    @_njit
    def _covariance(k, U, kt_ptr, kt_idx, kt_val, M):
        """Cell ``k``'s covariance into ``M[k]`` (3, 3), as :func:`_local_block` sums it."""
        m00 = 0.0; m01 = 0.0; m02 = 0.0
        m10 = 0.0; m11 = 0.0; m12 = 0.0
        m20 = 0.0; m21 = 0.0; m22 = 0.0
        for jj in range(kt_ptr[k], kt_ptr[k + 1]):
            j = kt_idx[jj]
            a0 = kt_val[jj, 0]; a1 = kt_val[jj, 1]; a2 = kt_val[jj, 2]
            u0 = U[j, 0]; u1 = U[j, 1]; u2 = U[j, 2]
            m00 += a0 * u0; m01 += a1 * u0; m02 += a2 * u0
            m10 += a0 * u1; m11 += a1 * u1; m12 += a2 * u1
            m20 += a0 * u2; m21 += a1 * u2; m22 += a2 * u2
        M[k, 0, 0] = m00; M[k, 0, 1] = m01; M[k, 0, 2] = m02
        M[k, 1, 0] = m10; M[k, 1, 1] = m11; M[k, 1, 2] = m12
        M[k, 2, 0] = m20; M[k, 2, 1] = m21; M[k, 2, 2] = m22

    @_njit
    def _sr_lanes(k0, nl, cells, M, a_ptr, a_idx, a_val, wR, Rold, R, S, W, Rl, no_tr):
        """:func:`_sr_local_nb`'s rotations of the cells ``cells[k0:k0 + nl]`` (``nl <=
        LANES``) from their covariances ``M`` (n, 3, 3), in the scratch ``S``, ``W``, ``Rl``
        (LANES, 3, 3)."""
        for l in range(nl):
            k = cells[k0 + l]
            m00 = M[k, 0, 0]; m01 = M[k, 0, 1]; m02 = M[k, 0, 2]
            m10 = M[k, 1, 0]; m11 = M[k, 1, 1]; m12 = M[k, 1, 2]
            m20 = M[k, 2, 0]; m21 = M[k, 2, 1]; m22 = M[k, 2, 2]
            n00 = 0.0; n01 = 0.0; n02 = 0.0  # the neighbours' sum
            n10 = 0.0; n11 = 0.0; n12 = 0.0
            n20 = 0.0; n21 = 0.0; n22 = 0.0
            for p in range(a_ptr[k], a_ptr[k + 1]):
                j = a_idx[p]
                c = a_val[p]
                n00 += c * Rold[j, 0, 0]; n01 += c * Rold[j, 0, 1]; n02 += c * Rold[j, 0, 2]
                n10 += c * Rold[j, 1, 0]; n11 += c * Rold[j, 1, 1]; n12 += c * Rold[j, 1, 2]
                n20 += c * Rold[j, 2, 0]; n21 += c * Rold[j, 2, 1]; n22 += c * Rold[j, 2, 2]
            S[_M00 + l] = m00 + wR * n00
            S[_M01 + l] = m01 + wR * n01
            S[_M02 + l] = m02 + wR * n02
            S[_M10 + l] = m10 + wR * n10
            S[_M11 + l] = m11 + wR * n11
            S[_M12 + l] = m12 + wR * n12
            S[_M20 + l] = m20 + wR * n20
            S[_M21 + l] = m21 + wR * n21
            S[_M22 + l] = m22 + wR * n22
        _polar_init(S, nl, W, 0, False)
        _polar_jacobi(S)
        _polar_finish(S)
        _polar_store(S, nl, 0, W, False, Rl, no_tr)
        for l in range(nl):
            k = cells[k0 + l]
            for a in range(3):
                for c in range(3):
                    R[k, a, c] = Rl[l, a, c]

    @_njit
    def _sr_local_nb(U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, cells, bptr, a_ptr,
                     a_idx, a_val, wR, Rold, R, M, Ek):
        """ARAP-SR's local step on the cells ``cells`` (c,) int64 in the batches
        ``cells[bptr[b]:bptr[b + 1]]`` one after the other, ``LANES`` cells at a time:
        ``R[k] = polar(M_k + wR sum_j a_kj Rold[j])`` with ``M_k`` the covariance (as
        :func:`_local_block` sums it; all of them first, in the cells' order, into the
        scratch ``M`` (n, 3, 3)) and the weighted graph as the CSR ``a_*`` (summed in its
        order); then ``Ek[k]`` (n,), every cell's ARAP energy at ``R[k]``
        (:func:`_cell_energy`), in the cells' order. ``Rold`` may be ``R`` when no two
        cells of a batch are neighbours (Gauss-Seidel: a batch reads the rotations the
        batches before it set)."""
        n = R.shape[0]
        for k in range(n):
            _covariance(k, U, kt_ptr, kt_idx, kt_val, M)
        S = np.empty(_SCRATCH)
        W = np.empty((LANES, 3, 3))
        Rl = np.empty((LANES, 3, 3))
        no_tr = np.empty(0)
        for b in range(bptr.shape[0] - 1):
            for k0 in range(bptr[b], bptr[b + 1], LANES):
                _sr_lanes(k0, min(LANES, bptr[b + 1] - k0), cells, M, a_ptr, a_idx, a_val, wR, Rold, R, S, W, Rl,
                          no_tr)
        for k in range(n):
            Ek[k] = _cell_energy(k, U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R)

    @_njit_par
    def _sr_local_par(U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, cells, bptr, a_ptr,
                      a_idx, a_val, wR, Rold, R, M, Ek, nt):
        """:func:`_sr_local_nb` on numba's threads: the covariances and energies split by
        cell, each batch's runs of ``LANES`` cells (the serial kernel's runs) split into ``nt``
        contiguous shares (int >= 1: the threads), each with its own scratch. Every cell's numbers are
        computed as in the serial kernel, so the results are its bits at any thread count."""
        n = R.shape[0]
        for k in _prange(n):
            _covariance(np.int64(k), U, kt_ptr, kt_idx, kt_val, M)
        no_tr = np.empty(0)
        for b in range(bptr.shape[0] - 1):
            lo = bptr[b]
            hi = bptr[b + 1]
            runs = (hi - lo + LANES - 1) // LANES
            share = (runs + nt - 1) // nt
            for t in _prange(nt):
                t0 = np.int64(t)  # prange counts in uint64, and uint64 * int64 is a float
                S = np.empty(_SCRATCH)
                W = np.empty((LANES, 3, 3))
                Rl = np.empty((LANES, 3, 3))
                for r in range(t0 * share, min((t0 + 1) * share, runs)):
                    k0 = lo + r * LANES
                    _sr_lanes(k0, min(LANES, hi - k0), cells, M, a_ptr, a_idx, a_val, wR, Rold, R, S, W, Rl,
                              no_tr)
        for k in _prange(n):
            Ek[k] = _cell_energy(np.int64(k), U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R)

    @_njit
    def _rhs_row(i, v, kv_ptr, kv_idx, kv_val, R, sub, out):
        """``out[i] = K(R)[v] - sub[i]`` from row ``v`` of the CSR with 3-vector values
        ``kv_*`` (``kv_val[jj, d] = K_d[v, kv_idx[jj]]``): ``sum_k R[k] kv_val[jj]``, one
        pass over the neighbouring cells (``K @ Rs`` sums block ``d`` by block ``d``: the
        same terms, rounded in another order)."""
        b0 = 0.0; b1 = 0.0; b2 = 0.0
        for jj in range(kv_ptr[v], kv_ptr[v + 1]):
            k = kv_idx[jj]
            a0 = kv_val[jj, 0]; a1 = kv_val[jj, 1]; a2 = kv_val[jj, 2]
            b0 += a0 * R[k, 0, 0] + a1 * R[k, 0, 1] + a2 * R[k, 0, 2]
            b1 += a0 * R[k, 1, 0] + a1 * R[k, 1, 1] + a2 * R[k, 1, 2]
            b2 += a0 * R[k, 2, 0] + a1 * R[k, 2, 1] + a2 * R[k, 2, 2]
        out[i, 0] = b0 - sub[i, 0]; out[i, 1] = b1 - sub[i, 1]; out[i, 2] = b2 - sub[i, 2]

    @_njit
    def _rhs_serial(rows, kv_ptr, kv_idx, kv_val, R, sub, out):
        """``out = K(R)[rows] - sub`` (:func:`_rhs_row`), one thread."""
        for i in range(rows.shape[0]):
            _rhs_row(i, rows[i], kv_ptr, kv_idx, kv_val, R, sub, out)

    @_njit_par
    def _rhs_parallel(rows, kv_ptr, kv_idx, kv_val, R, sub, out):
        """``out = K(R)[rows] - sub`` (:func:`_rhs_row`), rows split over threads."""
        for i in _prange(rows.shape[0]):
            _rhs_row(np.int64(i), rows[i], kv_ptr, kv_idx, kv_val, R, sub, out)


_POLAR = None  # None: not tried yet; False: unavailable; else the dispatcher
_ENERGY = None
# fused kernels: None = not tried, False = unusable, else (local, rhs) dispatchers. Serial
# and parallel apart (the OpenMP layer is not fork-safe with GNU libgomp: the worker
# pools fork).
_FUSED = {1: None, 2: None}
_SR_LOCAL = {1: None, 2: None}  # serial, parallel: as _FUSED


def polar_kernel():
    """The compiled numba polar kernel
    ``(M (k, 3, 3), R (k, 3, 3) out, tr (k,) out, W (k, 3, 3) warm start, warm: bool)``,
    or False when numba is unusable (then numpy)."""
    global _POLAR
    if _POLAR is None:
        try:
            polar_batch = _polar_batch_nb
            M = np.eye(3)[None].repeat(2, 0)
            polar_batch(M, np.empty_like(M), np.empty(2), M.copy(), True)  # compile / load cache
            polar_batch(M, np.empty_like(M), np.empty(2), M.copy(), False)
            _POLAR = polar_batch
        except Exception:  # pragma: no cover - numba missing or broken
            _POLAR = False
    return _POLAR


def energy_kernel():
    """The compiled numba per-cell energy kernel
    ``(U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R, out)``, or False when numba is
    unusable."""
    global _ENERGY
    if _ENERGY is None:
        try:
            cell_energies = _cell_energies_nb
            out = np.empty(1)  # compile (or load the cache) on a one-triangle cell
            cell_energies(np.zeros((2, 3)), np.array([[0, 1]], np.int64), np.ones((1, 3)),
                          np.array([0, 1], np.int64), np.array([0], np.int64), np.ones(1),
                          np.eye(3)[None], out)
            _ENERGY = cell_energies
        except Exception:  # pragma: no cover - numba missing or broken
            _ENERGY = False
    return _ENERGY


def sr_local_kernel(parallel: bool = False):
    """The compiled numba local step of ARAP-SR
    ``(U, *KernelData.local_arrays(), cells, bptr, a_ptr, a_idx, a_val, wR, Rold, R, M, Ek)``
    (every index array int64 but the kernel data's; :mod:`sshade.arap.smooth_rotations`),
    serial or on numba's threads (``parallel``: one more argument, the threads, int; the
    same bits; compiling it starts numba's thread pool), or False when numba is unusable (then its numpy path)."""
    key = 2 if parallel else 1
    if _SR_LOCAL[key] is None:
        try:
            if not energy_kernel():
                raise RuntimeError("numba unusable")
            kern = _sr_local_par if parallel else _sr_local_nb
            if parallel:
                note_launch()
            U, kt, pairs, W = _tiny_fused_args()
            one = np.array([0, 1, 2], np.int64)
            graph = (one, np.array([1, 0], np.int64), np.ones(2))
            kern(U, *kt, *pairs, np.arange(2, dtype=np.int64), np.array([0, 2], np.int64), *graph, 1.0, W,
                 np.empty((2, 3, 3)), np.empty((2, 3, 3)), np.empty(2), *((2,) if parallel else ()))
            _SR_LOCAL[key] = kern
        except Exception:  # pragma: no cover - numba missing or broken
            _SR_LOCAL[key] = False
    return _SR_LOCAL[key]


def _tiny_fused_args():
    """Arguments of the fused kernels on a one-edge mesh (types of the real calls)."""
    i1 = np.array([0, 1, 2], np.uint64)
    U = np.zeros((2, 3))
    kt = (i1, np.array([0, 1], np.uint32), np.ones((2, 3)))
    pairs = (np.array([[0, 1]], np.uint32), np.ones((1, 3)), np.array([0, 1, 1], np.uint64),
             np.array([0], np.uint32), np.ones(1))
    W = np.broadcast_to(np.eye(3), (2, 3, 3)).copy()
    return U, kt, pairs, W


def fused_kernels(parallel: bool):
    """``(local, rhs)`` compiled fused kernels (serial or parallel), or False.

    ``local(U, *KernelData.local_arrays(), W, warm, R, Ek, mode, edge_w, Et)`` is the
    local step (rotations into ``R``; by ``mode`` (int): 0, cell energies into ``Ek``; 1,
    the trace form's ``tr(R_k^T M_k)`` into ``Ek`` and edge terms into ``Et`` (ne,) with
    the weights ``edge_w`` (ne,); 2, cell energies at the given ``R`` only); ``rhs(rows, *KernelData.kv, R, sub, out)``
    writes ``K(R)[rows] - sub``. Compiling the parallel pair starts numba's thread pool.
    """
    key = 2 if parallel else 1
    if _FUSED[key] is None:
        try:
            if not energy_kernel():  # not the polar kernel: the fused ones hold their own copy
                raise RuntimeError("numba unusable")
            local, rhs = (_local_parallel, _rhs_parallel) if parallel else (_local_serial, _rhs_serial)
            if parallel:
                note_launch()
            U, kt, pairs, W = _tiny_fused_args()
            R = np.empty((2, 3, 3)); Ek = np.empty(2)
            for warm in (True, False):
                local(U, *kt, *pairs, W, warm, R, Ek, 0, np.ones(1), np.empty(1))
            rhs(np.arange(2, dtype=np.uint32), *kt, R, np.zeros((2, 3)), np.empty((2, 3)))
            _FUSED[key] = (local, rhs)
        except Exception:  # pragma: no cover - numba missing or broken
            _FUSED[key] = False
    return _FUSED[key]


def fused(threads: int):
    """The fused kernels for ``threads`` (serial for 1) or False (numpy paths; also when
    the energy kernel is unusable, e.g. monkeypatched off in a test). The standalone polar
    kernel (:func:`polar_kernel`) is not compiled for them: SShaDe's path never calls it."""
    if not energy_kernel():
        return False
    return fused_kernels(threads > 1)


def warmup_energy_kernels() -> bool:
    """Compile (or load from numba's cache) the serial kernels of this module, e.g. before
    forking worker processes. Returns whether numba is usable."""
    return bool(fused_kernels(False))

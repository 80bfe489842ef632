"""ARAP energies with libigl's cotangent weights: operators, energy and gradient.

Two energies, both with one rotation per vertex (libigl's ``ARAP_ENERGY_TYPE_SPOKES`` and
``ARAP_ENERGY_TYPE_SPOKES_AND_RIMS``):

* ``"spokes"`` (Sorkine & Alexa 2007, "As-rigid-as-possible surface modeling", SGP):
  the cell of vertex ``i`` is its one-ring of edges (the spokes ``(i, j)``).
* ``"spokes_and_rims"`` (Chao, Pinkall, Sanan, Schröder 2010, "A simple geometric model
  for elastic deformations", SIGGRAPH): the cell of vertex ``i`` is every edge of every
  triangle incident to ``i`` (the spokes plus the rims).

Conventions (match libigl's ``arap_linear_block`` / ``arap_rhs`` /
``covariance_scatter_matrix``, so the global step below *is* libigl's global step):

* ``c_{f,e} = cot(angle opposite e in f) / 2`` (``igl.cotmatrix_entries``), and the
  cotangent weight of an edge is ``w_sd = sum_f c_{f,e} = -igl.cotmatrix(V, F)[s, d]``.
* Rest edge ``e = v_s - v_d``, deformed edge ``e' = u_s - u_d``.
* ``"spokes"``: every face-edge ``(f, e)`` enters the cells of its two end points with
  weight ``c_{f,e} / 2`` (libigl: ``0.5 * C(f, e)``); ``"spokes_and_rims"``: it enters
  the cells of the three corners of ``f`` with weight ``c_{f,e} / 3`` (libigl:
  ``C(f, e) / 3``). Hence in both cases the weights of an edge over all cells sum to
  ``w_sd``, and

      E(U, R) = sum_k sum_{e in cell k} a_ke || e'_e - R_k e_e ||^2
              = tr(U^T L U) - 2 tr(U^T K(R)) + sum_e w_e ||e_e||^2,

  with ``L = -igl.cotmatrix`` (positive semi-definite) and ``K(R)`` linear in the
  rotations. For spokes this is ``E = 1/2 sum_i sum_{j in N(i)} w_ij ||e'_ij - R_i e_ij||^2``
  (i.e. exactly one half of Sorkine & Alexa's eq. 3 with their ``w_ij = 1/2(cot a +
  cot b)``); for spokes-and-rims it is ``1/3 sum_i sum_{f ni i} sum_{e in f} c_fe ||.||^2``.
  libigl minimises ``1/2 tr(U^T L U) - tr(U^T K(R))``, i.e. ``E / 2`` up to a constant,
  so both have the same minimiser and the same local/global iterates.
* The global step with fixed rotations is ``L U = K(R)`` with the handle rows fixed; the
  gradient of ``E(U) = min_R E(U, R)`` is ``dE/dU = 2 (L U - K(R*(U)))`` with ``R*`` the
  optimal rotations (envelope theorem: ``dE/dR = 0`` at the optimum over ``SO(3)``).

Kernels (numba, with numpy / scipy.sparse fallbacks used when numba is unusable):

* The local step is ONE kernel over blocks of :data:`LANES` cells (:meth:`ArapOperators.
  local_step`): covariances from ``K^T`` stored as a CSR with 3-vector values (the
  entries and summation order of scipy's ``KT @ U``, so the same floats), the polar
  decompositions with the Jacobi sweeps vectorised across the cells of a block (cyclic
  Jacobi on ``M^T M``, warm-started from the previous eigenvectors; bit-identical to a
  scalar implementation), then the cell energies summed term by term (relative rounding
  noise ~1e-15 instead of ~1e-13 for the closed form, which matters when comparing the
  energies of nearly converged iterates). Blocks run in parallel (``numba.prange``) for
  ``threads > 1``: every block writes only its own cells, so the results do not depend on
  the number of threads.
* The right-hand side ``K(R)`` is a kernel over vertices gathering the rotations of the
  neighbouring cells (:meth:`ArapOperators.rhs_rows`), parallel over vertices.
* :class:`KernelData` holds the kernels' arrays in the mesh's numbering or in a
  cache-friendly one (:func:`locality_order`); :func:`resolve_threads` picks the threads
  (serial below :data:`PARALLEL_MIN_CELLS` cells and in worker processes).

Measured on the 200k-vertex armadillo (spokes-and-rims, 2-core machine under load, one
thread): local step 0.13 s with scipy + the former scalar polar kernel + the energy
kernel, 0.043 s fused (0.08 s in the mesh's random vertex numbering); ``K(R)`` 0.031 s
with scipy, 0.009 s.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .errors import SShaDeError

__all__ = ["ENERGIES", "ArapOperators", "KernelData", "build_operators", "fit_rotations", "bbox_diag",
           "locality_order", "resolve_threads", "warmup_kernels"]

ENERGIES = ("spokes", "spokes_and_rims")


def bbox_diag(V: np.ndarray) -> float:
    """Length of the bounding-box diagonal of ``V`` ((n, 3) float64), mesh units."""
    V = np.asarray(V, np.float64)
    return float(np.linalg.norm(V.max(0) - V.min(0)))


def _polar_numpy(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    U, s, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U) * np.linalg.det(Vt))
    d[d == 0] = 1.0
    U[:, :, 2] *= d[:, None]
    return U @ Vt, s[:, 0] + s[:, 1] + d * s[:, 2]


# ---------------------------------------------------------------------- numba kernels
try:  # numba is a dependency of the package; without it the numpy paths are used
    import numba as _nb
except ImportError:  # pragma: no cover
    _nb = None

#: problems below this many cells use the serial kernels by default (no numba threading
#: layer; a parallel region costs ~10-50 us, which small meshes do not pay back, and the
#: low-res solves already run one per core in worker processes).
PARALLEL_MIN_CELLS = 20_000

# Lanes of the polar kernel: LANES cells are decomposed together, every 3x3 quantity
# stored as a row of LANES values of a scratch vector, so that the Jacobi sweeps are
# loops over lanes that LLVM vectorises (AVX2/AVX-512: 4-8 cells per instruction; the
# scalar version is latency-bound on its chain of divisions and square roots). Scratch
# rows: 0-8 the matrix M, 9-17 A = M^T M, 18-26 the eigenvectors Q (then the new warm
# start), 27 the active flags, 28-36 the rotation R, 37 the trace.
LANES = 64
_SM, _SA, _SQ, _SACT, _SR, _STR = 0, 9 * LANES, 18 * LANES, 27 * LANES, 28 * LANES, 37 * LANES
_SCRATCH = 38 * LANES

if _nb is not None:
    _prange = _nb.prange
    # error_model="numpy": no ZeroDivisionError checks (they block vectorisation); none of
    # these kernels divides by zero on finite input (guarded below).
    _njit = _nb.njit(cache=True, nogil=True, error_model="numpy")
    _njit_par = _nb.njit(cache=True, nogil=True, error_model="numpy", parallel=True)

    @_njit
    def _polar_init(S, nl, W, k0, warm):
        """Lanes ``l < nl``: ``A = Q^T M^T M Q`` with ``Q = W[k0 + l]`` (warm) or ``Q = I``,
        from ``M`` in the scratch ``S``; lanes ``l >= nl``: ``M = A = Q = I`` (inert)."""
        for l in range(LANES):
            m00 = S[_SM + 0 * LANES + l]; m01 = S[_SM + 1 * LANES + l]; m02 = S[_SM + 2 * LANES + l]
            m10 = S[_SM + 3 * LANES + l]; m11 = S[_SM + 4 * LANES + l]; m12 = S[_SM + 5 * LANES + l]
            m20 = S[_SM + 6 * LANES + l]; m21 = S[_SM + 7 * LANES + l]; m22 = S[_SM + 8 * LANES + l]
            q00 = 1.0; q01 = 0.0; q02 = 0.0
            q10 = 0.0; q11 = 1.0; q12 = 0.0
            q20 = 0.0; q21 = 0.0; q22 = 1.0
            if l >= nl:
                m00 = 1.0; m01 = 0.0; m02 = 0.0
                m10 = 0.0; m11 = 1.0; m12 = 0.0
                m20 = 0.0; m21 = 0.0; m22 = 1.0
                S[_SM + 0 * LANES + l] = m00; S[_SM + 1 * LANES + l] = m01; S[_SM + 2 * LANES + l] = m02
                S[_SM + 3 * LANES + l] = m10; S[_SM + 4 * LANES + l] = m11; S[_SM + 5 * LANES + l] = m12
                S[_SM + 6 * LANES + l] = m20; S[_SM + 7 * LANES + l] = m21; S[_SM + 8 * LANES + l] = m22
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
            S[_SA + 0 * LANES + l] = b00 * b00 + b10 * b10 + b20 * b20
            S[_SA + 1 * LANES + l] = b00 * b01 + b10 * b11 + b20 * b21
            S[_SA + 2 * LANES + l] = b00 * b02 + b10 * b12 + b20 * b22
            S[_SA + 3 * LANES + l] = b01 * b00 + b11 * b10 + b21 * b20
            S[_SA + 4 * LANES + l] = b01 * b01 + b11 * b11 + b21 * b21
            S[_SA + 5 * LANES + l] = b01 * b02 + b11 * b12 + b21 * b22
            S[_SA + 6 * LANES + l] = b02 * b00 + b12 * b10 + b22 * b20
            S[_SA + 7 * LANES + l] = b02 * b01 + b12 * b11 + b22 * b21
            S[_SA + 8 * LANES + l] = b02 * b02 + b12 * b12 + b22 * b22
            S[_SQ + 0 * LANES + l] = q00; S[_SQ + 1 * LANES + l] = q01; S[_SQ + 2 * LANES + l] = q02
            S[_SQ + 3 * LANES + l] = q10; S[_SQ + 4 * LANES + l] = q11; S[_SQ + 5 * LANES + l] = q12
            S[_SQ + 6 * LANES + l] = q20; S[_SQ + 7 * LANES + l] = q21; S[_SQ + 8 * LANES + l] = q22
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
        for sweep in range(30):
            nact = 0
            for l in range(LANES):
                a00 = S[_SA + 0 * LANES + l]; a01 = S[_SA + 1 * LANES + l]; a02 = S[_SA + 2 * LANES + l]
                a11 = S[_SA + 4 * LANES + l]; a12 = S[_SA + 5 * LANES + l]; a22 = S[_SA + 8 * LANES + l]
                off = a01 * a01 + a02 * a02 + a12 * a12
                dg = a00 * a00 + a11 * a11 + a22 * a22
                act = S[_SACT + l] != 0.0 and off > 1e-34 * dg
                S[_SACT + l] = 1.0 if act else 0.0
                nact += 1 if act else 0
            if nact == 0:
                break
            for l in range(LANES):  # plane (0, 1)
                a00 = S[_SA + 0 * LANES + l]; a01 = S[_SA + 1 * LANES + l]; a02 = S[_SA + 2 * LANES + l]
                a10 = S[_SA + 3 * LANES + l]; a11 = S[_SA + 4 * LANES + l]; a12 = S[_SA + 5 * LANES + l]
                a20 = S[_SA + 6 * LANES + l]; a21 = S[_SA + 7 * LANES + l]
                c, s = _rot_coef(S[_SACT + l] != 0.0 and a01 != 0.0, a00, a11, a01)
                n00 = c * a00 - s * a01; n01 = s * a00 + c * a01
                n10 = c * a10 - s * a11; n11 = s * a10 + c * a11
                S[_SA + 6 * LANES + l] = c * a20 - s * a21; S[_SA + 7 * LANES + l] = s * a20 + c * a21
                S[_SA + 0 * LANES + l] = c * n00 - s * n10; S[_SA + 3 * LANES + l] = s * n00 + c * n10
                S[_SA + 1 * LANES + l] = c * n01 - s * n11; S[_SA + 4 * LANES + l] = s * n01 + c * n11
                S[_SA + 2 * LANES + l] = c * a02 - s * a12; S[_SA + 5 * LANES + l] = s * a02 + c * a12
                for r in range(3):
                    qp = S[_SQ + (3 * r + 0) * LANES + l]; qq = S[_SQ + (3 * r + 1) * LANES + l]
                    S[_SQ + (3 * r + 0) * LANES + l] = c * qp - s * qq
                    S[_SQ + (3 * r + 1) * LANES + l] = s * qp + c * qq
            for l in range(LANES):  # plane (0, 2)
                a00 = S[_SA + 0 * LANES + l]; a01 = S[_SA + 1 * LANES + l]; a02 = S[_SA + 2 * LANES + l]
                a10 = S[_SA + 3 * LANES + l]; a12 = S[_SA + 5 * LANES + l]
                a20 = S[_SA + 6 * LANES + l]; a21 = S[_SA + 7 * LANES + l]; a22 = S[_SA + 8 * LANES + l]
                c, s = _rot_coef(S[_SACT + l] != 0.0 and a02 != 0.0, a00, a22, a02)
                n00 = c * a00 - s * a02; n02 = s * a00 + c * a02
                n20 = c * a20 - s * a22; n22 = s * a20 + c * a22
                S[_SA + 3 * LANES + l] = c * a10 - s * a12; S[_SA + 5 * LANES + l] = s * a10 + c * a12
                S[_SA + 0 * LANES + l] = c * n00 - s * n20; S[_SA + 6 * LANES + l] = s * n00 + c * n20
                S[_SA + 1 * LANES + l] = c * a01 - s * a21; S[_SA + 7 * LANES + l] = s * a01 + c * a21
                S[_SA + 2 * LANES + l] = c * n02 - s * n22; S[_SA + 8 * LANES + l] = s * n02 + c * n22
                for r in range(3):
                    qp = S[_SQ + (3 * r + 0) * LANES + l]; qq = S[_SQ + (3 * r + 2) * LANES + l]
                    S[_SQ + (3 * r + 0) * LANES + l] = c * qp - s * qq
                    S[_SQ + (3 * r + 2) * LANES + l] = s * qp + c * qq
            for l in range(LANES):  # plane (1, 2)
                a01 = S[_SA + 1 * LANES + l]; a02 = S[_SA + 2 * LANES + l]
                a10 = S[_SA + 3 * LANES + l]; a11 = S[_SA + 4 * LANES + l]; a12 = S[_SA + 5 * LANES + l]
                a20 = S[_SA + 6 * LANES + l]; a21 = S[_SA + 7 * LANES + l]; a22 = S[_SA + 8 * LANES + l]
                c, s = _rot_coef(S[_SACT + l] != 0.0 and a12 != 0.0, a11, a22, a12)
                n11 = c * a11 - s * a12; n12 = s * a11 + c * a12
                n21 = c * a21 - s * a22; n22 = s * a21 + c * a22
                S[_SA + 1 * LANES + l] = c * a01 - s * a02; S[_SA + 2 * LANES + l] = s * a01 + c * a02
                S[_SA + 3 * LANES + l] = c * a10 - s * a20; S[_SA + 6 * LANES + l] = s * a10 + c * a20
                S[_SA + 4 * LANES + l] = c * n11 - s * n21; S[_SA + 7 * LANES + l] = s * n11 + c * n21
                S[_SA + 5 * LANES + l] = c * n12 - s * n22; S[_SA + 8 * LANES + l] = s * n12 + c * n22
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
            m00 = S[_SM + 0 * LANES + l]; m01 = S[_SM + 1 * LANES + l]; m02 = S[_SM + 2 * LANES + l]
            m10 = S[_SM + 3 * LANES + l]; m11 = S[_SM + 4 * LANES + l]; m12 = S[_SM + 5 * LANES + l]
            m20 = S[_SM + 6 * LANES + l]; m21 = S[_SM + 7 * LANES + l]; m22 = S[_SM + 8 * LANES + l]
            q00 = S[_SQ + 0 * LANES + l]; q01 = S[_SQ + 1 * LANES + l]; q02 = S[_SQ + 2 * LANES + l]
            q10 = S[_SQ + 3 * LANES + l]; q11 = S[_SQ + 4 * LANES + l]; q12 = S[_SQ + 5 * LANES + l]
            q20 = S[_SQ + 6 * LANES + l]; q21 = S[_SQ + 7 * LANES + l]; q22 = S[_SQ + 8 * LANES + l]
            # order of the eigenvalues (descending): columns i0, i1 of Q
            e0 = S[_SA + 0 * LANES + l]; e1 = S[_SA + 4 * LANES + l]; e2 = S[_SA + 8 * LANES + l]
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
            S[_SQ + 0 * LANES + l] = v00; S[_SQ + 1 * LANES + l] = v01; S[_SQ + 2 * LANES + l] = v02
            S[_SQ + 3 * LANES + l] = v10; S[_SQ + 4 * LANES + l] = v11; S[_SQ + 5 * LANES + l] = v12
            S[_SQ + 6 * LANES + l] = v20; S[_SQ + 7 * LANES + l] = v21; S[_SQ + 8 * LANES + l] = v22
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
            S[_SR + 0 * LANES + l] = 1.0 if z else u00 * v00 + u01 * v01 + u02 * v02
            S[_SR + 1 * LANES + l] = 0.0 if z else u00 * v10 + u01 * v11 + u02 * v12
            S[_SR + 2 * LANES + l] = 0.0 if z else u00 * v20 + u01 * v21 + u02 * v22
            S[_SR + 3 * LANES + l] = 0.0 if z else u10 * v00 + u11 * v01 + u12 * v02
            S[_SR + 4 * LANES + l] = 1.0 if z else u10 * v10 + u11 * v11 + u12 * v12
            S[_SR + 5 * LANES + l] = 0.0 if z else u10 * v20 + u11 * v21 + u12 * v22
            S[_SR + 6 * LANES + l] = 0.0 if z else u20 * v00 + u21 * v01 + u22 * v02
            S[_SR + 7 * LANES + l] = 0.0 if z else u20 * v10 + u21 * v11 + u22 * v12
            S[_SR + 8 * LANES + l] = 1.0 if z else u20 * v20 + u21 * v21 + u22 * v22

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
    def _local_block(b, U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w,
                     W, warm, R, Ek):
        """Local step of the cells ``b LANES ... (b + 1) LANES - 1``: covariances (rows of
        the CSR with 3-vector values ``kt_*``, ``M[c, d] = sum_j kt_val[j, d] U[j, c]``,
        summed in ``scipy``'s order, so equal to ``KT @ U`` to the bit), polar
        decompositions into ``R`` (warm start ``W``) and cell energies into ``Ek``."""
        n = R.shape[0]
        k0 = b * LANES
        nl = min(LANES, n - k0)
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
            S[_SM + 0 * LANES + l] = m00; S[_SM + 1 * LANES + l] = m01; S[_SM + 2 * LANES + l] = m02
            S[_SM + 3 * LANES + l] = m10; S[_SM + 4 * LANES + l] = m11; S[_SM + 5 * LANES + l] = m12
            S[_SM + 6 * LANES + l] = m20; S[_SM + 7 * LANES + l] = m21; S[_SM + 8 * LANES + l] = m22
        _polar_init(S, nl, W, k0, warm)
        _polar_jacobi(S)
        _polar_finish(S)
        _polar_store(S, nl, k0, W, warm, R, Ek[:0])
        for k in range(k0, k0 + nl):
            Ek[k] = _cell_energy(k, U, edges, edge_vec, cell_ptr, pair_edge, pair_w, R)

    @_njit
    def _local_serial(U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W, warm, R, Ek):
        """Fused local step over all cells (:func:`_local_block`), one thread."""
        for b in range((R.shape[0] + LANES - 1) // LANES):
            _local_block(b, U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W, warm, R, Ek)

    @_njit_par
    def _local_parallel(U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W, warm, R, Ek):
        """Fused local step over all cells (:func:`_local_block`), blocks of cells split
        over threads (every block writes only its own outputs: the results are those of
        :func:`_local_serial`, whatever the number of threads)."""
        for b in _prange((R.shape[0] + LANES - 1) // LANES):
            _local_block(b, U, kt_ptr, kt_idx, kt_val, edges, edge_vec, cell_ptr, pair_edge, pair_w, W, warm, R, Ek)

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
            _rhs_row(i, rows[i], kv_ptr, kv_idx, kv_val, R, sub, out)


_NUMBA_KERNEL = None  # None: not tried yet; False: unavailable


def _numba_kernel():
    """The compiled numba polar kernel, or False when numba is unusable (then numpy)."""
    global _NUMBA_KERNEL
    if _NUMBA_KERNEL is None:
        try:
            polar_batch = _polar_batch_nb
            M = np.eye(3)[None].repeat(2, 0)
            polar_batch(M, np.empty_like(M), np.empty(2), M.copy(), True)  # compile / load cache
            polar_batch(M, np.empty_like(M), np.empty(2), M.copy(), False)
            _NUMBA_KERNEL = polar_batch
        except Exception:  # pragma: no cover - numba missing or broken
            _NUMBA_KERNEL = False
    return _NUMBA_KERNEL


_NUMBA_ENERGY = None


def _numba_energy_kernel():
    """The compiled numba per-cell energy kernel, or False when numba is unusable."""
    global _NUMBA_ENERGY
    if _NUMBA_ENERGY is None:
        try:
            cell_energies = _cell_energies_nb
            out = np.empty(1)  # compile (or load the cache) on a one-triangle cell
            cell_energies(np.zeros((2, 3)), np.array([[0, 1]], np.int64), np.ones((1, 3)),
                          np.array([0, 1], np.int64), np.array([0], np.int64), np.ones(1),
                          np.eye(3)[None], out)
            _NUMBA_ENERGY = cell_energies
        except Exception:  # pragma: no cover - numba missing or broken
            _NUMBA_ENERGY = False
    return _NUMBA_ENERGY


# fused kernels, compiled (or loaded from numba's cache) on first use: None = not tried,
# False = unusable, else (local, rhs) dispatchers. Serial and parallel apart, so that a
# process that never runs a parallel kernel never starts numba's threading layer (the
# OpenMP layer is not fork-safe with GNU libgomp: the worker pools fork).
_NUMBA_FUSED = {1: None, 2: None}


def _tiny_fused_args():
    """Arguments of the fused kernels on a one-edge mesh (types of the real calls)."""
    i1 = np.array([0, 1, 2], np.uint64)
    U = np.zeros((2, 3))
    kt = (i1, np.array([0, 1], np.uint32), np.ones((2, 3)))
    pairs = (np.array([[0, 1]], np.uint32), np.ones((1, 3)), np.array([0, 1, 1], np.uint64),
             np.array([0], np.uint32), np.ones(1))
    W = np.broadcast_to(np.eye(3), (2, 3, 3)).copy()
    return U, kt, pairs, W


def _numba_fused(parallel: bool):
    """``(local, rhs)`` compiled fused kernels (serial or parallel), or False."""
    key = 2 if parallel else 1
    if _NUMBA_FUSED[key] is None:
        try:
            if not _numba_kernel() or not _numba_energy_kernel():
                raise RuntimeError("numba unusable")
            local, rhs = (_local_parallel, _rhs_parallel) if parallel else (_local_serial, _rhs_serial)
            if parallel:
                _note_launch()
            U, kt, pairs, W = _tiny_fused_args()
            R = np.empty((2, 3, 3)); Ek = np.empty(2)
            for warm in (True, False):
                local(U, *kt, *pairs, W, warm, R, Ek)
            rhs(np.arange(2, dtype=np.uint32), *kt, R, np.zeros((2, 3)), np.empty((2, 3)))
            _NUMBA_FUSED[key] = (local, rhs)
        except Exception:  # pragma: no cover - numba missing or broken
            _NUMBA_FUSED[key] = False
    return _NUMBA_FUSED[key]


def max_threads() -> int:
    """Threads the parallel kernels may use: numba's ``NUMBA_NUM_THREADS`` (its
    environment variable, default the CPU count); 1 without numba."""
    return int(_nb.config.NUMBA_NUM_THREADS) if _nb is not None else 1


_LAUNCH_PID = None  # process that started numba's thread pool through this module


def _fork_unsafe() -> bool:
    """True in a forked child whose parent had started numba's OpenMP thread pool: GNU
    libgomp is not fork-safe and numba aborts the process ("fork() called from a process
    already using GNU OpenMP") at the child's first parallel region."""
    import os
    from numba.np.ufunc import parallel as _par
    if not getattr(_par, "_is_initialized", False):
        return False  # no pool yet: this process would start its own
    if _LAUNCH_PID == os.getpid():
        return False
    try:
        return _nb.threading_layer() == "omp"
    except Exception:  # pragma: no cover - unknown state: stay serial
        return True


def _note_launch() -> None:
    """Record that this process runs numba's thread pool (see :func:`_fork_unsafe`)."""
    global _LAUNCH_PID
    if _LAUNCH_PID is None:
        import os
        _LAUNCH_PID = os.getpid()


def resolve_threads(threads: int | None, n_cells: int) -> int:
    """Threads for the per-cell kernels of a problem with ``n_cells`` cells (1 = serial).

    ``threads=None`` (automatic): 1 below :data:`PARALLEL_MIN_CELLS` cells or inside a
    child process (``multiprocessing`` workers: the caller already parallelises over
    processes), else :func:`max_threads` (``NUMBA_NUM_THREADS``). An explicit
    ``threads >= 1`` is capped at :func:`max_threads`, and at 1 in a forked child of a
    process that ran numba's OpenMP threads (a parallel region would abort it).

    Raises
    ------
    SShaDeError on ``threads < 1``.
    """
    import multiprocessing
    if threads is not None and (int(threads) != threads or int(threads) < 1):
        raise SShaDeError(f"threads must be an integer >= 1 or None, got {threads!r}")
    child = multiprocessing.parent_process() is not None
    if threads is None:
        if n_cells < PARALLEL_MIN_CELLS or child:
            return 1
        t = max_threads()
    else:
        t = min(int(threads), max_threads())
    if t > 1 and child and _fork_unsafe():
        return 1
    return t


class _numba_threads:
    """Context manager: numba's thread count set to ``t`` for the calls inside (restored
    after). Only entered for parallel kernels (``t > 1``)."""

    def __init__(self, t: int):
        self.t = int(t)

    def __enter__(self):
        _note_launch()
        self.prev = _nb.get_num_threads()
        if self.prev != self.t:
            _nb.set_num_threads(self.t)
        return self

    def __exit__(self, *exc):
        if self.prev != self.t:
            _nb.set_num_threads(self.prev)
        return False


def _fused(threads: int):
    """The fused kernels for ``threads`` (serial for 1) or False (numpy paths; also when
    the polar or energy kernel is unusable, e.g. monkeypatched off in a test)."""
    if not _numba_kernel() or not _numba_energy_kernel():
        return False
    return _numba_fused(threads > 1)


def warmup_kernels() -> bool:
    """Compile (or load from numba's cache) the serial kernels of this module, e.g. before
    forking worker processes. Returns whether numba is usable."""
    return bool(_numba_fused(False))


def fit_rotations(M: np.ndarray, *, return_trace: bool = False, backend: str = "auto",
                  warm: np.ndarray | None = None):
    """Closest rotations to a batch of 3x3 matrices (polar decomposition, det fixed).

    ``R_k = argmax_{R in SO(3)} tr(R^T M_k)`` = ``U_k diag(1, 1, det(U_k V_k^T)) V_k^T``
    for ``M_k = U_k S_k V_k^T`` (Sorkine & Alexa 2007, §2; the reflection case flips the
    singular vector of the smallest singular value, as libigl's ``polar_svd`` does).

    Parameters
    ----------
    M : (k, 3, 3) float64, e.g. ``M_k = sum a e' e^T`` (deformed times rest).
    return_trace : bool, also return ``tr(R_k^T M_k)`` = ``s1 + s2 + sign * s3``.
    backend : ``"auto"`` (numba kernel when numba works, else numpy), ``"numba"`` or
        ``"numpy"`` (``numpy.linalg.svd`` on the stack). The numba kernel (cyclic Jacobi
        on ``M^T M`` in float64, vectorised across matrices, then ``U`` by Gram-Schmidt of
        ``M V``) agrees with the SVD to ~1e-13; 0.022 s for 200k warm-started matrices
        (0.065 s for the former scalar kernel, 0.45 s for ``numpy.linalg.svd`` of 173k).

    warm : (k, 3, 3) float64 C-contiguous array or None (numba backend only): right
        singular vectors of a previous, nearby ``M``, used as the Jacobi start and
        overwritten with the new ones (about halves the cost inside an iteration). Start
        it as ``np.broadcast_to(np.eye(3), (k, 3, 3)).copy()``.

    Returns
    -------
    R : (k, 3, 3) float64 rotations (det = +1).
    tr : (k,) float64, only with ``return_trace``.

    Raises
    ------
    SShaDeError on an unknown backend or ``"numba"`` when numba is unusable, or a ``warm``
    array of the wrong shape.
    """
    if backend not in ("auto", "numba", "numpy"):
        raise SShaDeError(f"unknown rotation backend {backend!r}")
    M = np.asarray(M, np.float64)
    kern = _numba_kernel() if backend != "numpy" else False
    if backend == "numba" and not kern:
        raise SShaDeError("numba rotation backend requested but numba is unusable")
    if warm is not None and (not isinstance(warm, np.ndarray) or warm.shape != M.shape
                             or warm.dtype != np.float64 or not warm.flags.c_contiguous):
        raise SShaDeError(f"warm must be a C-contiguous float64 array of shape {M.shape}")
    if kern:
        R = np.empty((len(M), 3, 3))
        tr = np.empty(len(M))
        kern(M, R, tr, M if warm is None else warm, warm is not None)
    else:
        R, tr = _polar_numpy(M)
    return (R, tr) if return_trace else R


@dataclass(eq=False)
class ArapOperators:
    """Precomputed ARAP operators of a rest mesh for one energy (built once).

    Attributes
    ----------
    energy_type : str, ``"spokes"`` or ``"spokes_and_rims"``.
    n : int, number of vertices (= number of rotation cells).
    V : (n, 3) float64 rest positions. F : (m, 3) int64 faces.
    edges : (ne, 2) int64 undirected edges ``(s, d)``, ``s < d``.
    edge_vec : (ne, 3) float64 rest edge vectors ``v_s - v_d`` (mesh units).
    edge_w : (ne,) float64 cotangent weights ``w_sd = -cotmatrix[s, d]`` (dimensionless).
    pair_cell, pair_edge : (p,) int64, the (cell, edge) incidences of the energy.
    pair_w : (p,) float64 weight of edge ``pair_edge`` in cell ``pair_cell``
        (``w/2`` per end point for spokes; sums of ``c/3`` for spokes-and-rims).
    cell_ptr : (n + 1,) int64, the pairs of cell ``k`` are ``cell_ptr[k]:cell_ptr[k+1]``
        (pairs are sorted by cell).
    L : (n, n) scipy.sparse.csr_matrix, ``-igl.cotmatrix(V, F)`` (PSD, rows sum to 0).
    K : (n, 3n) scipy.sparse.csr_matrix, ``[K_0 K_1 K_2]``: the right-hand side is
        ``K(R)[:, c] = sum_d K_d @ R[:, c, d]`` (libigl's ``arap_rhs`` up to sign and
        layout).
    KT : (3n, n) scipy.sparse.csr_matrix, row ``3k + d`` is row ``k`` of ``K_d^T``: the
        covariances are ``M[k, c, d] = (K_d^T U)[k, c]`` (libigl's
        ``covariance_scatter_matrix``).
    rest_term : float, ``sum_e w_e ||e_e||^2`` (mesh units^2).
    mass : (n,) float64 Voronoi-hybrid vertex areas (``igl.massmatrix``), mesh units^2.
    diag : float, bounding-box diagonal of ``V``.

    The numba kernels use :class:`KernelData` (:meth:`kernel_data`), built on first use.
    """

    energy_type: str
    n: int
    V: np.ndarray
    F: np.ndarray
    edges: np.ndarray
    edge_vec: np.ndarray
    edge_w: np.ndarray
    pair_cell: np.ndarray
    pair_edge: np.ndarray
    pair_w: np.ndarray
    cell_ptr: np.ndarray
    L: sp.csr_matrix
    K: sp.csr_matrix
    KT: sp.csr_matrix
    rest_term: float
    mass: np.ndarray
    diag: float
    _kdata: dict = field(default_factory=dict, repr=False)

    def kernel_data(self, reorder: bool = False) -> KernelData:
        """The arrays of the numba kernels (:class:`KernelData`), built once per numbering.

        Parameters
        ----------
        reorder : bool, False: the mesh's own vertex numbering; True: the reverse
            Cuthill-McKee numbering of ``L`` (:func:`locality_order`), in which the
            kernels' gathers from neighbouring vertices and cells hit the cache (on the
            randomly numbered 200k-vertex armadillo: fused local step 0.09 -> 0.05 s,
            right-hand side 0.023 -> 0.012 s).
        """
        key = bool(reorder)
        if key not in self._kdata:
            perm = locality_order(self.L) if key else None
            self._kdata[key] = KernelData.build(self, perm)
        return self._kdata[key]

    # ------------------------------------------------------------------ local step
    def covariances(self, U: np.ndarray) -> np.ndarray:
        """Per-cell matrices ``M_k = sum_{e in cell k} a_ke e'_e e_e^T``.

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.

        Returns
        -------
        M : (n, 3, 3) float64, ``M[k, c, d] = sum a e'_c e_d``. The covariance in Sorkine
            & Alexa's notation is ``S_k = sum w e e'^T = M_k^T``; the optimal rotation is
            ``R_k = polar(M_k)`` (:func:`fit_rotations`).
        """
        out = self.KT @ np.asarray(U, np.float64)  # (3n, 3): row 3k + d, column c
        return out.reshape(self.n, 3, 3).transpose(0, 2, 1)

    def local_step(self, U: np.ndarray, R: np.ndarray, Ek: np.ndarray, warm: np.ndarray | None = None,
                   threads: int = 1, data: KernelData | None = None) -> float:
        """The local step into preallocated arrays: optimal rotations ``R*(U)`` and ``E(U)``.

        With numba, ONE kernel over the cells does the covariance, the polar decomposition
        and the cell's energy summed term by term (parallel over blocks of cells for
        ``threads > 1``; the results do not depend on ``threads``); without, the numpy
        path of :meth:`rotations`.

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.
        R : (n, 3, 3) float64 C-contiguous, overwritten with the rotations.
        Ek : (n,) float64 C-contiguous scratch, overwritten with the cell energies (numba)
            or left untouched (numpy).
        warm : (n, 3, 3) float64 C-contiguous or None, polar warm start, updated in place
            (:func:`fit_rotations`).
        threads : int >= 1, threads of the kernel (:func:`resolve_threads`).
        data : :class:`KernelData` or None (:meth:`kernel_data`, mesh numbering); all the
            arrays above are in its numbering.

        Returns
        -------
        E : float, ``E(U, R*(U))`` (mesh units^2; the sum of ``Ek``).
        """
        kern = _fused(threads)
        if not kern:
            if data is None or data.perm is None:
                Rn, E = self._rotations_numpy(U, True, warm)
                R[...] = Rn
                return E
            inv, perm = data.inv, data.perm  # numpy path in the mesh's numbering
            Wo = None if warm is None else warm[inv]
            Rn, E = self._rotations_numpy(np.asarray(U)[inv], True, Wo)
            R[...] = Rn[perm]
            if warm is not None:
                warm[...] = Wo[perm]
            return E
        if data is None:
            data = self.kernel_data(False)
        U = np.ascontiguousarray(U, np.float64)
        n = self.n
        for name, a, shape in (("U", U, (n, 3)), ("R", R, (n, 3, 3)), ("Ek", Ek, (n,)),
                               ("warm", R if warm is None else warm, (n, 3, 3))):
            if not (isinstance(a, np.ndarray) and a.shape == shape and a.dtype == np.float64
                    and a.flags.c_contiguous):
                raise SShaDeError(f"{name} must be a C-contiguous float64 array of shape {shape}")
        args = (U, *data.local_arrays(), R if warm is None else warm, warm is not None, R, Ek)
        if threads > 1:
            with _numba_threads(threads):
                kern[0](*args)
        else:
            kern[0](*args)
        # summed in the mesh's cell order: the same float in every numbering
        return float((Ek if data.perm is None else Ek[data.inv]).sum())

    def rotations(self, U: np.ndarray, *, return_energy: bool = False, warm: np.ndarray | None = None,
                  threads: int | None = None):
        """Optimal rotations for ``U`` (the local step), optionally with ``E(U)``.

        Parameters
        ----------
        U : (n, 3) float64.
        return_energy : bool, also return the energy with these rotations.
        warm : (n, 3, 3) float64 or None, warm start of the polar kernel, updated in place
            (:func:`fit_rotations`).
        threads : int or None, threads of the numba kernel (:func:`resolve_threads`).

        Returns
        -------
        R : (n, 3, 3) float64 rotations. E : float, only with ``return_energy``
            (mesh units^2; :meth:`energy`).
        """
        t = resolve_threads(threads, self.n)
        if _fused(t):
            if warm is not None and (not isinstance(warm, np.ndarray) or warm.shape != (self.n, 3, 3)
                                     or warm.dtype != np.float64 or not warm.flags.c_contiguous):
                raise SShaDeError(f"warm must be a C-contiguous float64 array of shape {(self.n, 3, 3)}")
            R = np.empty((self.n, 3, 3))
            E = self.local_step(U, R, np.empty(self.n), warm, t)
            return (R, E) if return_energy else R
        return self._rotations_numpy(U, return_energy, warm)

    def _rotations_numpy(self, U, return_energy, warm):
        """Local step with scipy's ``KT @ U`` and :func:`fit_rotations` (no fused kernel)."""
        M = self.covariances(U)
        R, tr = fit_rotations(M, return_trace=True, warm=warm if _numba_kernel() else None)
        if not return_energy:
            return R
        return R, self._energy(U, R, tr)

    def _energy_from_trace(self, U: np.ndarray, tr: np.ndarray) -> float:
        """Closed form on edge differences (translation-invariant; ~1e-13 relative noise)."""
        ed = U[self.edges[:, 0]] - U[self.edges[:, 1]]
        return float((self.edge_w * np.einsum("ij,ij->i", ed, ed)).sum() + self.rest_term - 2.0 * tr.sum())

    def _energy(self, U: np.ndarray, R: np.ndarray, tr: np.ndarray | None) -> float:
        """Energy ``E(U, R)``: the numba term-by-term sum when available (~1e-15 relative
        noise, needed to compare energies of iterates near the minimum), else the closed
        form (``tr[k] = tr(R_k^T M_k)`` required)."""
        kern = _numba_energy_kernel()
        if kern:
            out = np.empty(self.n)
            kern(np.ascontiguousarray(U, np.float64), self.edges, self.edge_vec, self.cell_ptr, self.pair_edge,
                 self.pair_w, np.ascontiguousarray(R), out)
            return float(out.sum())
        if tr is None:
            tr = np.einsum("kab,kab->k", R, self.covariances(U))
        return self._energy_from_trace(U, tr)

    # ----------------------------------------------------------------- global step
    def rhs(self, R: np.ndarray, *, threads: int | None = None) -> np.ndarray:
        """Right-hand side ``K(R)`` of the global step ``L U = K(R)``.

        Parameters
        ----------
        R : (n, 3, 3) float64 per-cell rotations.
        threads : int or None, threads of the numba kernel (:func:`resolve_threads`).

        Returns
        -------
        B : (n, 3) float64, ``B_s = sum_{(k,e), e=(s,d)} a_ke R_k (v_s - v_d)`` (and the
            negative for the other end point).
        """
        out = np.empty((self.n, 3))
        return self.rhs_rows(R, np.arange(self.n, dtype=np.uint32), np.zeros((self.n, 3)), out,
                             resolve_threads(threads, self.n))

    def rhs_rows(self, R: np.ndarray, rows: np.ndarray, sub: np.ndarray, out: np.ndarray,
                 threads: int = 1, data: KernelData | None = None) -> np.ndarray:
        """``out = K(R)[rows] - sub``, the global step's right-hand side on some rows.

        Numba: a kernel over the rows (parallel for ``threads > 1``) gathering the
        rotations of the neighbouring cells; else scipy's ``K @ Rs``.

        Parameters
        ----------
        R : (n, 3, 3) float64 rotations. rows : (r,) integer vertex indices (uint32 spares a
            conversion).
        sub : (r, 3) float64. out : (r, 3) float64 C-contiguous, written.
        threads : int >= 1.
        data : :class:`KernelData` or None (mesh numbering); ``R`` and ``rows`` are in its
            numbering.

        Returns
        -------
        out.
        """
        kern = _fused(threads)
        if not kern:
            if data is not None and data.perm is not None:  # numpy path in the mesh's numbering
                R = np.asarray(R)[data.inv]
                rows = data.perm[rows]
            Rs = np.ascontiguousarray(np.asarray(R, np.float64).transpose(2, 0, 1)).reshape(3 * self.n, 3)
            np.subtract((self.K @ Rs)[rows], sub, out=out)
            return out
        if data is None:
            data = self.kernel_data(False)
        rows = rows if rows.dtype == np.uint32 and rows.flags.c_contiguous else _u32(rows)
        R = np.ascontiguousarray(R, np.float64)
        sub = np.ascontiguousarray(sub, np.float64)
        r = len(rows)
        if (r and rows.max() >= self.n) or R.shape != (self.n, 3, 3) or sub.shape != (r, 3) \
                or not (isinstance(out, np.ndarray) and out.shape == (r, 3) and out.dtype == np.float64
                        and out.flags.c_contiguous):
            raise SShaDeError("rhs_rows: rows must index vertices, R be (n, 3, 3), sub and out (len(rows), 3) "
                              "float64 (out C-contiguous)")
        args = (rows, *data.kv, R, sub, out)
        if threads > 1:
            with _numba_threads(threads):
                kern[1](*args)
        else:
            kern[1](*args)
        return out

    # ------------------------------------------------------------ energy/gradient
    def energy(self, U: np.ndarray, R: np.ndarray | None = None) -> float:
        """ARAP energy ``E(U) = min_R E(U, R)`` (or ``E(U, R)`` for given ``R``).

        Summed term by term (numba kernel, relative rounding noise ~1e-15) or, without
        numba, in closed form ``E = sum_e w_e (||e'_e||^2 + ||e_e||^2) - 2 sum_k
        tr(R_k^T M_k)`` (rotations preserve lengths; the edge weights over all cells sum
        to ``w_e``; noise ~1e-13 relative from cancellation).

        Parameters
        ----------
        U : (n, 3) float64 deformed positions.
        R : (n, 3, 3) float64 or None; None: the optimal rotations.

        Returns
        -------
        float, mesh units^2 (``0`` for a rigid motion of ``V``).
        """
        U = np.asarray(U, np.float64)
        if R is None:
            return self.rotations(U, return_energy=True)[1]
        return self._energy(U, np.asarray(R, np.float64), None)

    def energy_direct(self, U: np.ndarray, R: np.ndarray | None = None) -> float:
        """Same as :meth:`energy` but summed term by term,
        ``sum_k sum_e a_ke ||e'_e - R_k e_e||^2`` (for tests; O(p) memory)."""
        U = np.asarray(U, np.float64)
        if R is None:
            R = self.rotations(U)
        ed = U[self.edges[:, 0]] - U[self.edges[:, 1]]
        r = ed[self.pair_edge] - np.einsum("kab,kb->ka", R[self.pair_cell], self.edge_vec[self.pair_edge])
        return float((self.pair_w * (r * r).sum(1)).sum())

    def gradient(self, U: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        """Gradient ``dE/dU = 2 (L U - K(R))`` with the optimal rotations ``R*(U)``.

        Parameters
        ----------
        U : (n, 3) float64. R : (n, 3, 3) or None (None: optimal rotations for ``U``;
            then this is the gradient of ``E(U) = min_R E(U, R)`` by the envelope theorem).

        Returns
        -------
        (n, 3) float64, mesh units (energy units / length).
        """
        U = np.asarray(U, np.float64)
        if R is None:
            R = self.rotations(U)
        return 2.0 * (self.L @ U - self.rhs(R))

    def local_global_step(self, U: np.ndarray, handles: np.ndarray, targets: np.ndarray,
                          solve) -> np.ndarray:
        """One local/global iteration (for tests and simple use).

        Parameters
        ----------
        U : (n, 3) float64 current positions. handles : (h,) int64; targets : (h, 3).
        solve : callable, ``X = solve(B)`` solving ``L_ff X = B`` for ``(n_f, 3)`` ``B``
            on the free vertices (``np.setdiff1d(arange(n), handles)``, sorted).

        Returns
        -------
        (n, 3) float64 next iterate (handles at their targets).
        """
        free = np.setdiff1d(np.arange(self.n), handles)
        R = self.rotations(U)
        B = self.rhs(R)
        Ut = np.array(U, np.float64)
        Ut[handles] = targets
        Ut[free] = 0.0
        B = B - self.L @ Ut
        Un = Ut.copy()
        Un[free] = solve(B[free])
        return Un


def locality_order(L) -> np.ndarray:
    """A cache-friendly vertex numbering: reverse Cuthill-McKee of the pattern of ``L``.

    Parameters
    ----------
    L : (n, n) scipy.sparse matrix with a symmetric pattern (the cotangent Laplacian).

    Returns
    -------
    perm : (n,) int64, ``perm[new] = old``.
    """
    from scipy.sparse.csgraph import reverse_cuthill_mckee
    return np.asarray(reverse_cuthill_mckee(sp.csr_matrix(L), symmetric_mode=True), np.int64)


def _permute_csr(ptr, idx, val, perm, inv):
    """Rows of a CSR taken in the order ``perm`` (row ``i`` of the result is row
    ``perm[i]``), column indices mapped by ``inv``; the entries of a row keep their order.
    ``val`` (nnz, ...) may be None. Returns ``(ptr, idx, val, src)`` with ``src`` the old
    position of every entry."""
    lens = np.diff(ptr)[perm]
    nptr = np.zeros(len(perm) + 1, np.int64)
    np.cumsum(lens, out=nptr[1:])
    src = np.repeat(ptr[:-1][perm] - nptr[:-1], lens) + np.arange(nptr[-1], dtype=np.int64)
    nidx = None if idx is None else (idx[src] if inv is None else inv[idx[src]])
    return nptr, nidx, None if val is None else np.ascontiguousarray(val[src]), src


@dataclass(eq=False)
class KernelData:
    """The arrays of the fused numba kernels, in one vertex numbering.

    Attributes
    ----------
    perm : (n,) int64 or None, ``perm[new] = old`` (None: the mesh's numbering); ``inv``
        its inverse (``inv[old] = new``). Cells are numbered as vertices.
    kt : ``(ptr (n + 1,) uint64, idx (nnz,) uint32, val (nnz, 3) float64)``, the three
        blocks of ``K^T`` as one CSR with 3-vector values: the covariance of cell ``k`` is
        ``M_k[c, d] = sum_jj val[jj, d] U[idx[jj], c]`` (``scipy``'s ``KT @ U``, same
        entries in the same order).
    kv : same for ``K``: ``K(R)[v] = sum_d sum_jj val[jj, d] R[idx[jj], :, d]``.
    edges, edge_vec, cell_ptr, pair_edge, pair_w : the operators' arrays renumbered
        (edges sorted by their smaller new end point; every edge keeps its orientation and
        every cell the order of its pairs, so the cell energies are summed term by term in
        the same order in every numbering).

    Index arrays (``idx``, ``edges``, ``pair_edge``) are uint32 and pointer arrays
    (``ptr``, ``cell_ptr``) uint64: unsigned indices spare numba's negative-index
    wraparound (a quarter of the energy kernel's time).
    """

    perm: np.ndarray | None
    inv: np.ndarray | None
    kt: tuple
    kv: tuple
    edges: np.ndarray
    edge_vec: np.ndarray
    cell_ptr: np.ndarray
    pair_edge: np.ndarray
    pair_w: np.ndarray

    @classmethod
    def build(cls, ops: "ArapOperators", perm: np.ndarray | None = None) -> "KernelData":
        """From ``ops`` in the numbering ``perm`` (``perm[new] = old``; None: identity)."""
        n = ops.n
        kt = _csr3([ops.KT[d::3] for d in range(3)])
        kv = _csr3([ops.K[:, d * n:(d + 1) * n] for d in range(3)])
        if perm is None:
            return cls(None, None, _u32csr(kt), _u32csr(kv), _u32(ops.edges), ops.edge_vec,
                       np.ascontiguousarray(ops.cell_ptr, np.uint64), _u32(ops.pair_edge), ops.pair_w)
        perm = np.ascontiguousarray(perm, np.int64)
        inv = np.empty(n, np.int64)
        inv[perm] = np.arange(n, dtype=np.int64)
        kt = _permute_csr(*kt, perm, inv)[:3]
        kv = _permute_csr(*kv, perm, inv)[:3]
        es, ed = inv[ops.edges[:, 0]], inv[ops.edges[:, 1]]
        eperm = np.argsort(np.minimum(es, ed) * n + np.maximum(es, ed), kind="stable")
        einv = np.empty(len(eperm), np.int64)
        einv[eperm] = np.arange(len(eperm), dtype=np.int64)
        edges = np.ascontiguousarray(np.stack([es, ed], 1)[eperm])
        cell_ptr, pair_edge, _, src = _permute_csr(ops.cell_ptr, ops.pair_edge, None, perm, einv)
        return cls(perm, inv, _u32csr(kt), _u32csr(kv), _u32(edges), np.ascontiguousarray(ops.edge_vec[eperm]),
                   np.ascontiguousarray(cell_ptr, np.uint64), _u32(pair_edge), np.ascontiguousarray(ops.pair_w[src]))

    def local_arrays(self) -> tuple:
        """Arguments of the local kernel after ``U``."""
        return (*self.kt, self.edges, self.edge_vec, self.cell_ptr, self.pair_edge, self.pair_w)


def _u32(a) -> np.ndarray:
    """C-contiguous uint32 copy of a non-negative index array (< 2^32)."""
    a = np.asarray(a)
    if a.size and (a.min() < 0 or a.max() >= 2 ** 32):
        raise SShaDeError("index out of the uint32 range")
    return np.ascontiguousarray(a, np.uint32)


def _u32csr(c) -> tuple:
    """``(ptr uint64, idx uint32, val)``."""
    return np.ascontiguousarray(c[0], np.uint64), _u32(c[1]), np.ascontiguousarray(c[2], np.float64)


def _csr3(blocks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Three (r, c) CSR matrices as one CSR with 3-vector values (union of the patterns,
    entries in row-major order, missing ones 0): ``(ptr, idx, val)``."""
    blocks = [sp.csr_matrix(b) for b in blocks]
    for b in blocks:
        if not b.has_canonical_format:
            b.sum_duplicates()
    b0 = blocks[0]
    if all(np.array_equal(b.indptr, b0.indptr) and np.array_equal(b.indices, b0.indices) for b in blocks[1:]):
        val = np.stack([b.data for b in blocks], 1)
        return b0.indptr.astype(np.int64), b0.indices.astype(np.int64), np.ascontiguousarray(val, np.float64)
    r, c = b0.shape  # patterns differ (explicit zeros dropped somewhere): merge
    coo = [b.tocoo() for b in blocks]
    key = np.concatenate([x.row.astype(np.int64) * c + x.col for x in coo])
    ukey, inv = np.unique(key, return_inverse=True)
    val = np.zeros((len(ukey), 3))
    o = 0
    for d, x in enumerate(coo):
        val[inv[o:o + x.nnz], d] = x.data
        o += x.nnz
    ptr = np.zeros(r + 1, np.int64)
    np.cumsum(np.bincount(ukey // c, minlength=r), out=ptr[1:])
    return ptr, (ukey % c).astype(np.int64), val


def _check_mesh(V, F) -> tuple[np.ndarray, np.ndarray]:
    V = np.ascontiguousarray(V, np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) < 3:
        raise SShaDeError(f"V must have shape (n, 3) with n >= 3, got {np.shape(V)}")
    if not np.isfinite(V).all():
        raise SShaDeError("V contains NaN/inf")
    F = np.asarray(F)
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise SShaDeError(f"F must have shape (m, 3) with m >= 1, got {np.shape(F)}")
    if not np.issubdtype(F.dtype, np.integer):
        raise SShaDeError(f"F must hold integer vertex indices, got dtype {F.dtype}")
    F = np.ascontiguousarray(F, np.int64)
    if F.min() < 0 or F.max() >= len(V):
        raise SShaDeError(f"F has a vertex index out of range [0, {len(V)})")
    return V, F


def build_operators(V: np.ndarray, F: np.ndarray, energy: str = "spokes_and_rims") -> ArapOperators:
    """Precompute the ARAP operators of the rest mesh ``(V, F)`` for ``energy``.

    Parameters
    ----------
    V : (n, 3) float64 rest positions (any length unit). F : (m, 3) int faces.
    energy : ``"spokes"`` (Sorkine & Alexa 2007) or ``"spokes_and_rims"`` (Chao et al.
        2010), with libigl's weights (module docstring).

    Returns
    -------
    ArapOperators

    Raises
    ------
    SShaDeError
        Unknown energy; bad shapes, NaN/inf, indices out of range; a degenerate face (its
        cotangent weights are not finite); a vertex that is in no face.

    Examples
    --------
    >>> ops = build_operators(V, F, "spokes")  # doctest: +SKIP
    >>> ops.energy(V)  # rest pose: 0  # doctest: +SKIP
    """
    import igl

    if energy not in ENERGIES:
        raise SShaDeError(f"unknown ARAP energy {energy!r}; use one of {ENERGIES}")
    V, F = _check_mesh(V, F)
    n, m = len(V), len(F)
    if np.bincount(F.ravel(), minlength=n).min() == 0:
        raise SShaDeError("a vertex is referenced by no face (unreferenced vertex)")
    C = igl.cotmatrix_entries(V, F)  # (m, 3): cot/2 for edges [1,2], [2,0], [0,1]
    if not np.isfinite(C).all():
        bad = int(np.flatnonzero(~np.isfinite(C).all(1))[0])
        raise SShaDeError(f"face {bad} is degenerate (non-finite cotangent weight)")
    L = (-igl.cotmatrix(V, F)).tocsr()
    # face-edges: edge e of face f goes from S to D, opposite corner X
    S = F[:, [1, 2, 0]].ravel()
    D = F[:, [2, 0, 1]].ravel()
    X = F[:, [0, 1, 2]].ravel()
    c = C.ravel()
    lo, hi = np.minimum(S, D), np.maximum(S, D)
    key = lo * n + hi
    ukey, fe2e = np.unique(key, return_inverse=True)
    edges = np.stack([ukey // n, ukey % n], 1)
    ne = len(edges)
    edge_vec = V[edges[:, 0]] - V[edges[:, 1]]
    edge_w = np.bincount(fe2e, weights=c, minlength=ne)
    if energy == "spokes":
        cells = np.concatenate([S, D])
        pe = np.concatenate([fe2e, fe2e])
        pw = np.concatenate([c, c]) / 2.0
    else:
        cells = np.concatenate([S, D, X])
        pe = np.concatenate([fe2e, fe2e, fe2e])
        pw = np.concatenate([c, c, c]) / 3.0
    P = sp.coo_matrix((pw, (cells, pe)), shape=(n, ne)).tocsr()  # sums duplicates
    P.sort_indices()
    cell_ptr = P.indptr.astype(np.int64)
    P = P.tocoo()
    pair_cell, pair_edge, pair_w = P.row.astype(np.int64), P.col.astype(np.int64), P.data
    # K_d[s, k] += a e_d ; K_d[d, k] -= a e_d   for every pair (k, e = (s, d))
    s_, d_ = edges[pair_edge, 0], edges[pair_edge, 1]
    rows = np.concatenate([s_, d_])
    blocks = []
    for dd in range(3):
        val = pair_w * edge_vec[pair_edge, dd]
        blocks.append(sp.coo_matrix((np.concatenate([val, -val]),
                                     (rows, np.concatenate([pair_cell, pair_cell]))), shape=(n, n)).tocsr())
    K = sp.hstack(blocks, format="csr")
    KT = sp.vstack([b.T for b in blocks], format="csr")
    perm = (np.arange(3)[None, :] * n + np.arange(n)[:, None]).ravel()  # row 3k + d <- d n + k
    KT = KT[perm]
    rest_term = float((edge_w * (edge_vec ** 2).sum(1)).sum())
    mass = np.asarray(igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI).diagonal(), np.float64)
    return ArapOperators(energy_type=energy, n=n, V=V, F=F, edges=edges, edge_vec=edge_vec, edge_w=edge_w,
                         pair_cell=pair_cell, pair_edge=pair_edge, pair_w=pair_w, cell_ptr=cell_ptr, L=L, K=K, KT=KT,
                         rest_term=rest_term, mass=mass, diag=bbox_diag(V))

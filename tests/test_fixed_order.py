"""defaust/fixed_order.py: each function equals a pure-Python evaluation in its stated
order bit for bit (Python floats are IEEE doubles, one rounding per operation, no fused
multiply-add), agrees with numpy/scipy's BLAS and libm results to rounding, and gives the
same bytes under other BLAS thread counts and kernels (a subprocess each)."""
from __future__ import annotations

import hashlib
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from defaust import fixed_order as fo


def _rng():
    return np.random.default_rng(7)


def test_matmul_equals_the_left_to_right_python_sum_bit_for_bit_and_numpy_to_rounding():
    A, B = _rng().normal(size=(5, 3, 4)), _rng().normal(size=(5, 4, 2))
    got = fo.matmul(A, B)
    for b in range(5):
        for i in range(3):
            for j in range(2):
                s = A[b, i, 0] * B[b, 0, j]
                for k in range(1, 4):
                    s = s + A[b, i, k] * B[b, k, j]
                assert got[b, i, j] == s
    assert np.allclose(got, A @ B, rtol=0, atol=1e-14)


def test_blend_equals_the_ascending_python_sum_bit_for_bit_and_skipping_zero_columns_changes_nothing():
    rng = _rng()
    W = rng.random((50, 6)) * (rng.random((50, 6)) < 0.5)
    W[:, 2] = 0.0
    T = rng.normal(size=(6, 3, 4))
    got = fo.blend(W, T)
    for v in range(50):
        s = np.zeros(12)
        for j in range(6):
            s = s + W[v, j] * T[j].ravel()
        assert np.array_equal(got[v].ravel(), s)
    assert np.allclose(got, np.einsum("vj,jab->vab", W, T), rtol=0, atol=1e-14)


def test_rigid_inverse_and_apply_affine_undo_a_rigid_map_to_rounding():
    R = Rotation.random(4, random_state=1).as_matrix()
    T = np.zeros((4, 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, _rng().normal(size=(4, 3)), 1.0
    X = _rng().normal(size=(4, 3))
    back = fo.apply_affine(fo.rigid_inverse(T), fo.apply_affine(T, X))
    assert np.allclose(back, X, rtol=0, atol=1e-14)
    assert np.allclose(fo.rigid_inverse(T), np.linalg.inv(T), rtol=0, atol=1e-14)


def test_sum_ascending_equals_the_left_to_right_python_sum_bit_for_bit():
    X = _rng().normal(size=(40, 7)) * 10.0 ** _rng().integers(-8, 9, size=(40, 7))
    for axis in (0, 1):
        got = fo.sum_ascending(X, axis=axis)
        for i, row in enumerate(np.moveaxis(X, axis, -1)):
            s = row[0]
            for v in row[1:]:
                s = s + v
            assert got[i] == s
    col = X[:, 3]
    s = float(col[0])
    for v in col[1:].tolist():
        s = s + v
    assert float(fo.sum_ascending(col)) == s and fo.sum_ascending(col).shape == ()
    assert float(fo.sum_ascending([1.0, 1e16, -1e16])) == 0.0  # (1 + 1e16) rounds to 1e16 first
    with pytest.raises(ValueError):
        fo.sum_ascending(np.zeros((0, 3)))


def test_solve3_agrees_with_lapack_on_near_rotations():
    M = Rotation.random(20, random_state=2).as_matrix() * (1 + 0.1 * _rng().random((20, 1, 1)))
    y = _rng().normal(size=(20, 3))
    assert np.allclose(fo.solve3(M, y), np.linalg.solve(M, y[..., None])[..., 0], rtol=0, atol=1e-13)


def test_norm3_and_dot3_are_the_stated_sums():
    v = _rng().normal(size=(30, 3))
    for a in v:
        assert fo.norm3(a) == math.sqrt((a[0] * a[0] + a[1] * a[1]) + a[2] * a[2])
        assert fo.dot3(a, a[::-1]) == (a[0] * a[2] + a[1] * a[1]) + a[2] * a[0]


def _ulps(a, b) -> np.ndarray:
    return np.abs(np.asarray(a) - np.asarray(b)) / np.spacing(np.abs(np.asarray(b)))


def test_cross3_is_the_stated_differences_and_agrees_with_numpy():
    a, b = _rng().normal(size=(50, 3)), _rng().normal(size=(50, 3))[::-1]
    got = fo.cross3(a, b)
    for i in range(50):
        x, y = a[i].tolist(), b[i].tolist()
        assert got[i].tolist() == [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]]
    np.testing.assert_allclose(got, np.cross(a, b), rtol=0, atol=1e-15)


def test_decimal_transcendentals_are_within_one_ulp_of_libm_and_exact_on_known_values():
    x = np.concatenate([_rng().uniform(-7, 7, 300), [0.0, -0.0, 1e-300, math.pi, -math.pi / 2, 100.0]])
    assert (_ulps(fo.sin(x), np.array([math.sin(v) for v in x])) <= 1).all()
    assert (_ulps(fo.cos(x), np.array([math.cos(v) for v in x])) <= 1).all()
    y = _rng().normal(size=300)
    xx = _rng().normal(size=300)
    assert (_ulps(fo.atan2(y, xx), np.array([math.atan2(a, b) for a, b in zip(y, xx)])) <= 1).all()
    assert float(fo.sin(1.0)) == 0.8414709848078965 and float(fo.cos(1.0)) == 0.5403023058681398
    for a, b in ((0.0, 1.0), (-0.0, 1.0), (0.0, -1.0), (-0.0, -1.0), (0.0, 0.0), (-0.0, -0.0), (1.0, 0.0),
                 (-1.0, 0.0), (1e-320, 1.0), (5.0, -1e-300)):
        assert float(fo.atan2(a, b)) == math.atan2(a, b), (a, b)
    with pytest.raises(ValueError):
        fo.sin([1.0, np.nan])


def test_rotvec_to_matrix_agrees_with_scipy_and_gives_the_identity_at_zero():
    rv = np.vstack([Rotation.random(50, random_state=3).as_rotvec(), np.zeros(3), [1e-12, 0, 0]])
    R = fo.rotvec_to_matrix(rv)
    assert np.allclose(R, Rotation.from_rotvec(rv).as_matrix(), rtol=0, atol=1e-15)
    assert np.array_equal(R[50], np.eye(3))


def test_matrix_to_rotvec_inverts_rodrigues_and_agrees_with_scipy():
    rv = Rotation.random(300, random_state=4).as_rotvec()
    axis = rv / np.linalg.norm(rv, axis=1, keepdims=True)
    rv = np.vstack([rv, axis[:10] * (np.pi - 1e-9), axis[10:20] * 1e-9, np.zeros((1, 3))])
    R = fo.rotvec_to_matrix(rv)
    got = fo.matrix_to_rotvec(R)
    assert np.abs(got - rv).max() < 1e-13
    assert np.abs(got - Rotation.from_matrix(R).as_rotvec()).max() < 1e-13
    assert np.array_equal(got[-1], np.zeros(3))
    half = fo.matrix_to_rotvec(fo.rotvec_to_matrix(axis[:5] * np.pi))  # a half turn: +-axis * pi
    assert np.allclose(np.abs(fo.dot3(half, axis[:5])), np.pi, rtol=0, atol=1e-12)


def test_eigh3_agrees_with_lapack_on_random_repeated_and_nearly_repeated_eigenvalues():
    rng = np.random.default_rng(0)
    mats = [A @ A.T for A in rng.normal(size=(50, 3, 3))]
    mats += [np.diag([1.0, 1.0, 2.0]), np.diag([3.0, 2.0, 1.0]), np.zeros((3, 3)), np.diag([2.0, 2.0, 2.0])]
    mats += [np.diag([1.0, 1.0, 2.0]) + 1e-17 * mats[0]]  # nearly repeated values, tiny off-diagonals
    for C in mats:
        w, vecs = fo.eigh3(C)
        E = np.array(vecs)
        scale = max(1.0, float(np.abs(C).max()))
        np.testing.assert_allclose(w, np.linalg.eigvalsh(C)[::-1], atol=1e-13 * scale)
        np.testing.assert_allclose(E @ E.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(E @ C @ E.T, np.diag(w), atol=1e-13 * scale)


_PROBE = """
import hashlib, numpy as np
from defaust import fixed_order as fo
rng = np.random.default_rng(0)
A, B = rng.normal(size=(200, 4, 4)), rng.normal(size=(200, 4, 4))
W, T = rng.random((2000, 64)), rng.normal(size=(64, 3, 4))
parts = [fo.matmul(A, B), fo.blend(W, T), fo.rigid_inverse(A), fo.solve3(A[:, :3, :3], A[:, 3, :3]),
         fo.rotvec_to_matrix(A[:, 0, :3]), fo.atan2(A[:, 1, 1], A[:, 2, 2]),
         fo.matrix_to_rotvec(fo.rotvec_to_matrix(A[:, 1, :3])), fo.sum_ascending(W, axis=1),
         np.array([fo.eigh3(C)[1] for C in fo.matmul(A[:20], np.swapaxes(A[:20], 1, 2))])]
print(hashlib.sha256(b"".join(np.ascontiguousarray(p).tobytes() for p in parts)).hexdigest())
"""


def test_the_same_bytes_under_other_blas_thread_counts_and_kernels():
    outs = set()
    for env in ({"OPENBLAS_NUM_THREADS": "1"}, {"OPENBLAS_NUM_THREADS": "2", "OPENBLAS_CORETYPE": "Haswell"},
                {"OPENBLAS_NUM_THREADS": "2", "OPENBLAS_CORETYPE": "Sandybridge"}):
        r = subprocess.run([sys.executable, "-c", _PROBE], env={**os.environ, **env}, capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stderr
        outs.add(r.stdout.strip())
    assert len(outs) == 1, outs
    assert len(hashlib.sha256(b"").hexdigest()) == len(outs.pop())


def test_blend_skipping_zero_weights_gives_the_bytes_of_a_pass_over_every_row():
    """Sparse weights (a few joints per row, signed zeros in the items): the same bytes as
    adding ``W[:, j] T[j]`` to every row, joint by joint in ascending order."""
    rng = np.random.default_rng(3)
    n, k = 2000, 40
    W = np.zeros((n, k))
    for _ in range(4):
        W[np.arange(n), rng.integers(0, k, n)] = rng.random(n) * rng.choice([1.0, -1.0], n)
    W[:, 7] = 0.0
    T = rng.standard_normal((k, 3, 4))
    T[3] = -0.0
    T[5, 1, 2] = 0.0
    dense = np.zeros((n, 12))
    for j in range(k):
        dense = dense + W[:, j, None] * T[j].reshape(-1)
    assert fo.blend(W, T).tobytes() == dense.reshape(n, 3, 4).tobytes()

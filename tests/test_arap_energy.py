"""ARAP energies with libigl's weights (sshade.arap_energy): energy, gradient, local and
global steps against libigl and finite differences."""
import igl
import numpy as np
import pytest
from scipy.sparse.linalg import splu

from sshade.arap import rigid_fit
from sshade.arap_cases import bent_cylinder, twisted_bar
from sshade.arap_energy import ENERGIES, build_operators, fit_rotations
from sshade.errors import SShaDeError

IGL_ENERGY = {"spokes": igl.ARAP_ENERGY_TYPE_SPOKES, "spokes_and_rims": igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS}


@pytest.fixture(scope="module")
def bar():
    return twisted_bar(90.0, h=0.25)  # 290 vertices


def _random_rotation(rng):
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.linalg.det(Q))


@pytest.mark.parametrize("energy", ENERGIES)
def test_gradient_matches_finite_differences(bar, energy):
    V, F, _, _ = bar
    ops = build_operators(V, F, energy)
    rng = np.random.default_rng(1)
    U = V + 0.05 * rng.normal(size=V.shape)
    g = ops.gradient(U)
    eps = 1e-6
    for i, c in [(3, 0), (40, 1), (111, 2), (200, 0)]:
        Up, Um = U.copy(), U.copy()
        Up[i, c] += eps
        Um[i, c] -= eps
        fd = (ops.energy(Up) - ops.energy(Um)) / (2 * eps)
        assert fd == pytest.approx(g[i, c], rel=1e-6, abs=1e-7)
    D = rng.normal(size=V.shape)
    fd = (ops.energy(U + eps * D) - ops.energy(U - eps * D)) / (2 * eps)
    assert fd == pytest.approx(float((g * D).sum()), rel=1e-6)


@pytest.mark.parametrize("energy", ENERGIES)
def test_rigid_motion_has_zero_energy_and_gradient(bar, energy):
    V, F, _, _ = bar
    ops = build_operators(V, F, energy)
    rng = np.random.default_rng(2)
    U = V @ _random_rotation(rng).T + rng.normal(size=3)
    assert abs(ops.energy(U)) <= 1e-13 * ops.rest_term
    assert np.abs(ops.gradient(U)).max() <= 1e-12 * ops.diag
    assert ops.energy(V) == pytest.approx(0.0, abs=1e-13 * ops.rest_term)


@pytest.mark.parametrize("energy", ENERGIES)
def test_energy_closed_form_equals_term_by_term(bar, energy):
    V, F, _, _ = bar
    ops = build_operators(V, F, energy)
    U = V + 0.1 * np.random.default_rng(3).normal(size=V.shape)
    R, tr = fit_rotations(ops.covariances(U), return_trace=True)
    e_direct = ops.energy_direct(U, R)
    assert ops.energy(U) == pytest.approx(e_direct, rel=1e-12)
    assert ops._energy_from_trace(U, tr) == pytest.approx(e_direct, rel=1e-12)
    # libigl's quadratic: E(U, R) = tr(U'LU) - 2 tr(U'K(R)) + sum w |e|^2
    quad = float((U * (ops.L @ U)).sum() - 2 * (U * ops.rhs(R)).sum() + ops.rest_term)
    assert quad == pytest.approx(e_direct, rel=1e-10)
    # the optimal rotations are optimal: perturbing them raises E(U, R)
    P = np.stack([_random_rotation(np.random.default_rng(k)) for k in range(len(R))])
    Rp = np.einsum("kab,kbc->kac", R, np.eye(3) + 0.01 * (P - np.eye(3)))
    Rp = fit_rotations(Rp)
    assert ops.energy_direct(U, Rp) > e_direct


def test_rotation_backends_agree():
    rng = np.random.default_rng(4)
    M = rng.normal(size=(2000, 3, 3))
    M[:100, :, 2] = 0.0  # rank 2 (flat cells)
    M[100:200] = -np.eye(3) @ rng.normal(size=(100, 3, 3))
    Rn, trn = fit_rotations(M, return_trace=True, backend="numpy")
    Ra, tra = fit_rotations(M, return_trace=True)
    np.testing.assert_allclose(tra, trn, atol=1e-12)
    np.testing.assert_allclose(Ra, Rn, atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(Ra), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("kab,kab->k", Ra, M), trn, atol=1e-12)
    # warm start (previous right singular vectors) gives the same rotations
    W = np.broadcast_to(np.eye(3), M.shape).copy()
    fit_rotations(M, warm=W)
    Mp = M + 1e-3 * rng.normal(size=M.shape)
    Rw, trw = fit_rotations(Mp, return_trace=True, warm=W)
    Rc, trc = fit_rotations(Mp, return_trace=True, backend="numpy")
    np.testing.assert_allclose(trw, trc, atol=1e-12)
    full = slice(200, None)  # full-rank, non-reflected inputs: unique rotation
    np.testing.assert_allclose(Rw[full], Rc[full], atol=1e-9)
    with pytest.raises(SShaDeError):
        fit_rotations(M, warm=np.zeros((3, 3, 3)))


@pytest.mark.parametrize("energy", ENERGIES)
def test_one_step_equals_libigl(bar, energy):
    V, F, h, T = bar
    ops = build_operators(V, F, energy)
    R, t = rigid_fit(V[h], T)
    U0 = V @ R.T + t
    U0[h] = T
    data = igl.ARAPData()
    data.energy = IGL_ENERGY[energy]
    data.max_iter = 1
    igl.arap_precomputation(V, F, 3, h.astype(np.int32), data)
    U_igl = igl.arap_solve(T, data, U0)
    free = np.setdiff1d(np.arange(len(V)), h)
    lu = splu(ops.L[free][:, free].tocsc())
    U_ours = ops.local_global_step(U0, h, T, lu.solve)
    # libigl fits rotations in single precision: agreement to ~1e-6 of the diagonal
    assert np.abs(U_ours - U_igl).max() <= 1e-5 * ops.diag
    assert np.abs(U_ours - U0).max() > 1e-2 * ops.diag  # the step did move
    # with libigl's own single-precision rotations the global steps agree to rounding
    M = ops.covariances(U0)
    M = M / np.abs(M).max()  # libigl's normalisation before the float SVD
    R_igl = np.stack([igl.polar_svd3x3(np.ascontiguousarray(m.T)).T for m in M])
    B = ops.rhs(R_igl)
    Ut = U0.copy()
    Ut[free] = 0.0
    B = B - ops.L @ Ut
    Ue = Ut.copy()
    Ue[free] = lu.solve(B[free])
    assert np.abs(Ue - U_igl).max() <= 1e-10 * ops.diag


@pytest.mark.parametrize("energy", ENERGIES)
def test_local_global_never_increases_energy(energy):
    V, F, h, T = bent_cylinder(90.0, h=0.2)
    ops = build_operators(V, F, energy)
    R, t = rigid_fit(V[h], T)
    U = V @ R.T + t
    U[h] = T
    free = np.setdiff1d(np.arange(len(V)), h)
    lu = splu(ops.L[free][:, free].tocsc())
    E = [ops.energy(U)]
    for _ in range(50):
        U = ops.local_global_step(U, h, T, lu.solve)
        E.append(ops.energy(U))
    E = np.array(E)
    assert (np.diff(E) <= 1e-14 * E[0]).all()
    assert E[-1] < 0.5 * E[0]


def test_bad_input_raises(bar):
    V, F, _, _ = bar
    with pytest.raises(SShaDeError):
        build_operators(V, F, "elements")
    Vn = V.copy()
    Vn[0, 0] = np.nan
    with pytest.raises(SShaDeError):
        build_operators(Vn, F)
    with pytest.raises(SShaDeError):
        build_operators(V, F[:, :2])
    with pytest.raises(SShaDeError):
        build_operators(V, F + len(V))
    Vd = V.copy()
    Vd[F[0, 1]] = Vd[F[0, 0]]  # degenerate face
    with pytest.raises(SShaDeError):
        build_operators(Vd, F)
    with pytest.raises(SShaDeError):
        fit_rotations(np.eye(3)[None], backend="lapack")

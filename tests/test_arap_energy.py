"""ARAP energies with libigl's weights (sshade.arap.operators): energy, gradient, local and
global steps against libigl and finite differences."""
import igl
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from sshade.arap import ENERGIES, build_operators, fit_rotations, rigid_fit
from sshade.arap.operators import TRACE_MIN_ENERGY
from sshade.arap.problems import bent_cylinder, twisted_bar
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


def _bumpy_bar():
    """The bar with its vertices moved at random (obtuse faces, negative weights) and its
    faces shuffled, so that no face order or orientation is special."""
    V, F, _, _ = twisted_bar(90.0, h=0.25)
    rng = np.random.default_rng(3)
    V = V + rng.normal(scale=0.02, size=V.shape)
    return V, np.ascontiguousarray(F[rng.permutation(len(F))])


@pytest.mark.parametrize("mesh", ["bar", "bumpy", "cylinder"])
@pytest.mark.parametrize("energy", ENERGIES)
def test_laplacian_and_pairs_are_libigls_and_a_sparse_assembly_to_the_bit(bar, mesh, energy):
    V, F = {"bar": bar[:2], "bumpy": _bumpy_bar(), "cylinder": bent_cylinder()[:2]}[mesh]
    ops = build_operators(V, F, energy)
    L = (-igl.cotmatrix(V, F)).tocsr()
    L.sort_indices()
    assert np.array_equal(ops.L.indptr, L.indptr) and np.array_equal(ops.L.indices, L.indices)
    assert np.array_equal(ops.L.data, L.data)  # libigl's sums, in its order
    # the (cell, edge) pairs: scipy's sum of every face's contributions
    C = igl.cotmatrix_entries(V, F)
    key = {tuple(e): i for i, e in enumerate(ops.edges)}
    cells, pe, pw = [], [], []
    for f in range(len(F)):
        for k in range(3):
            s, d, x = F[f, (k + 1) % 3], F[f, (k + 2) % 3], F[f, k]
            e = key[(min(s, d), max(s, d))]
            for cell in ((s, d) if energy == "spokes" else (s, d, x)):
                cells.append(cell)
                pe.append(e)
                pw.append(C[f, k] / (2.0 if energy == "spokes" else 3.0))
    P = sp.coo_matrix((pw, (cells, pe)), shape=(len(V), len(ops.edges))).tocsr()
    P.sort_indices()
    assert np.array_equal(ops.cell_ptr, P.indptr) and np.array_equal(ops.pair_edge, P.indices)
    assert np.array_equal(ops.pair_cell, np.repeat(np.arange(len(V)), np.diff(P.indptr)))
    assert np.array_equal(ops.pair_w, P.data)


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


# ------------------------------------------------------------------ numba kernels
def test_polar_kernel_special_inputs():
    rng = np.random.default_rng(7)
    M = rng.normal(size=(300, 3, 3))  # not a multiple of the kernel's block of cells
    M[:10] = 0.0
    M[10:20] = rng.normal(size=(10, 3, 1)) * rng.normal(size=(10, 1, 3))  # rank one
    M[20:30] = np.eye(3)
    M[30:40] = np.diag([2.0, 2.0, 0.0])
    R, tr = fit_rotations(M, return_trace=True, backend="numba")
    np.testing.assert_array_equal(R[:10], np.broadcast_to(np.eye(3), (10, 3, 3)))
    np.testing.assert_array_equal(tr[:10], 0.0)
    np.testing.assert_allclose(np.einsum("kab,kcb->kac", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.einsum("kab,kab->k", R, M), tr, atol=1e-12)
    Rn, trn = fit_rotations(M[40:], return_trace=True, backend="numpy")
    np.testing.assert_allclose(tr[40:], trn, atol=1e-12)
    np.testing.assert_allclose(R[40:], Rn, atol=1e-9)


@pytest.mark.parametrize("energy", ENERGIES)
def test_fused_local_step_matches_separate_steps(bar, energy):
    V, F, _, _ = bar
    ops = build_operators(V, F, energy)
    rng = np.random.default_rng(8)
    U = V + 0.05 * rng.normal(size=V.shape)
    n = ops.n
    W = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    W2 = W.copy()
    R, Ek = np.empty((n, 3, 3)), np.empty(n)
    for _step in range(3):
        E = ops.local_step(U, R, Ek, W, 1)
        M = np.ascontiguousarray(ops.covariances(U))
        R2 = fit_rotations(M, warm=W2)
        # same covariances, same polar arithmetic, same warm start: the same floats
        np.testing.assert_array_equal(R, R2)
        np.testing.assert_array_equal(W, W2)
        assert E == pytest.approx(ops.energy_direct(U, R), rel=1e-12)
        assert E == ops.energy(U, R)  # the same per-cell sums in the same order
        U = U + 1e-3 * rng.normal(size=V.shape)
    # right-hand side kernel = scipy's K @ Rs up to rounding
    Rs = np.ascontiguousarray(R.transpose(2, 0, 1)).reshape(3 * n, 3)
    B = ops.rhs(R, threads=1)
    np.testing.assert_allclose(B, ops.K @ Rs, rtol=0, atol=1e-13 * np.abs(B).max())


@pytest.mark.parametrize("trace", [False, True], ids=["pairs", "trace form"])
@pytest.mark.parametrize("energy", ENERGIES)
def test_kernels_independent_of_threads_and_numbering(bar, energy, trace):
    V, F, _, _ = bar
    ops = build_operators(V, F, energy)
    n = ops.n
    U = V + 0.05 * np.random.default_rng(9).normal(size=V.shape)
    out = {}
    for reorder in (False, True):
        kd = ops.kernel_data(reorder)
        perm = np.arange(n) if kd.perm is None else kd.perm
        for t in (1, 2):
            W = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
            R, Ek = np.empty((n, 3, 3)), np.empty(n)
            Et = np.empty(len(ops.edges)) if trace else None
            E = ops.local_step(np.ascontiguousarray(U[perm]), R, Ek, W, t, kd, Et)
            rows = np.arange(n, dtype=np.uint32)
            B = ops.rhs_rows(R, rows, np.zeros((n, 3)), np.empty((n, 3)), t, kd)
            inv = np.argsort(perm)
            out[reorder, t] = (R[inv], Ek[inv], E, W[inv], B[inv])
    ref = out[False, 1]
    for val in out.values():
        for a, b in zip(ref[:4], val[:4]):  # rotations, cell energies or traces, energy, warm start: bit-identical
            np.testing.assert_array_equal(a, b)
        np.testing.assert_allclose(val[4], ref[4], rtol=0, atol=1e-13 * np.abs(ref[4]).max())
    np.testing.assert_array_equal(out[True, 1][4], out[True, 2][4])  # same numbering: same floats


@pytest.mark.parametrize("energy", ENERGIES)
def test_trace_form_is_the_term_by_term_energy_and_gives_way_to_it_near_rigid_states(bar, energy):
    V, F, _, _ = bar
    ops = build_operators(V, F, energy)
    n, ne = ops.n, len(ops.edges)
    rng = np.random.default_rng(11)
    Q = _random_rotation(rng)
    states = {"deformed": V + 0.05 * rng.normal(size=V.shape),
              "nearly rigid": V @ Q.T + 0.3 + 1e-7 * rng.normal(size=V.shape)}
    for name, U in states.items():
        runs = {}
        for Et in (None, np.empty(ne)):
            W = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
            R, Ek = np.empty((n, 3, 3)), np.empty(n)
            runs[Et is None] = (ops.local_step(np.ascontiguousarray(U), R, Ek, W, 1, None, Et), R, W)
        (E_pairs, R_pairs, W_pairs), (E_trace, R_trace, W_trace) = runs[True], runs[False]
        np.testing.assert_array_equal(R_trace, R_pairs)  # the same rotations and warm starts either way
        np.testing.assert_array_equal(W_trace, W_pairs)
        if abs(E_pairs) >= TRACE_MIN_ENERGY * ops.rest_term:
            assert name == "deformed" and E_trace == pytest.approx(E_pairs, rel=1e-10, abs=0)
        else:  # below the threshold the trace form's terms cancel: the pair sum, bit for bit
            assert name == "nearly rigid" and E_trace == E_pairs


def test_numpy_fallbacks_when_numba_is_off(monkeypatch, bar):
    from sshade.arap import kernels
    V, F, _, _ = bar
    ops = build_operators(V, F, "spokes_and_rims")
    U = V + 0.05 * np.random.default_rng(10).normal(size=V.shape)
    R1, E1 = ops.rotations(U, return_energy=True)
    B1 = ops.rhs(R1)
    monkeypatch.setattr(kernels, "_POLAR", False)
    monkeypatch.setattr(kernels, "_ENERGY", False)
    R2, E2 = ops.rotations(U, return_energy=True)
    np.testing.assert_allclose(R2, R1, atol=1e-9)
    assert E2 == pytest.approx(E1, rel=1e-10)
    np.testing.assert_allclose(ops.rhs(R1), B1, atol=1e-13 * np.abs(B1).max())
    # the numpy path in a renumbered KernelData
    kd = ops.kernel_data(True)
    n = ops.n
    R3, Ek = np.empty((n, 3, 3)), np.empty(n)
    E3 = ops.local_step(np.ascontiguousarray(U[kd.perm]), R3, Ek, None, 1, kd)
    np.testing.assert_allclose(R3, R1[kd.perm], atol=1e-9)
    assert E3 == pytest.approx(E1, rel=1e-10)
    B3 = ops.rhs_rows(R3, np.arange(n), np.zeros((n, 3)), np.empty((n, 3)), 1, kd)
    np.testing.assert_allclose(B3, B1[kd.perm], atol=1e-9 * np.abs(B1).max())


def test_resolve_threads():
    import threading

    from sshade.arap import MAIN_MIN_CELLS, PARALLEL_MIN_CELLS, beside_others, max_threads, resolve_threads
    assert resolve_threads(None, 100) == 1
    assert resolve_threads(None, MAIN_MIN_CELLS - 1) == 1
    assert resolve_threads(None, MAIN_MIN_CELLS) == max_threads()  # the main thread's threshold
    assert resolve_threads(None, PARALLEL_MIN_CELLS) == max_threads()
    got = {}
    t = threading.Thread(target=lambda: got.update(small=resolve_threads(None, MAIN_MIN_CELLS),
                                                   large=resolve_threads(None, PARALLEL_MIN_CELLS)))
    t.start()
    t.join()
    assert got == {"small": 1, "large": max_threads()}  # another thread: the larger threshold
    with beside_others():  # SShaDe's low-res solves: the larger threshold in the main thread too
        with beside_others():
            assert resolve_threads(None, MAIN_MIN_CELLS) == 1
        assert resolve_threads(None, MAIN_MIN_CELLS) == 1
        assert resolve_threads(None, PARALLEL_MIN_CELLS) == max_threads()
    assert resolve_threads(None, MAIN_MIN_CELLS) == max_threads()
    assert resolve_threads(1, 10 ** 6) == 1
    assert resolve_threads(10 ** 6, 100) == max_threads()
    for bad in (0, -1, 1.5):
        with pytest.raises(SShaDeError):
            resolve_threads(bad, 100)


def test_kernel_entry_points_check_their_arrays(bar):
    V, F, _, _ = bar
    ops = build_operators(V, F, "spokes_and_rims")
    n = ops.n
    with pytest.raises(SShaDeError):
        ops.local_step(V, np.empty((n - 1, 3, 3)), np.empty(n))
    with pytest.raises(SShaDeError):
        ops.local_step(V, np.empty((n, 3, 3)), np.empty(n), warm=np.empty((n, 3, 3), np.float32))
    R = ops.rotations(V)
    with pytest.raises(SShaDeError):
        ops.rhs_rows(R, np.array([n]), np.zeros((1, 3)), np.empty((1, 3)))
    with pytest.raises(SShaDeError):
        ops.rhs_rows(R, np.array([0, 1]), np.zeros((1, 3)), np.empty((2, 3)))

"""sshade.arap.accelerate: the L-BFGS direction in its compact form (Byrd, Nocedal &
Schnabel 1994) against Nocedal & Wright's two-loop recursion (Algorithm 7.4), written here
in numpy, on the iterates of a convex quadratic; the ring's bookkeeping (wrap-around, a
rejected pair, a restart that keeps the pairs); the float32 history (the matrix of the
rounded pairs, within rounding of float64's); the numpy fallback kernels against numba's.
"""
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from sshade.arap import accelerate, solver_kernels
from sshade.arap.accelerate import LBFGS


@pytest.fixture
def float64_history(monkeypatch):
    """L-BFGS's history kept in float64: the compact form's algebra, exact to rounding."""
    monkeypatch.setattr(accelerate, "LBFGS_HISTORY_DTYPE", np.float64)


def _two_loop(S, Y, Z, gamma, grad, z):
    """``H grad`` by the two-loop recursion with ``gamma H0``, ``H0 grad = z``, ``H0 y_i =
    Z_i`` (pairs oldest first; no pairs: ``z``)."""
    if not S:
        return z.copy()
    q, alpha = grad.copy(), []
    for s, y in zip(S[::-1], Y[::-1]):
        a = (s @ q) / (s @ y)
        alpha.append(a)
        q -= a * y
    r = gamma * z  # gamma H0 q, by linearity: H0 q = z - sum a_i Z_i
    for zz, a in zip(Z[::-1], alpha):
        r = r - gamma * a * zz
    for s, y, a in zip(S, Y, alpha[::-1]):
        r = r + (a - (y @ r) / (s @ y)) * s
    return r


def _problem(n=600, seed=0):
    """A sparse SPD ``L`` (n, n) (the initial Hessian's matrix) and a stiffer SPD ``Q``
    (3n, 3n) whose quadratic ``x^T Q x / 2`` is minimised."""
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=6 / n, random_state=seed)
    L = sp.csr_matrix(A @ A.T + sp.eye(n))
    Q = sp.kron(2.0 * L, sp.eye(3)) + sp.diags(3.0 * rng.random(3 * n))
    return L, sp.csr_matrix(Q), rng


def _run(m, steps, *, restart_at=None, seed=0, slope_rel=1e-10):
    """L-BFGS iterates ``x + 0.7 d`` on the quadratic; at each step the direction against
    the two-loop recursion on the pairs the reference keeps (the slope within
    ``slope_rel``). Returns the worst relative difference."""
    L, Q, rng = _problem(seed=seed)
    n = L.shape[0]
    solve = sla.factorized(sp.csc_matrix(2.0 * L))
    lb = LBFGS(m, L)
    x = rng.standard_normal((n, 3))
    S, Y, Z, prev, gamma = [], [], [], None, 1.0
    worst = 0.0
    for it in range(steps):
        if it == restart_at:  # a new problem on the same L: pairs kept, the last point forgotten
            lb.restart()
            prev = None
            x = x + 0.1 * rng.standard_normal(x.shape)
        grad = (Q @ x.ravel()).reshape(n, 3)
        z = np.stack([solve(grad[:, c]) for c in range(3)], 1)
        g = x - z  # the plain step's point, G(x)
        gk = np.ascontiguousarray(2.0 * (L @ (x - g)))
        d, slope = lb.direction(x, g, gk)
        gr, zr = gk.ravel(), (x - g).ravel()
        if prev is not None:
            s, y, h = x.ravel() - prev[0], gr - prev[1], zr - prev[2]
            S, Y, Z = (S + [s])[-m:], (Y + [y])[-m:], (Z + [h])[-m:]
            gamma = (s @ y) / (y @ h)
        prev = (x.ravel().copy(), gr.copy(), zr.copy())
        ref = _two_loop(S, Y, Z, gamma, gr, zr)
        assert lb.n_hist == len(S)
        worst = max(worst, np.abs(d.ravel() + ref).max() / np.abs(ref).max())
        assert slope == pytest.approx(-(gr @ ref), rel=slope_rel) and slope < 0
        x = x + 0.7 * d
    return worst


@pytest.mark.parametrize("m", [1, 3, 10])
def test_compact_direction_equals_the_two_loop_recursion_through_wraparound(m, float64_history):
    assert _run(m, 3 * m + 5) < 1e-12


def test_compact_direction_equals_the_two_loop_recursion_after_a_restart_that_keeps_the_pairs(float64_history):
    assert _run(4, 14, restart_at=8) < 1e-12


@pytest.mark.parametrize("m", [3, 10])
def test_float32_history_directions_are_within_its_rounding_of_the_exact_recursion(m):
    assert LBFGS(m, sp.eye(4)).hist.dtype == np.float32
    assert _run(m, 3 * m + 5, slope_rel=1e-5) < 1e-6
    assert _run(4, 14, restart_at=8, slope_rel=1e-5) < 1e-6


def test_float32_history_products_are_those_of_the_stored_rounded_pair():
    if solver_kernels.nb is None:
        pytest.skip("numba unusable")
    rng = np.random.default_rng(5)
    N, m, slot = 3001, 4, 1
    x, g, grad = (rng.standard_normal(N) for _ in range(3))
    prev = rng.standard_normal((3, N))
    y = grad - prev[1]
    for update in (solver_kernels.lbfgs_update, solver_kernels._numpy_lbfgs_update):
        hist, dots, p = rng.standard_normal((2, m, N)).astype(np.float32), np.zeros((4, m)), prev.copy()
        ss, _ = update(x, g, grad, p, hist, slot, True, np.array([0, 2], np.int64), dots)
        s, h = hist[0, slot].astype(np.float64), hist[1, slot].astype(np.float64)
        np.testing.assert_array_equal(s, (x - prev[0]).astype(np.float32))  # rounded once
        np.testing.assert_array_equal(h, ((x - g) - prev[2]).astype(np.float32))
        want = [s @ grad, h @ grad, s @ y, h @ y]
        np.testing.assert_allclose(dots[:, slot], want, rtol=1e-12)
        assert ss == pytest.approx(s @ s, rel=1e-12)
        assert abs(dots[2, slot] - (x - prev[0]) @ y) > 1e-12 * abs(dots[2, slot])  # the rounding is seen


def test_a_pair_failing_the_curvature_test_is_dropped_and_the_oldest_with_it_when_full():
    L, _, rng = _problem(n=50)
    lb = LBFGS(2, L)

    def direction(x, z):  # the solver's triple: x, G(x) = x - z, grad = 2 L z
        return lb.direction(x, x - z, np.ascontiguousarray(2.0 * (L @ z)))

    x = rng.standard_normal((50, 3))
    for _ in range(3):  # s = 0.1 x, H0 y = 0.05 x: s . y > 0, kept
        direction(x, 0.5 * x)
        z, x = 0.5 * x, 1.1 * x
    assert lb.n_hist == 2
    pos = lb.pos
    s = x - x / 1.1
    _, slope = direction(x, z - s)  # H0 y = -s: s . y = -2 s^T L s < 0, rejected
    assert lb.n_hist == 1 and lb.pos == pos and slope < 0  # the oldest pair's slot was overwritten


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_numpy_kernels_agree_with_numba(dtype):
    if solver_kernels.nb is None:
        pytest.skip("numba unusable")
    rng = np.random.default_rng(3)
    N, m, slot = 5000, 5, 2
    S, Z = rng.standard_normal((m, N)).astype(dtype), rng.standard_normal((m, N)).astype(dtype)
    vecs = [rng.standard_normal(N) for _ in range(6)]
    old = np.array([0, 1, 3, 4], np.int64)
    outs = []
    for update in (solver_kernels.lbfgs_update, solver_kernels._numpy_lbfgs_update):
        args = [v.copy() for v in vecs[:3]] + [np.array(vecs[3:]), np.array([S, Z])]
        dots = np.zeros((4, m))
        ss_yy = update(*args, slot, True, old, dots)
        outs.append((np.array(ss_yy), dots, args))
    np.testing.assert_allclose(outs[0][0], outs[1][0], rtol=1e-12)
    np.testing.assert_allclose(outs[0][1], outs[1][1], rtol=1e-11, atol=1e-9)
    for a, b in zip(outs[0][2], outs[1][2]):  # the new pair and the previous point: exact
        np.testing.assert_array_equal(a, b)
    SY = np.triu(rng.random((m, m))) + 5.0 * np.eye(m)
    YZ = rng.random((m, m))
    YZ = YZ + YZ.T
    idx = np.array([3, 4, 0, 1], np.int64)
    d = [np.empty(N), np.empty(N)]
    dots = np.array([vecs[0], vecs[1], vecs[4], vecs[5]])[:, :m]
    sl = [f(np.array([S, Z]), np.array([SY, YZ]), dots, idx, 1.7, vecs[2], vecs[3], dd)
          for f, dd in zip((solver_kernels.lbfgs_direction, solver_kernels._numpy_lbfgs_direction), d)]
    np.testing.assert_allclose(d[0], d[1], rtol=1e-11, atol=1e-12 * np.abs(d[1]).max())
    assert sl[0] == pytest.approx(sl[1], rel=1e-11)

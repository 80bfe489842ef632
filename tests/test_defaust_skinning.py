"""defaust.skinning's weight transfer: the sparse-row arithmetic gives the dense definition's
bytes (the DeFAUST build's files depend on them), and falls back to it where a left-out entry
would not be +0.0."""
from __future__ import annotations

import numpy as np
import pytest

from defaust import fixed_order as fo
from defaust import skinning as sk
from defaust.highres import ls3_loop
from sshade.errors import SShaDeError


def _dense_interpolate(W, corners, bc):
    """The definition: the dense arithmetic of transfer_weights, term by term."""
    out = bc[:, 0:1] * W[corners[:, 0]] + bc[:, 1:2] * W[corners[:, 1]] + bc[:, 2:3] * W[corners[:, 2]]
    out = np.maximum(out, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return out / fo.sum_ascending(out, axis=1)[:, None]


def _dense_subdivision(V, F, W, iterations):
    """The definition of subdivision_weights' weights: each new vertex the mean of its edge's ends."""
    Ws, Vt, Ft = W, V, F
    for _ in range(iterations):
        n = len(Ws)
        Vt, Ft = ls3_loop(Vt, Ft, 1)
        E = np.sort(np.concatenate([Ft[:, [0, 1]], Ft[:, [1, 2]], Ft[:, [2, 0]]]), axis=1)
        key = np.unique(E[:, 0] * len(Vt) + E[:, 1])
        E = np.stack([key // len(Vt), key % len(Vt)], axis=1)
        E = E[(E[:, 0] < n) & (E[:, 1] >= n)]
        E = E[np.argsort(E[:, 1], kind="stable")]
        Ws = np.concatenate([Ws, 0.5 * (Ws[E[0::2, 0]] + Ws[E[1::2, 0]])])
    return Ws


def _sparse_weights(rng, n, k, per_row=3):
    """(n, k) skinning-like weights: ``per_row`` random nonzero joints a row, rows summing to 1."""
    W = np.zeros((n, k))
    for i in range(n):
        j = rng.choice(k, per_row, replace=False)
        W[i, j] = rng.random(per_row)
    return W / W.sum(axis=1, keepdims=True)


def _problem(rng, n=300, k=40, p=2000):
    W = _sparse_weights(rng, n, k)
    corners = rng.integers(0, n, (p, 3))
    bc = rng.random((p, 3))
    bc /= bc.sum(axis=1, keepdims=True)
    bc[rng.random((p, 3)) < 0.1] = 0.0  # points on edges and corners
    bc[::97, 1] = -0.0  # a clipped -0.0 coordinate
    return W, corners, bc


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sparse_interpolation_gives_the_dense_definitions_bytes(seed):
    W, corners, bc = _problem(np.random.default_rng(seed))
    got = sk._interpolate(sk._sparse_rows(W), W.shape[1], corners, bc)
    assert got.tobytes() == _dense_interpolate(W, corners, bc).tobytes()


def test_negative_weights_clamped_and_all_zero_rows_give_the_dense_bytes():
    rng = np.random.default_rng(3)
    W, corners, bc = _problem(rng)
    W[5] = 0.0  # a row of zeros: 0/0 in the dense division
    corners[:10] = 5
    W[7, :3] = [-0.5, 0.25, 0.0]  # negative weights: the sum clamped at 0
    corners[10:20, 0] = 7
    got = sk._interpolate(sk._sparse_rows(W), W.shape[1], corners, bc)
    want = _dense_interpolate(W, corners, bc)
    assert np.isnan(want[:10]).all()
    assert got.tobytes() == want.tobytes()


def test_a_negative_zero_or_nan_weight_takes_the_dense_path():
    W, corners, bc = _problem(np.random.default_rng(4))
    for bad in (-0.0, np.nan, np.inf):
        V = W.copy()
        V[0, 0] = bad
        assert sk._sparse_rows(V) is None
        with np.errstate(invalid="ignore"):
            got = sk._interpolate(sk._sparse_rows(V) or V, V.shape[1], corners, bc)
        assert got.tobytes() == _dense_interpolate(V, corners, bc).tobytes()


def test_mean_rows_gives_the_dense_means_bytes():
    rng = np.random.default_rng(5)
    W = _sparse_weights(rng, 500, 30)
    a, b = rng.integers(0, 500, 800), rng.integers(0, 500, 800)
    S = sk._mean_rows(sk._sparse_rows(W), a, b)
    assert sk._dense(S, 30).tobytes() == (0.5 * (W[a] + W[b])).tobytes()
    stacked = sk._dense(sk._stack(sk._sparse_rows(W), S), 30)
    assert stacked.tobytes() == np.concatenate([W, 0.5 * (W[a] + W[b])]).tobytes()


def test_subdivision_and_high_res_weights_give_the_dense_definitions_bytes():
    rng = np.random.default_rng(6)
    V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    V, F = ls3_loop(V, F, 2)  # a small closed mesh to start from
    W = _sparse_weights(rng, len(V), 12, per_row=2)
    Vs, Fs, Ws = sk.subdivision_weights(V, F, W, 2)
    want = _dense_subdivision(V, F, W, 2)
    assert Ws.tobytes() == want.tobytes()
    P = Vs[::3] + 1e-3 * rng.standard_normal((len(Vs[::3]), 3))
    fi, bc = sk.closest_barycentric(Vs, Fs, P)
    got = sk.high_res_weights(V, F, W, P, 2)
    assert got.tobytes() == _dense_interpolate(want, Fs[fi], bc).tobytes()
    assert got.tobytes() == sk.transfer_weights(Vs, Fs, want, P).tobytes()


def test_a_last_level_whose_split_edges_are_not_the_level_befores_edges_is_refused(monkeypatch):
    """The last LS3 level's topology comes from the call that gives the positions; an old
    vertex numbered otherwise there than in the single iterations (two swapped) is refused."""
    V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    V, F = ls3_loop(V, F, 1)  # vertex 0 of valence 3, vertex 5 of valence 6
    W = _sparse_weights(np.random.default_rng(7), len(V), 6, per_row=2)
    real = sk.ls3_loop

    def swapped(V_, F_, iterations=1):
        Vs, Fs = real(V_, F_, iterations)
        if iterations == 2:
            p = np.arange(len(Vs))
            p[[0, 5]] = p[[5, 0]]
            Fs = p[Fs]
        return Vs, Fs

    monkeypatch.setattr(sk, "ls3_loop", swapped)
    with pytest.raises(SShaDeError, match="split edges are not the edges"):
        sk.subdivision_weights(V, F, W, 2)
    monkeypatch.setattr(sk, "ls3_loop", real)
    assert sk.subdivision_weights(V, F, W, 2)[2].tobytes() == _dense_subdivision(V, F, W, 2).tobytes()

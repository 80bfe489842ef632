"""sshade/lrf.py: the per-triangle frames and the transfer of Alg. 1, with either anchor
(the barycenter of Alg. 1, or each vertex's projection onto its triangle)."""
from __future__ import annotations

import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.lrf import (
    ANCHORS,
    anchor_points,
    decode,
    decode_with_frames,
    deformed_frames,
    encode,
    frame_functions,
    transfer,
)
from sshade.projection import closest_point_triangle


def _rotation(rng) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def _grid(n: int):
    """A planar n x n grid in z = 0 split into triangles: (n*n, 3) vertices, faces."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    i = np.arange(n - 1)
    a = (i[:, None] * n + i[None, :]).ravel()
    F = np.r_[np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]]
    return V, F.astype(np.int64)


def _on_coarse(V_high, VN, FN):
    """Triangle and barycentric coordinates of each high-res vertex on the coarse mesh
    (closest point over all triangles: a brute-force projection for small tests)."""
    tri, bary = np.empty(len(V_high), np.int64), np.empty((len(V_high), 3))
    for i, v in enumerate(V_high):
        best = None
        for t, f in enumerate(FN):
            b = closest_point_triangle(v, *VN[f])
            d = np.linalg.norm(b @ VN[f] - v)
            if best is None or d < best[0] - 1e-15:
                best = (d, t, b)
        tri[i], bary[i] = best[1], best[2]
    return tri, bary


@pytest.mark.parametrize("anchor", ANCHORS)
@pytest.mark.parametrize("gradient", ["normalized", "raw"])
def test_a_rigid_motion_is_reproduced_exactly(anchor, gradient):
    rng = np.random.default_rng(0)
    VN, FN = _grid(4)
    VN[:, 2] = 0.1 * rng.normal(size=len(VN))  # not planar
    V = rng.uniform(0, 1, size=(60, 3)) * [1, 1, 0.1]
    tri, bary = _on_coarse(V, VN, FN)
    R, t = _rotation(rng), rng.normal(size=3)
    Vd = transfer(V, tri, VN, VN @ R.T + t, FN, gradient=gradient, bary=bary if anchor == "projection" else None)
    np.testing.assert_allclose(Vd, V @ R.T + t, atol=1e-12)


def test_on_its_triangle_a_vertex_follows_any_motion_of_it_with_the_projection_anchor():
    """A piecewise-affine, non-rigid motion of a coarse mesh that represents the fine one
    exactly (both planar): the projection anchor moves every fine vertex exactly with
    the affine map of its triangle; the barycenter anchor of Alg. 1 does not."""
    rng = np.random.default_rng(1)
    VN, FN = _grid(3)
    V, _ = _grid(9)  # on the coarse triangles
    tri, bary = _on_coarse(V, VN, FN)
    VNd = VN * [1.6, 0.7, 1.0] + 0.05 * rng.normal(size=VN.shape)  # stretch, shear, lift per vertex
    exact = anchor_points(VNd, FN, tri, bary)  # the same barycentric point on each deformed triangle
    np.testing.assert_allclose(transfer(V, tri, VN, VNd, FN, bary=bary), exact, atol=1e-12)
    assert np.abs(transfer(V, tri, VN, VNd, FN) - exact).max() > 1e-2


def test_the_barycenter_anchor_is_alg1():
    """bary=None and bary=(1/3, 1/3, 1/3) are the same transfer: v' = L'_t L_t^T (v - b_t) + b'_t."""
    rng = np.random.default_rng(2)
    VN, FN = _grid(4)
    VN[:, 2] = 0.2 * rng.normal(size=len(VN))
    V = rng.uniform(0, 1, size=(40, 3))
    tri = rng.integers(0, len(FN), len(V))
    VNd = VN + 0.1 * rng.normal(size=VN.shape)
    third = np.full((len(V), 3), 1 / 3)
    np.testing.assert_allclose(transfer(V, tri, VN, VNd, FN), transfer(V, tri, VN, VNd, FN, bary=third), atol=1e-14)


def test_the_frame_fallback_fires_only_where_the_x_axis_is_near_the_normal():
    """frame_functions keeps x wherever |grad x| = sin(angle(x axis, n_t)) >= 0.5, whatever
    the triangle's shape; on a triangle facing x (normal within 30 deg) it takes another axis."""
    rng = np.random.default_rng(3)
    tris = rng.normal(size=(500, 3, 3))
    VN, FN = tris.reshape(-1, 3), np.arange(1500).reshape(-1, 3)
    n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    axis = frame_functions(VN, FN)
    far = np.abs(n[:, 0]) < np.cos(np.radians(30)) - 1e-9
    assert (axis[far] == 0).all() and (axis[~far] != 0).all() and (~far).any()


@pytest.mark.parametrize("anchor", ANCHORS)
def test_decoding_some_rows_into_or_onto_an_array_is_decode_bit_for_bit(anchor):
    """decode_with_frames on a block of rows, on chosen rows, and added onto an array: the
    same numbers as the whole decode (the blocks of Prepared's threaded average)."""
    rng = np.random.default_rng(3)
    VN, FN = _grid(4)
    VN[:, 2] = 0.1 * rng.normal(size=len(VN))
    V = rng.uniform(0, 1, size=(50, 3)) * [1, 1, 0.1]
    tri, bary = _on_coarse(V, VN, FN)
    bary = bary if anchor == "projection" else None
    axis = frame_functions(VN, FN)
    C = encode(V, tri, VN, FN, axis, "normalized", bary)
    VNd = VN + 0.05 * rng.normal(size=VN.shape)
    whole = decode(C, tri, VN, VNd, FN, axis, "normalized", bary)
    L = deformed_frames(VN, VNd, FN, axis)
    assert np.array_equal(decode_with_frames(L, C, tri, VNd, FN, bary, rows=slice(10, 30)), whole[10:30])
    rows = np.array([49, 0, 7])
    assert np.array_equal(decode_with_frames(L, C, tri, VNd, FN, bary, rows=rows), whole[rows])
    acc = np.ones((20, 3))
    decode_with_frames(L, C, tri, VNd, FN, bary, rows=slice(10, 30), out=acc, add=True)
    assert np.array_equal(acc, 1.0 + whole[10:30])
    with pytest.raises(SShaDeError, match="out must be"):
        decode_with_frames(L, C, tri, VNd, FN, bary, rows=slice(0, 5), out=np.empty((4, 3)))
    with pytest.raises(SShaDeError, match="add=True"):
        decode_with_frames(L, C, tri, VNd, FN, bary, add=True)

"""sshade/smooth_transfer.py: the transfer with the corners' deformation gradients
blended (``transfer="vertex"``): exact for rigid motions and at the low-res vertices,
the module's formula, and third-order accuracy on a smooth bending where Alg. 1's one
frame per triangle is second order; the decoding regrouped per corner (rest offsets made
once, corner maps once per deformed mesh) agrees with the module's formula as first
written out to rounding, and on rows, into or onto an array it gives the whole decode's
numbers bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.lrf import transfer
from sshade.smooth_transfer import (
    corner_maps,
    jacobian_rest,
    smooth_decode,
    smooth_decode_with,
    smooth_offsets,
    triangle_jacobians,
    vertex_jacobians,
)
from tests.test_lrf import _grid, _on_coarse, _rotation


def _bend(P, R=0.5):
    """Roll the plane z = 0 onto a cylinder of radius R (an isometry), z along the normal."""
    x, y, z = P.T
    return np.c_[(R - z) * np.sin(x / R), y, R - (R - z) * np.cos(x / R)]


def _bumpy(n, rng):
    VN, FN = _grid(n)
    VN[:, 2] = 0.1 * rng.normal(size=len(VN))
    return VN, FN


@pytest.mark.parametrize("projection", [True, False])
def test_a_rigid_motion_is_reproduced_exactly(projection):
    rng = np.random.default_rng(1)
    VN, FN = _bumpy(4, rng)
    V = rng.uniform(0, 1, size=(60, 3)) * [1, 1, 0.1]
    tri, bary = _on_coarse(V, VN, FN)
    R, t = _rotation(rng), rng.normal(size=3)
    Vd = smooth_decode(V, tri, bary if projection else None, VN, VN @ R.T + t, FN)
    np.testing.assert_allclose(Vd, V @ R.T + t, atol=1e-12)


def test_a_vertex_at_a_low_res_vertex_goes_exactly_to_its_deformed_position():
    rng = np.random.default_rng(2)
    VN, FN = _bumpy(5, rng)
    VD = VN + 0.2 * rng.normal(size=VN.shape)
    tri, bary = _on_coarse(VN, VN, FN)
    np.testing.assert_allclose(smooth_decode(VN, tri, bary, VN, VD, FN), VD, atol=1e-12)


def test_the_kernel_computes_the_module_formula():
    rng = np.random.default_rng(3)
    VN, FN = _bumpy(5, rng)
    VD = VN + 0.1 * rng.normal(size=VN.shape)
    V = rng.uniform(0, 1, size=(80, 3)) * [1, 1, 0.2]
    tri, bary = _on_coarse(V, VN, FN)
    J, A = triangle_jacobians(VN, VD, FN)
    Jv = np.zeros((len(VN), 3, 3))
    for t, f in enumerate(FN):  # area-weighted mean at the corners, written out
        for c in f:
            Jv[c] += A[t] * J[t]
    Jv /= np.bincount(FN.ravel(), weights=np.repeat(A, 3), minlength=len(VN))[:, None, None]
    np.testing.assert_allclose(vertex_jacobians(VN, VD, FN), Jv, atol=1e-13)
    C = FN[tri]
    a, ad = np.einsum("ni,nij->nj", bary, VN[C]), np.einsum("ni,nij->nj", bary, VD[C])
    Jbar = np.einsum("ni,nijk->njk", bary, Jv[C])
    want = ad + np.einsum("njk,nk->nj", Jbar, V - a) + 0.5 * np.einsum("ni,nijk,nik->nj", bary, Jv[C],
                                                                         a[:, None, :] - VN[C])
    np.testing.assert_allclose(smooth_decode(V, tri, bary, VN, VD, FN), want, atol=1e-13)


@pytest.mark.slow
def test_on_a_smooth_bending_the_error_falls_faster_than_with_one_frame_per_triangle():
    rng = np.random.default_rng(0)
    V = rng.uniform(0.1, 0.9, size=(300, 3))
    V[:, 2] = 0.0
    err = {}
    for n in (9, 17, 33):
        VN, FN = _grid(n)
        tri, bary = _on_coarse(V, VN, FN)
        err[n] = (np.abs(transfer(V, tri, VN, _bend(VN), FN, bary=bary) - _bend(V)).max(),
                  np.abs(smooth_decode(V, tri, bary, VN, _bend(VN), FN) - _bend(V)).max())
    for coarse, fine in ((9, 17), (17, 33)):
        assert err[coarse][0] / err[fine][0] < 4.5             # one frame per triangle: second order
        assert err[coarse][1] / err[fine][1] > 7.0             # corners blended: third order
    assert err[17][1] < err[17][0] / 50


def test_a_degenerate_low_res_triangle_is_refused():
    VN, FN = _grid(3)
    VD = VN.copy()
    VD[FN[0]] = VD[FN[0][0]]
    with pytest.raises(SShaDeError, match="degenerate"):
        vertex_jacobians(VN, VD, FN)


def _previous_decode(V, tri, bary, P, Q, FN, Jv):
    """The module formula as first computed (anchors, then each corner's gradient applied
    to the offset (v - a) + (a - N_k) / 2), written out in Python floats."""
    out = np.empty((len(tri), 3))
    for i in range(len(tri)):
        t, w = tri[i], (bary[i] if bary is not None else np.full(3, 1.0 / 3.0))
        a, ad = [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]
        for k in range(3):
            for d in range(3):
                a[d] += float(w[k]) * float(P[FN[t, k], d])
                ad[d] += float(w[k]) * float(Q[FN[t, k], d])
        o = list(ad)
        for k in range(3):
            c = FN[t, k]
            for d in range(3):
                s = 0.0
                for e in range(3):
                    s += float(Jv[c, d, e]) * ((float(V[i, e]) - a[e]) + 0.5 * (a[e] - float(P[c, e])))
                o[d] += float(w[k]) * s
        out[i] = o
    return out


def _case(seed=4):
    rng = np.random.default_rng(seed)
    VN, FN = _bumpy(5, rng)
    VD = VN + 0.1 * rng.normal(size=VN.shape)
    V = rng.uniform(0, 1, size=(70, 3)) * [1, 1, 0.2]
    tri, bary = _on_coarse(V, VN, FN)
    return VN, FN, VD, V, tri, bary


@pytest.mark.parametrize("projection", [True, False])
def test_the_regrouped_decoding_agrees_with_the_formula_first_written_out_to_rounding(projection):
    """The corner maps' regrouping (t_k + J_k g) against the anchor-and-offsets form, per
    coordinate within a few units in the last place of the positions (about 1 here)."""
    VN, FN, VD, V, tri, bary = _case()
    bary = bary if projection else None
    Jv = vertex_jacobians(VN, VD, FN)
    assert np.array_equal(vertex_jacobians(VN, VD, FN, rest=jacobian_rest(VN, FN)), Jv)
    got, want = smooth_decode(V, tri, bary, VN, VD, FN), _previous_decode(V, tri, bary, VN, VD, FN, Jv)
    assert np.abs(got - want).max() <= 8 * np.finfo(float).eps * np.abs(want).max()


@pytest.mark.parametrize("projection", [True, False])
def test_decoding_some_rows_into_or_onto_an_array_is_the_whole_decode_bit_for_bit(projection):
    """smooth_decode_with on a block of rows, on chosen rows, added onto an array: the
    numbers of the whole decode (a prepared SShaDe's sum over the samplings)."""
    VN, FN, VD, V, tri, bary = _case(5)
    bary = bary if projection else None
    whole = smooth_decode(V, tri, bary, VN, VD, FN)
    G, g = corner_maps(vertex_jacobians(VN, VD, FN), VN, VD), smooth_offsets(V, tri, bary, VN, FN)
    assert g.shape == (len(V), 3) and g.flags.c_contiguous and G.shape == (len(VN), 3, 4)
    assert np.array_equal(smooth_decode_with(G, g, tri, bary, FN), whole)
    assert np.array_equal(smooth_decode_with(G, g, tri, bary, FN, rows=slice(10, 30)), whole[10:30])
    rows = np.array([69, 0, 7])
    assert np.array_equal(smooth_decode_with(G, g, tri, bary, FN, rows=rows), whole[rows])
    acc = np.ones((20, 3))
    assert smooth_decode_with(G, g, tri, bary, FN, rows=slice(10, 30), out=acc, add=True) is acc
    assert np.array_equal(acc, 1.0 + whole[10:30])
    smooth_decode_with(G, g, tri, bary, FN, rows=slice(10, 30), out=acc)
    assert np.array_equal(acc, whole[10:30])


@pytest.mark.parametrize("out", [np.empty((4, 3)), np.empty((5, 3), np.float32), np.empty((3, 5)).T])
def test_a_bad_out_array_is_refused(out):
    VN, FN, VD, V, tri, bary = _case()
    G, g = corner_maps(vertex_jacobians(VN, VD, FN), VN, VD), smooth_offsets(V, tri, bary, VN, FN)
    with pytest.raises(SShaDeError, match="out must be"):
        smooth_decode_with(G, g, tri, bary, FN, rows=slice(0, 5), out=out)
    with pytest.raises(SShaDeError, match="add=True"):
        smooth_decode_with(G, g, tri, bary, FN, add=True)
    with pytest.raises(SShaDeError, match="step 1"):
        smooth_decode_with(G, g, tri, bary, FN, rows=slice(0, 10, 2))


def test_a_degenerate_rest_triangle_is_refused_by_the_rest_part():
    VN, FN = _grid(3)
    VN[FN[0]] = VN[FN[0][0]]
    with pytest.raises(SShaDeError, match="degenerate"):
        jacobian_rest(VN, FN)

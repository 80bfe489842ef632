"""Degenerate low-res faces (sshade/remesh_repair.py: degenerate_faces; sshade/remesh.py:
remesh_drawn): a face with almost no area for its size is found, repaired like a flipped
one, and a sampling that keeps one is drawn again with a derived seed, said in the info.
No sampling hands the low-res ARAP a triangle it cannot weigh."""
from __future__ import annotations

import importlib

import igl
import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.remesh import MAX_REDRAWS, redraw_seed, remesh_drawn
from sshade.remesh_repair import MIN_FACE_QUALITY, degenerate_faces

remesh_module = importlib.import_module("sshade.remesh")  # the package's `remesh` is the function


def test_degenerate_faces_flags_flat_and_near_flat_triangles_only():
    h = [1.0, 0.3, 10 * MIN_FACE_QUALITY, 0.3 * MIN_FACE_QUALITY, 1e-12, 0.0, np.nan]
    P = np.array([[0.0, 0, 0], [1.0, 0, 0]] + [[0.4, y, 0] for y in h])
    FN = np.array([[0, 1, 2 + i] for i in range(len(h))])
    flagged = degenerate_faces(P, FN)
    assert flagged.tolist() == [False, False, False, True, True, True, True]
    with np.errstate(divide="ignore", invalid="ignore"):  # what the low-res ARAP would have met
        C = igl.cotmatrix_entries(P[:-1], FN[:-1])
    huge = ~(np.abs(2 * C) < 1 / MIN_FACE_QUALITY)  # C holds cot / 2; NaN and inf count as huge
    assert huge.any(axis=1).tolist() == flagged[:-1].tolist()


def test_a_sampling_left_with_a_degenerate_face_is_drawn_again_with_a_derived_seed(monkeypatch):
    """The remesh of the first draw keeps a degenerate face: the second draw (seed
    derived from the seed and the attempt) is kept and the first is named in the info."""
    from sshade.arap.problems import lifted_plane
    V, F, _, _ = lifted_plane(0.2, n_target=600)
    real, seen = remesh_module.remesh, []

    def first_draw_degenerate(*a, seed, **kw):
        rm = real(*a, seed=seed, **kw)
        seen.append(seed)
        if len(seen) == 1:
            rm.n_degenerate = 1
        return rm

    monkeypatch.setattr(remesh_module, "remesh", first_draw_degenerate)
    rm, given_up = remesh_drawn(V, F, 60, seed=11)
    assert given_up == [11] and seen == [11, redraw_seed(11, 1)] and rm.n_degenerate == 0
    assert redraw_seed(11, 1) not in (11, redraw_seed(11, 2), redraw_seed(12, 1))


def test_a_sampling_that_stays_degenerate_is_refused_naming_its_seeds(monkeypatch):
    from sshade.arap.problems import lifted_plane
    V, F, _, _ = lifted_plane(0.2, n_target=600)
    real = remesh_module.remesh

    def always_degenerate(*a, **kw):
        rm = real(*a, **kw)
        rm.n_degenerate = 2
        return rm

    monkeypatch.setattr(remesh_module, "remesh", always_degenerate)
    with pytest.raises(SShaDeError, match=f"every one of {MAX_REDRAWS + 1} samplings drawn from seed 5"):
        remesh_drawn(V, F, 60, seed=5)


def _sheet_with_a_handle_sliver(q: float):
    """A bumpy 30 x 30 sheet whose triangle (a, d, c) is squashed to quality about ``q``
    (c moved towards the midpoint of a-d: a valid input face with area), and handles on
    its three corners and the sheet's corners."""
    n = 30
    xs, ys = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    V = np.c_[xs.ravel(), ys.ravel(), 0.05 * np.sin(3 * xs.ravel()) * np.cos(2 * ys.ravel())]
    F = np.array([f for i in range(n - 1) for j in range(n - 1) for f in
                  ([i * n + j, i * n + j + 1, (i + 1) * n + j + 1], [i * n + j, (i + 1) * n + j + 1, (i + 1) * n + j])])
    a, d, c = 14 * n + 14, 15 * n + 15, 15 * n + 14
    mid = 0.5 * (V[a] + V[d])
    V[c] = mid + q * (V[c] - mid)
    H = np.array([a, d, c, 0, n - 1, n * n - 1, n * (n - 1)])
    T = V[H].copy()
    T[:3, 2] += 0.1
    return V, F, H, T


@pytest.mark.parametrize("q", [1e-5, 1e-7])
def test_a_sliver_input_face_whose_corners_are_all_handles_is_kept_not_refused(q):
    """No seed added removes a low-res face made of three handles: it is neither repaired
    nor redrawn for (it has area, so finite cotangent weights joining handles only), and
    the deformation reaches its handles. (Refused as "every one of 5 samplings ... kept a
    degenerate low-res face" before.)"""
    import sshade
    from sshade.remesh_repair import fixed_faces
    V, F, H, T = _sheet_with_a_handle_sliver(q)
    rm = remesh_module.remesh(V, F, 60, seed=0, required=H)
    fixed = np.zeros(len(V), bool)
    fixed[H] = True
    deg = degenerate_faces(V[rm.seeds], rm.F)
    assert deg.any() and (deg <= fixed_faces(fixed, rm.seeds, rm.F)).all() and rm.n_degenerate == 0
    for seed in range(3):
        U, info = sshade.deform(V, F, H, T, n_low=60, n_samplings=2, seed=seed, return_info=True)
        assert np.isfinite(U).all() and np.abs(U[H] - T).max() == 0 and info["redrawn"] == 0


def _jittered_grid_sheet(nx: int, ny: int, eps: float, seed: int = 0):
    """A flat nx x ny unit-grid sheet, one diagonal per square, every vertex moved in its
    plane by ``eps`` times a seeded normal draw: a clean manifold mesh whose grid rows are
    collinear to within ``eps``. Farthest-point seeds on such a sheet often lie on one
    row, and the Dijkstra distances tie along rows, so three seeds within ``eps`` of a
    line can have regions meeting at one face: a low-res triangle whose area libigl's
    Heron formula puts at zero (a non-finite cotangent weight), with a normal that agrees
    with the surface (so not caught as flipped)."""
    x, y = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0), indexing="ij")
    V = np.c_[x.ravel(), y.ravel(), np.zeros(x.size)]
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    a = (i * (ny + 1) + j).ravel()
    b = a + ny + 1
    F = np.r_[np.c_[a, b, b + 1], np.c_[a, b + 1, a + 1]].astype(np.int64)
    V[:, :2] += eps * np.random.default_rng(seed).standard_normal((len(V), 2))
    return V, F


@pytest.mark.parametrize("nx, ny, n_low, seed", [(15, 10, 53, 1), (15, 10, 56, 0), (20, 12, 74, 0),
                                                 (16, 16, 77, 3)])
def test_a_clean_jittered_grid_sheet_deforms_where_a_degenerate_low_res_face_made_it_fail(nx, ny, n_low, seed):
    """Each of these (mesh, n_low, seed) raised "face k is degenerate (non-finite
    cotangent weight)" from the low-res ARAP before degenerate faces were repaired: the
    failure SShaDe met on a 168k-vertex FAUST-built DeFAUST subject, constructed here on
    176 to 357 vertices. Now the sampling's low-res mesh has no degenerate face, the
    corners reach their targets exactly and the low-res ARAP converges."""
    import sshade
    V, F = _jittered_grid_sheet(nx, ny, 1e-11)
    H = np.array([0, ny, len(V) - 1 - ny, len(V) - 1])
    T = V[H].copy()
    T[-1, 2] += 0.3 * nx
    U, info = sshade.deform(V, F, H, T, n_low=n_low, n_samplings=1, seed=seed, return_info=True)
    assert np.isfinite(U).all() and np.abs(U[H] - T).max() == 0 and info["status"] == "converged"
    rm, _ = remesh_drawn(V, F, n_low, seed=info["samplings"][0]["seed"], required=H)
    assert not degenerate_faces(V[rm.seeds], rm.F).any()


def test_fuzz_jittered_grid_sheets_give_no_degenerate_low_res_face():
    """60 seeded draws of a jittered sheet (10-30 squares a side, jitter 1e-13 to 1e-8,
    n_low 6-80): no sampling keeps a low-res face of quality below the bound or with a
    non-finite cotangent weight. Without the degeneracy repair 5 of these 60 kept one,
    each with a non-finite weight (3 % of 166k draws of a wider fuzz of the same sheets)."""
    rng = np.random.default_rng(2026)
    for _ in range(60):
        nx, ny = (int(k) for k in rng.integers(10, 31, 2))
        V, F = _jittered_grid_sheet(nx, ny, 10.0 ** rng.uniform(-13, -8), seed=int(rng.integers(1 << 31)))
        rm, _ = remesh_drawn(V, F, int(rng.integers(6, 81)), seed=int(rng.integers(1000)))
        P = V[rm.seeds]
        with np.errstate(divide="ignore", invalid="ignore"):
            C = igl.cotmatrix_entries(P, rm.F)
        assert np.isfinite(C).all() and not degenerate_faces(P, rm.F).any()

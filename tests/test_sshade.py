"""End-to-end properties of SShaDe and the baselines (paper §3, §4.1)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from baselines import ARAP, Elastic
from sshade import SShaDe, deform
from sshade.lrf import transfer
from sshade.mesh.io import read_mesh
from sshade.projection import project_to_fans
from sshade.remesh import remesh

from .conftest import data_file


@pytest.fixture(scope="module")
def faust():
    V, F = read_mesh(data_file("faust_reg/tr_reg_000.ply"))
    rng = np.random.default_rng(1)
    h = rng.choice(len(V), 60, replace=False)
    return V, F, h


METHODS = [lambda: SShaDe(n_low=400, n_samplings=2, workers=1), ARAP, Elastic]


@pytest.mark.parametrize("make", METHODS, ids=["SShaDe", "ARAP", "Elastic"])
def test_rigid_motion_is_reproduced(faust, make):
    V, F, h = faust
    R = Rotation.from_euler("xyz", [0.4, -0.7, 1.3]).as_matrix()
    t = np.array([0.5, -2.0, 3.0])
    Vd = make().deform(V, F, h, V[h] @ R.T + t)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.abs(Vd - (V @ R.T + t)).max() < 1e-6 * diag


@pytest.mark.parametrize("make", METHODS, ids=["SShaDe", "ARAP", "Elastic"])
def test_identity(faust, make):
    V, F, h = faust
    Vd = make().deform(V, F, h, V[h])
    assert np.abs(Vd - V).max() < 1e-10


@pytest.mark.parametrize("gradient", ["normalized", "raw"])
def test_lrf_transfer_reproduces_rigid_motion_of_low_res(gradient):
    V, F = read_mesh(data_file("tosca/cat0.off"))
    rm = remesh(V, F, 500, seed=0)
    VN = V[rm.seeds]
    P = project_to_fans(V, rm.label, VN, rm.F)
    R = Rotation.from_rotvec([0.3, 1.1, -0.2]).as_matrix()
    Vd = transfer(V, P.tri, VN, VN @ R.T + 7.0, rm.F, gradient=gradient)
    assert np.abs(Vd - (V @ R.T + 7.0)).max() < 1e-9 * np.linalg.norm(V.max(0) - V.min(0))


def test_handles_reach_targets_and_real_deformation_is_close_to_ground_truth(faust):
    """Handles taken from another FAUST pose: handles hit their targets exactly and the
    result is closer to the true pose than the rest pose is (a real deformation)."""
    V, F, h = faust
    V2, _ = read_mesh(data_file("faust_reg/tr_reg_001.ply"))
    Vd, info = deform(V, F, h, V2[h], n_low=500, n_samplings=2, workers=2, return_info=True)
    assert np.allclose(Vd[h], V2[h])
    err = np.linalg.norm(Vd - V2, axis=1).mean()
    assert err < 0.5 * np.linalg.norm(V - V2, axis=1).mean()
    assert len(info["sampling_seeds"]) == 2 and info["workers"] == 2
    assert all(s["converged"] for s in info["samplings"])
    # the handle error before the overwrite: what the transfer left, recorded apart. A
    # handle is a low-res vertex, which projects onto itself: the projection anchor
    # rebuilds it exactly; the barycenter anchor of Alg. 1 leaves a residual
    assert info["handles"] == "overwritten" and info["anchor"] == "projection" and info["handle_pre_pct"] < 1e-9
    assert all("handle_resid" not in s for s in info["samplings"])  # no arrays in the stored info
    _, info_b = deform(V, F, h, V2[h], n_low=500, n_samplings=2, workers=2, return_info=True, anchor="barycenter")
    assert 0 < info_b["handle_pre_pct"] < 5


def test_handle_error_before_overwrite_is_zero_for_a_rigid_motion(faust):
    """The transfer reproduces a rigid motion, so nothing is left for the overwrite."""
    V, F, h = faust
    R = Rotation.from_euler("xyz", [0.4, -0.7, 1.3]).as_matrix()
    _, info = deform(V, F, h, V[h] @ R.T + 1.0, n_low=400, n_samplings=2, workers=1, return_info=True)
    assert info["handle_pre_pct"] < 1e-8


def test_averaging_is_deterministic_and_parallel_matches_serial(faust):
    V, F, h = faust
    tg = V[h] + np.array([0.0, 0.05, 0.0]) * (V[h, 1:2] > 0)
    a = deform(V, F, h, tg, n_low=300, n_samplings=3, seed=5, workers=1)
    b = deform(V, F, h, tg, n_low=300, n_samplings=3, seed=5, workers=2)
    assert np.allclose(a, b, atol=1e-12)


def test_low_res_solves_in_the_main_thread_keep_the_serial_threshold(faust, monkeypatch):
    """SShaDe's samplings share the cores (one solve per sampling), so their low-res solves
    run serial below PARALLEL_MIN_CELLS even from the main thread (workers=1), while a
    full-resolution solve of that size there may take the threads."""
    import sshade.arap.solver as solver
    from sshade.arap import MAIN_MIN_CELLS, max_threads
    seen = []
    real = solver.resolve_threads
    monkeypatch.setattr(solver, "resolve_threads", lambda t, n: seen.append((n, real(t, n))) or seen[-1][1])
    V, F, h = faust
    tg = V[h] + np.array([0.0, 0.05, 0.0]) * (V[h, 1:2] > 0)
    deform(V, F, h, tg, n_low=MAIN_MIN_CELLS + 500, n_samplings=1, seed=0, workers=1)
    assert seen and all(n >= MAIN_MIN_CELLS and t == 1 for n, t in seen)
    seen.clear()
    Elastic().deform(V, F, h, tg)
    assert seen and all(t == max_threads() for n, t in seen)

"""SShaDe's low-res energy (``energy``: spokes and rims, spokes, ARAP-SR): a rigid motion
of the handles comes out exactly with each; the default is the spokes-and-rims call bit
for bit; the low-res solve is :func:`sshade.arap.arap_deform` of that energy, for ARAP-SR
the ARAP-SR solver on the low-res mesh with the baseline's alpha; an unknown energy is
refused before any work; the energy is recorded. Small synthetic meshes, no data."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sshade import SShaDe, SShaDeError, check_params, deform, prepare
from sshade.arap import (
    DEFAULT_ALPHA,
    DEFORM_ENERGIES,
    ArapOptions,
    arap_deform,
    arap_sr_deform,
    bbox_diag,
    solve_arap_sr,
)
from sshade.arap.problems import bent_cylinder, twisted_bar
from sshade.pipeline import deform_once, prepare_sampling

N_LOW = 120


@pytest.fixture(scope="module")
def bar():
    """A twisted bar (290 vertices), its handles and their targets."""
    return twisted_bar(60.0, h=0.25)


@pytest.mark.parametrize("protocol", ["converged", "paper"])
@pytest.mark.parametrize("energy", DEFORM_ENERGIES)
def test_a_rigid_motion_of_the_handles_is_reproduced_exactly(energy, protocol):
    V, F, h, _ = bent_cylinder(h=0.25)
    R = Rotation.from_euler("xyz", [30.0, -50.0, 110.0], degrees=True).as_matrix()
    t = np.array([0.3, -1.2, 2.5])
    Vd = deform(V, F, h, V[h] @ R.T + t, n_low=N_LOW, n_samplings=2, workers=1, energy=energy, protocol=protocol)
    assert np.abs(Vd - (V @ R.T + t)).max() < 1e-9 * bbox_diag(V)


def test_spokes_and_rims_is_the_default_bit_for_bit(bar):
    V, F, h, T = bar
    kw = dict(n_low=N_LOW, n_samplings=3, workers=1)
    assert np.array_equal(deform(V, F, h, T, energy="spokes_and_rims", **kw), deform(V, F, h, T, **kw))
    with prepare(V, F, h, energy="spokes_and_rims", **kw) as a, prepare(V, F, h, **kw) as b:
        assert np.array_equal(a.solve(T), b.solve(T))


def _low_res(V, F, h, T, energy, protocol):
    """One sampling of SShaDe with ``energy`` (:func:`deform_once`): its result, info, and
    the low-res mesh (the seeds, faces, the handles' low-res indices) drawn the same way."""
    Vd, info = deform_once(V, F, h, T, n_low=N_LOW, seed=3, energy=energy, protocol=protocol)
    prep, _ = prepare_sampling(V, F, h, N_LOW, 3, None)  # the remesh deform_once made
    return Vd, info, prep


@pytest.mark.parametrize("protocol", ["converged", "paper"])
def test_spokes_solves_the_low_res_mesh_as_arap_deform(bar, protocol):
    V, F, h, T = bar
    Vd, info, prep = _low_res(V, F, h, T, "spokes", protocol)
    seeds = prep["seeds"]
    res = arap_deform(V[seeds], prep["F"], prep["low_handles"], T, ArapOptions(energy="spokes", protocol=protocol))
    assert info["iterations"] == res.iterations > 0 and info["status"] == res.info["status"]
    assert info["gnorm"] == res.info["gnorm"]
    # the projection anchor rebuilds every low-res vertex at its deformed position
    np.testing.assert_allclose(Vd[seeds], res.V, rtol=0, atol=1e-12 * bbox_diag(V))


def test_arap_sr_solves_the_low_res_mesh_as_the_arap_sr_solver(bar):
    V, F, h, T = bar
    Vd, info, prep = _low_res(V, F, h, T, "arap_sr", "converged")
    seeds = prep["seeds"]
    res = solve_arap_sr(V[seeds], prep["F"], prep["low_handles"], T, ArapOptions(alpha=DEFAULT_ALPHA))
    assert res.info["alpha"] == 0.01 and res.info["alpha_scaling"] == "valence"  # the baseline's default
    assert info["iterations"] == res.iterations > 0 and info["status"] == res.info["status"] == "converged"
    assert info["energy"] == res.info["energy"] and info["gnorm"] == res.info["gnorm"]
    np.testing.assert_allclose(Vd[seeds], res.V, rtol=0, atol=1e-12 * bbox_diag(V))
    # the paper protocol: ARAP-SR's Jacobi iteration stopped by SShaDe's move rule (tol)
    Vp, info_p, _ = _low_res(V, F, h, T, "arap_sr", "paper")
    rp = arap_sr_deform(V[seeds], prep["F"], prep["low_handles"], T, ArapOptions(stop="move", tol=1e-4, max_iter=1000))
    assert info_p["iterations"] == rp.iterations and info_p["energy"] == rp.info["energy"]
    np.testing.assert_allclose(Vp[seeds], rp.V, rtol=0, atol=1e-12 * bbox_diag(V))


def test_arap_sr_prepared_first_solve_is_deform_and_later_ones_converge(bar):
    V, F, h, T = bar
    kw = dict(n_low=N_LOW, n_samplings=2, seed=1, energy="arap_sr")
    with prepare(V, F, h, **kw) as p:
        Vd = p.solve(T)
        assert np.array_equal(Vd, deform(V, F, h, T, workers=1, **kw))
        _, info = p.solve(T * 1.01, return_info=True)
        assert info["converged"] and info["solve"] == 1


@pytest.mark.parametrize("energy", ["elements", "SPOKES", None, 3])
def test_an_unknown_energy_is_refused_before_any_work(energy):
    message = r"^SShaDe: unknown low-res energy .*; use one of \('spokes', 'spokes_and_rims', 'arap_sr'\)$"
    with pytest.raises(SShaDeError, match=message):
        check_params(energy=energy)
    with pytest.raises(SShaDeError, match=message):
        SShaDe(energy=energy)
    for run in (deform, lambda *a, **k: prepare(*a[:3], **k)):  # no mesh is read: None is never looked at
        with pytest.raises(SShaDeError, match=message):
            run(None, None, None, None, energy=energy)


def test_the_energy_is_recorded(bar):
    assert SShaDe().effective_params()["energy"] == "spokes_and_rims"
    m = SShaDe(energy="arap_sr", n_low=N_LOW, n_samplings=1, workers=1)
    assert m.effective_params()["energy"] == "arap_sr" and m.params.replace(seed=2).energy == "arap_sr"
    V, F, h, T = bar
    m.deform(V, F, h, T)
    assert m.info["low_res_energy"] == "arap_sr" and m.info["converged"]

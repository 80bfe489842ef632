"""The coarse start of the converged protocol (baselines/coarse_start.py; for ARAP-SR,
ARAP and Elastic) and the start rotations ``R0`` of :func:`sshade.arap.solve_arap` it
feeds."""
from __future__ import annotations

import numpy as np
import pytest

from baselines import ARAP, ARAPSR, Elastic
from baselines.coarse_start import COARSE_MIN_RATIO, check_start, coarse_start, start_rotations, uses_coarse
from sshade.arap import DEEP_CRITERION, ArapOptions, arap_deform, build_operators, solve_arap
from sshade.arap.problems import bent_cylinder, lifted_plane
from sshade.errors import SShaDeError

ENERGIES = ("spokes", "spokes_and_rims")


def _mean_dist(A, B, V):
    return float(np.linalg.norm(A - B, axis=1).mean() / np.linalg.norm(V.max(0) - V.min(0)))


def test_r0_start_is_the_global_step_of_r0():
    """With ``R0`` the first iterate minimises ``E(U, R0)`` over the free vertices: its
    gradient with ``R0`` held vanishes there; ``U0`` and ``R0`` together are refused."""
    V, F, h, T = lifted_plane(n_target=600)
    ops = build_operators(V, F, "spokes")
    R0 = np.broadcast_to(np.eye(3), (len(V), 3, 3)).copy()
    res = solve_arap(V, F, h, T, ArapOptions(energy="spokes", max_iter=0), R0=R0, operators=ops)
    U = res.V
    free = np.setdiff1d(np.arange(len(V)), h)
    g = ops.gradient(U, R0)[free]
    assert np.abs(g).max() < 1e-9 * np.abs(ops.rhs(R0)).max()
    assert np.allclose(U[h], T) and res.info["energy"] == pytest.approx(ops.energy(U), rel=1e-9)
    with pytest.raises(SShaDeError, match="not both"):
        solve_arap(V, F, h, T, ArapOptions(energy="spokes"), R0=R0, U0=V)
    with pytest.raises(SShaDeError, match="R0"):
        solve_arap(V, F, h, T, ArapOptions(energy="spokes"), R0=R0[:-1])
    with pytest.raises(SShaDeError, match="converged"):
        arap_deform(V, F, h, T, ArapOptions(energy="spokes", protocol="paper"), R0=R0)


@pytest.mark.parametrize("energy", ENERGIES)
def test_coarse_start_same_minimiser(energy):
    """The coarse start (the rotations of a low-res solve of the same energy) reaches the
    criterion with a never-increasing energy, and ends at the rigid start's minimiser on
    the lifted plane (a case with one minimum in reach)."""
    V, F, h, T = lifted_plane(n_target=2500)
    ops = build_operators(V, F, energy)
    deep = solve_arap(V, F, h, T, ArapOptions(energy=energy, criterion=DEEP_CRITERION, max_iter=20000), operators=ops)
    R0, info = coarse_start(V, F, h, T, energy=energy, n_low=300)
    assert R0.shape == (len(V), 3, 3) and info["coarse_status"] == "converged" and info["coarse_n"] >= 300
    assert np.allclose(np.einsum("kab,kcb->kac", R0, R0), np.eye(3), atol=1e-9)
    res = solve_arap(V, F, h, T, ArapOptions(energy=energy), R0=R0, operators=ops)
    rigid = solve_arap(V, F, h, T, ArapOptions(energy=energy), operators=ops)
    assert res.info["status"] == "converged" and np.allclose(res.V[h], T)
    E = np.array(res.info["energy_history"])
    assert (np.diff(E) <= 1e-12 * np.abs(E[1:])).all(), "the energy increased"
    assert _mean_dist(res.V, deep.V, V) < 5e-4 and _mean_dist(res.V, rigid.V, V) < 5e-4
    assert abs(res.info["energy"] - rigid.info["energy"]) < 1e-4 * abs(deep.info["energy"])


@pytest.mark.parametrize("cls", [ARAP, Elastic])
def test_fullres_start_option(cls):
    V, F, h, T = bent_cylinder(h=0.16)
    m = cls(start="coarse", coarse_n_low=100)
    U = m.deform(V, F, h, T)
    assert m.info["converged"] and m.info["coarse_n"] >= 100 and np.allclose(U[h], T)
    r = cls(start="rigid")
    Ur = r.deform(V, F, h, T)
    assert r.info["converged"] and "coarse_n" not in r.info
    assert m.info["energy"] <= r.info["energy"] * (1 + 1e-6) or _mean_dist(U, Ur, V) < 5e-4
    assert cls().start == "rigid" and cls(protocol="paper").start == "rigid"  # the default
    a = cls(start="auto")  # auto: a mesh below COARSE_MIN_RATIO x coarse_n_low starts rigid
    assert np.array_equal(a.deform(V, F, h, T), Ur) and "coarse_n" not in a.info
    a = cls(start="auto", coarse_n_low=len(V) // COARSE_MIN_RATIO)  # ... and at least that starts coarse
    a.deform(V, F, h, T)
    assert "coarse_n" in a.info
    p = cls(protocol="paper", start="coarse", max_iter=3)  # the paper protocol has no start
    p.deform(V, F, h, T)
    assert "coarse_n" not in p.info and p.info["iterations"] == 3


@pytest.mark.parametrize("cls", [ARAP, Elastic, ARAPSR])
@pytest.mark.parametrize("bad", [{"start": "fine"}, {"start": None}, {"coarse_n_low": 2}, {"coarse_n_low": 1.5},
                                 {"coarse_n_low": True}, {"coarse_n_low": "6000"}])
def test_start_options_refused(cls, bad):
    with pytest.raises(SShaDeError, match="start|coarse_n_low"):
        cls(**bad)


def test_auto_rule():
    """``auto`` is coarse from COARSE_MIN_RATIO x coarse_n_low vertices: FAUST (6,890)
    starts rigid, DeFAUST (168,897) coarse with the default 6000."""
    assert check_start("ARAP", "auto", 6000) == ("auto", 6000)
    assert not uses_coarse("auto", 6890, 6000) and uses_coarse("auto", 168_897, 6000)
    assert uses_coarse("coarse", 10, 6000) and not uses_coarse("rigid", 10**6, 4)
    V, F, h, T = bent_cylinder(h=0.16)
    assert start_rotations("auto", V, F, h, T, energy="spokes", coarse_n_low=6000) == (None, {})
    with pytest.raises(SShaDeError, match="energy"):
        coarse_start(V, F, h, T, energy="elements", n_low=100)


def test_the_coarse_start_size_is_written_once_and_the_method_configs_follow_it():
    """COARSE_N_LOW is the default of every signature that takes a coarse size, the config
    states the same number once (``arap.coarse_n_low``: a YAML cannot import it), and the
    ARAP, Elastic and ARAP-SR files take theirs from it."""
    import inspect
    from pathlib import Path

    import yaml

    from baselines.coarse_start import COARSE_N_LOW
    from baselines.fullres_arap import FullResArap

    conf = Path(__file__).resolve().parents[1] / "conf"
    assert yaml.safe_load((conf / "config.yaml").read_text())["arap"]["coarse_n_low"] == COARSE_N_LOW
    for name in ("ARAP", "Elastic", "ARAP-SR"):
        text = (conf / "method" / f"{name}.yaml").read_text()
        assert yaml.safe_load(text)["coarse_n_low"] == "${arap.coarse_n_low}", name
    numbers = [line for p in conf.rglob("*.yaml") for line in p.read_text().splitlines()
               if line.split("#")[0].strip().startswith("coarse_n_low:") and "${" not in line]
    assert len(numbers) == 1, numbers
    classes = (ARAPSR, ARAP, Elastic, FullResArap)
    signatures = [(coarse_start, "n_low"), *((c.__init__, "coarse_n_low") for c in classes)]
    for f, p in signatures:
        assert inspect.signature(f).parameters[p].default == COARSE_N_LOW, f

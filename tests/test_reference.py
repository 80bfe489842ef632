"""Reference solutions (eval/metrics/reference.py), the two ARAP protocols, SShaDe + refine and
the time-to-accuracy experiment (eval/experiments/convergence.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from eval.config_check import check_config
from eval.metrics.reference import reference_solution
from eval.metrics.reference_scores import method_energy, reference_metrics
from sshade.arap import ArapOptions, arap_deform
from sshade.arap.problems import bent_cylinder, lifted_plane
from sshade.errors import SShaDeError


@pytest.fixture(scope="module")
def plane():
    return lifted_plane(0.2, n_target=2000)


def test_reference_is_cached_and_reused(plane, tmp_path):
    V, F, h, T = plane
    r1 = reference_solution(V, F, h, T, cache_dir=tmp_path)
    assert not r1.info["cached"] and r1.path.is_file() and r1.path.parent == tmp_path
    r2 = reference_solution(V, F, h, T, cache_dir=tmp_path)
    assert r2.info["cached"] and r2.key == r1.key
    np.testing.assert_array_equal(r2.U, r1.U)
    assert r2.energy == r1.energy > 0
    # another energy or other targets: another entry
    r3 = reference_solution(V, F, h, T, energy="spokes", cache_dir=tmp_path)
    T2 = T.copy()
    T2[-1, 2] += 1e-3
    r4 = reference_solution(V, F, h, T2, cache_dir=tmp_path)
    assert len({r1.path, r3.path, r4.path}) == 3 and not r4.info["cached"]
    with pytest.raises(SShaDeError, match="unknown ARAP energy"):
        reference_solution(V, F, h, T, energy="elastic", cache_dir=tmp_path)


def _entry_mutations(d: dict) -> dict:
    """Damaged or edited versions of a cache entry's arrays ``d`` (what -> arrays)."""
    shifted = dict(d, U=d["U"] + 0.01)  # the case: the solution moved, key intact
    return {
        "info is not JSON": dict(d, info=np.array("{not json")),
        "solution shifted": shifted,
        "energy edited": dict(d, energy=np.float64(float(d["energy"]) * 0.5)),
        "solution has a NaN": dict(d, U=np.where(np.arange(len(d["U"]))[:, None] == 3, np.nan, d["U"])),
        "no content digest": {k: v for k, v in d.items() if k != "content"},
        "an array of another case": dict(d, U=d["U"][:-1]),
    }


def test_a_damaged_or_edited_cache_entry_is_recomputed_with_one_warning(plane, tmp_path, caplog):
    """Each damaged entry (not JSON, solution shifted with its key intact, energy edited,
    NaN, no digest, wrong shape, truncated, a link to a whole entry elsewhere) is computed
    again with one warning naming the file and why, and gives the reference itself."""
    from defaust.store import read_npz, write_npz
    V, F, h, T = plane
    good = reference_solution(V, F, h, T, cache_dir=tmp_path / "c")
    whole, good_bytes = read_npz(good.path), good.path.read_bytes()
    cases = _entry_mutations(whole)
    cases["truncated"] = good.path.read_bytes()[:500]
    for what, content in [*cases.items(), ("a link", "link")]:
        cache = tmp_path / what.replace(" ", "_")
        cache.mkdir()
        p = cache / good.path.name
        if content == "link":
            p.symlink_to(good.path)
        elif isinstance(content, bytes):
            p.write_bytes(content)
        else:
            write_npz(p, content)
        caplog.clear()
        with caplog.at_level("WARNING", logger="eval"):
            ref = reference_solution(V, F, h, T, cache_dir=cache)
        warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
        assert len(warned) == 1 and str(p) in warned[0] and "computing it again" in warned[0], (what, warned)
        assert not ref.info["cached"], what
        np.testing.assert_array_equal(ref.U, good.U, err_msg=what)
        assert ref.energy == good.energy and not p.is_symlink(), what
        again = reference_solution(V, F, h, T, cache_dir=cache)  # the entry written anew is whole
        assert again.info["cached"], what
    assert good.path.read_bytes() == good_bytes  # the link's target was never written


def test_a_cache_entry_that_inflates_beyond_its_case_is_refused_before_it_is_read(plane, tmp_path, caplog):
    """A compressed entry of 300 KB with an extra array that inflates to 300 MB, or a
    solution declared larger than its case's: refused from the zip directory (one
    warning, computed again) with a traced peak far below what the arrays would take."""
    import tracemalloc
    import zipfile

    from defaust.store import read_npz
    V, F, h, T = plane
    good = reference_solution(V, F, h, T, cache_dir=tmp_path / "c")
    whole = read_npz(good.path)
    for what, arrays in [("an extra array", dict(whole, bomb=np.zeros(300 * 2**20 // 8))),
                         ("a solution too large", dict(whole, U=np.zeros((len(whole["U"]) * 1000, 3))))]:
        cache = tmp_path / what.replace(" ", "_")
        cache.mkdir()
        np.savez_compressed(cache / good.path.name, **arrays)
        assert (cache / good.path.name).stat().st_size < 2**20 and zipfile.is_zipfile(cache / good.path.name)
        caplog.clear()
        tracemalloc.start()
        try:
            with caplog.at_level("WARNING", logger="eval"):
                ref = reference_solution(V, F, h, T, cache_dir=cache)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 100 * 2**20, (what, peak)
        assert not ref.info["cached"] and ref.energy == good.energy, what
        assert sum(r.levelname == "WARNING" for r in caplog.records) == 1, what


def test_reference_metrics(plane, tmp_path):
    V, F, h, T = plane
    ref = reference_solution(V, F, h, T, cache_dir=tmp_path)
    m = reference_metrics(V, ref.U, F, ref)
    assert m["ref_mean_pct"] == 0 and m["ref_max_pct"] == 0 and abs(m["energy_gap"]) < 1e-12
    paper = arap_deform(V, F, h, T, ArapOptions(protocol="paper", max_iter=20))  # far from the minimiser
    mp = reference_metrics(V, paper.V, F, ref)
    assert mp["ref_mean_pct"] > 0.01 and mp["energy_gap"] > 1e-3
    assert method_energy(type("M", (), {"name": "ARAP"})) == "spokes"
    assert method_energy(type("M", (), {"name": "Mine"})) == "spokes_and_rims"


def test_converged_protocol_reaches_the_minimiser_where_the_paper_rule_stops_short(tmp_path):
    """The paper's move rule fires long before the minimiser on a low-frequency bend; the
    converged protocol's result is within its guarantee (0.05 % mean, 0.5 % max)."""
    V, F, h, T = bent_cylinder(90.0, h=0.12)
    ref = reference_solution(V, F, h, T, cache_dir=tmp_path)
    conv = arap_deform(V, F, h, T, ArapOptions(protocol="converged"))
    paper = arap_deform(V, F, h, T, ArapOptions(protocol="paper"))
    assert conv.converged and conv.info["status"] == "converged" and conv.info["protocol"] == "converged"
    mc, mp = reference_metrics(V, conv.V, F, ref), reference_metrics(V, paper.V, F, ref)
    assert mc["ref_mean_pct"] < 0.05 and mc["ref_max_pct"] < 0.5
    assert mp["ref_mean_pct"] > 5 * mc["ref_mean_pct"]
    assert paper.info["protocol"] == "paper"
    with pytest.raises(SShaDeError, match="unknown ARAP protocol"):
        arap_deform(V, F, h, T, ArapOptions(protocol="fast"))


def test_methods_follow_the_protocol():
    from eval.method_config import make_methods
    cfg = {"methods": ["ARAP", "Elastic", "SShaDe", "SShaDe+refine"], "arap": {"protocol": "paper"}}
    ms = make_methods(check_config(cfg).methods)
    assert [m.protocol for m in ms[:2]] == ["paper", "paper"] and ms[2].params["protocol"] == "paper"
    with pytest.raises(SShaDeError, match="arap.protocol"):
        make_methods(check_config({"methods": ["ARAP"], "arap": {"protocol": "fast"}}).methods)
    with pytest.raises(SShaDeError, match="arap.gtol"):
        make_methods(check_config({"methods": ["ARAP"], "arap": {"gtol": -1}}).methods)


def test_sshade_refine_saves_iterations(plane):
    from baselines import Elastic
    from sshade.refine import SShaDeRefine
    V, F, h, T = plane
    el = Elastic()
    Ve = el.deform(V, F, h, T)
    m = SShaDeRefine(n_low=300, n_samplings=2, workers=1)
    Vr = m.deform(V, F, h, T)
    assert m.info["converged"] and el.info["converged"]
    assert m.info["refine_iterations"] < el.info["iterations"]
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.abs(Vr - Ve).max() < 5e-3 * diag  # both within the criterion of one minimiser


def test_convergence_experiment_writes_table_and_figure(tmp_path):
    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR, run_experiment
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=[
            "experiment=convergence", "convergence.cases=[plane]", "convergence.plane.n_target=2000",
            "convergence.time_budget_s=10", "sshade.n_low=300", "sshade.workers=1",
            f"out_dir={tmp_path / 'out'}", f"reference.cache={tmp_path / 'refs'}"])
    res = run_experiment(cfg)
    t = res["table"]
    assert list(t["solver"]) == ["libigl local/global", "L-BFGS (ours)", "Anderson (ours)", "SShaDe k=1",
                                 "SShaDe k=5", "SShaDe + refine"]
    for solver in ("L-BFGS (ours)", "Anderson (ours)"):
        row = t.set_index("solver").loc[solver]
        assert row["stopped"] == "converged" and row["ref_mean_pct"] < 0.05
    assert (tmp_path / "out" / "convergence.png").stat().st_size > 10000
    assert "| plane_2k |" in (tmp_path / "out" / "table.md").read_text()
    assert json.loads((tmp_path / "out" / "run.json").read_text())["status"] == "done"


def test_arap_sr_reference_continues_the_methods_path(plane, tmp_path):
    """ARAP-SR's deep reference continued from its converged result and rotations equals
    the one from the rigid start (same minimiser, same energy); the result is within
    0.05% of the diagonal of it, and its energy gap read at the method's own rotations
    is tiny, an upper bound of the gap at the optimal rotations."""
    from baselines.arap_sr import ARAPSR
    from eval.metrics.reference_scores import sr_energy

    V, F, h, T = plane
    m = ARAPSR(alpha=0.01)
    Vd = m.deform(V, F, h, T)
    assert m.rotations is not None and m.rotations.shape == (len(V), 3, 3)
    e = sr_energy(0.01)
    cont = reference_solution(V, F, h, T, energy=e, cache_dir=tmp_path / "a", U0=Vd, R0=m.rotations)
    rigid = reference_solution(V, F, h, T, energy=e, cache_dir=tmp_path / "b")
    assert cont.key == rigid.key  # the start is not part of the key
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.linalg.norm(cont.U - rigid.U, axis=1).max() < 1e-6 * diag
    assert abs(cont.energy - rigid.energy) <= 1e-9 * abs(rigid.energy)
    own = reference_metrics(V, Vd, F, cont, R0=m.rotations)
    arap = reference_metrics(V, Vd, F, cont)
    assert own["ref_mean_pct"] < 0.05
    # on this small mesh ARAP's rotations + 2,000 sweeps reach min_R E: the method's
    # rotations + 20 sweeps give an upper bound of it, and a tiny one
    assert -1e-12 <= arap["energy_gap"] <= own["energy_gap"] + 1e-15 and own["energy_gap"] < 1e-6


def test_reference_key_changes_with_the_solver_code(monkeypatch):
    """A cached reference computed by other solver code (the import closure of
    eval.metrics.reference: its solvers, energies and operators) or other numerical
    libraries is not reused: both are part of its key."""
    import eval.run.reference_cache as cache
    from eval.run.code_identity import artifact_identity

    V = np.eye(3)
    F = np.array([[0, 1, 2]])
    args = (V, F, np.array([0]), V[:1], "spokes_and_rims", {"etol": 1e-12})
    k0 = cache.reference_key(*args)
    solvers = artifact_identity()["modules"]
    assert {"eval.metrics.reference", "sshade.arap.solver", "sshade.arap.smooth_rotations",
            "baselines.coarse_start"} <= set(solvers)
    assert not {"baselines.implicit_arap.method", "sshade.pipeline"} & set(solvers)  # not another method's code
    monkeypatch.setattr(cache, "artifact_identity", lambda: {"sources": "edited"})
    k1 = cache.reference_key(*args)
    monkeypatch.setattr(cache, "numerical_versions", lambda: {"numpy": "0"})
    assert len({k0, k1, cache.reference_key(*args)}) == 3


def _strip(nx: int = 41, ny: int = 11, compress: float = 0.1):
    """A flat 4 x 1 strip in z = 0 whose two end columns are handles, the right one moved
    ``compress`` of the length towards the left: ``(V, F, handles, targets)``."""
    x, y = np.meshgrid(np.linspace(0.0, 4.0, nx), np.linspace(0.0, 1.0, ny), indexing="ij")
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(nx * ny)])
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])]).astype(np.int64)
    h = np.concatenate([idx[0], idx[-1]]).astype(np.int64)
    T = V[h].copy()
    T[ny:, 0] -= compress * 4.0
    return V, F, h, T


def test_a_reference_continued_from_a_saddle_leaves_it_for_the_lower_basin_its_probe_finds(tmp_path):
    """A compressed flat strip: by the z -> -z symmetry the solver stays in the plane and
    stops there, first-order converged, at a saddle (the strip buckles out of the plane
    at a lower energy). The deep solve continued from it stays at the saddle; the
    second-order probe finds the lower basin and the reference is the buckled minimiser,
    whose own probe comes back no lower."""
    V, F, h, T = _strip()
    flat = arap_deform(V, F, h, T, ArapOptions(energy="spokes_and_rims"))
    assert flat.converged and np.abs(flat.V[:, 2]).max() < 1e-12
    ref = reference_solution(V, F, h, T, cache_dir=tmp_path, U0=flat.V)
    E_flat = flat.info["energy"]
    rounds = ref.info["probe"]["rounds"]
    assert rounds[0]["lower"] and rounds[0]["energy"] <= E_flat  # the deep solve stayed at the saddle
    assert ref.info["probe"]["verified"] and not rounds[-1]["lower"]
    assert ref.energy < 0.5 * E_flat and np.abs(ref.U[:, 2]).max() > 0.1  # buckled out of the plane
    np.testing.assert_array_equal(ref.U[h], T)


def test_the_probe_leaves_a_deep_minimiser_bit_for_bit_the_same(plane, tmp_path):
    """On the lifted plane (a minimum) one probe round comes back no lower and the
    reference is the deep solve's own output, bit for bit."""
    from eval.metrics import reference as mod

    V, F, h, T = plane
    ref = reference_solution(V, F, h, T, cache_dir=tmp_path)
    probe = ref.info["probe"]
    assert probe["verified"] and len(probe["rounds"]) == 1 and probe["deep_iterations"] == 0
    assert probe["rounds"][0]["probe_energy"] >= ref.energy * (1 - mod.PROBE_RTOL)
    solver = mod._solver_settings(50000, 3600.0, "spokes_and_rims")
    U, E, _ = mod._deep_solve(V, F, h, T, "spokes_and_rims", solver, None)
    np.testing.assert_array_equal(ref.U, U)
    assert ref.energy == E

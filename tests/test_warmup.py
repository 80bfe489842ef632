"""Honest timings (sshade/warmup.py): numba's compilation happens in each method's
warmup(), never inside a timed deform call; the evaluator and the scaling benchmark
report it apart as compile_s."""
from __future__ import annotations

import importlib
import json
import time

import numpy as np
import pandas as pd
import pytest

from eval.config_check import check_config
from sshade.mesh.validate import validate_handles, validate_mesh
from sshade.warmup import tiny_problem, uses_parallel_kernels

_KERNEL_MODULES = ["sshade.mesh.geodesic", "sshade.remesh", "sshade.mesh.halfedge", "sshade.mesh.validate",
                   "sshade.projection", "sshade.arap.kernels", "sshade.arap.solver_kernels", "sshade.arap.sr_local",
                   "sshade.arap.smooth_rotations", "sshade.lrf"]


def _specialisations() -> dict[str, int]:
    """Compiled (or cache-loaded) signatures of every numba kernel of the package."""
    import numba
    out = {}
    for name in _KERNEL_MODULES:
        mod = importlib.import_module(name)
        for k, v in vars(mod).items():
            if isinstance(v, numba.core.dispatcher.Dispatcher):
                out[f"{name}.{k}"] = len(v.signatures)
    return out


def _methods():
    from baselines import ARAP, ARAPSR, Elastic
    from sshade import SShaDe
    from sshade.refine import SShaDeRefine
    return [SShaDe(n_low=300, n_samplings=2, workers=1), SShaDeRefine(n_low=300, n_samplings=2, workers=1),
            ARAP(), Elastic(), ARAP(protocol="paper"), ARAPSR(max_iter=20)]


@pytest.fixture(scope="module")
def sphere():
    """A 2,562-vertex icosphere deformed by 12 handles: larger than the warm-up's mesh."""
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=4)
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    h = np.argsort(V[:, 2])
    handles = np.concatenate([h[:6], h[-6:]])
    T = V[handles].copy()
    T[6:] += [0.3, 0.0, 0.2]
    return V, F, handles, T


def test_tiny_problem_is_a_valid_deformation():
    V, F, h, T = tiny_problem()
    V2, F2 = validate_mesh(V, F)
    h2, T2 = validate_handles(V2, h, T)
    assert len(V2) == 162 and len(h2) == 6 and np.abs(T2 - V2[h2]).max() > 0.1
    V[:] = 0  # copies: the next call is unchanged
    assert np.abs(tiny_problem()[0]).max() == pytest.approx(1.0)
    from sshade.arap import MAIN_MIN_CELLS, max_threads
    assert not uses_parallel_kernels(None) and not uses_parallel_kernels(MAIN_MIN_CELLS - 1)
    assert uses_parallel_kernels(6890) == (max_threads() > 1)  # this (main) thread's threshold


@pytest.mark.parametrize("i", range(6))
def test_after_warmup_a_deform_compiles_nothing(i, sphere):
    """The property the timings rest on: once ``warmup(n)`` ran, ``deform`` on a bigger
    mesh adds no numba specialisation (no compilation, no cache load), and a second
    ``warmup`` costs nothing."""
    m = _methods()[i]
    V, F, h, T = sphere
    s = m.warmup(len(V))
    assert s >= 0.0 and m.warmup(len(V)) == 0.0
    before = _specialisations()
    Vd = m.deform(V, F, h, T)
    after = _specialisations()
    assert {k: after[k] - before.get(k, 0) for k in after if after[k] != before.get(k, 0)} == {}, m.name
    assert np.abs(Vd[h] - T).max() < 1e-6 * np.ptp(V)


def test_deform_reports_compile_time_outside_total(monkeypatch, sphere):
    """sshade.deform: the kernel compilation it still does itself is compile_s, not total_s."""
    sd = importlib.import_module("sshade.pipeline")
    V, F, h, T = sphere
    sd.warm_kernels()

    def slow_warmup(large=True):  # a cold cache, simulated
        time.sleep(0.5)
        return 0.5
    monkeypatch.setattr(sd, "warm_kernels", slow_warmup)
    t0 = time.perf_counter()
    _, info = sd.deform(V, F, h, T, n_low=200, n_samplings=1, workers=1, return_info=True)
    wall = time.perf_counter() - t0
    assert info["compile_s"] == 0.5 and wall >= 0.5
    assert info["total_s"] <= wall - 0.5 + 1e-3


def test_evaluator_keeps_compilation_out_of_time_s(tmp_path, faust_root, monkeypatch):
    """eval.app.run calls warmup() before the first timed call of each method, once; its
    seconds and any compile_s the method reports go to compile_s (row and run.json),
    never to time_s."""
    root = faust_root
    from hydra import compose, initialize_config_dir

    import eval.method_config as em
    from eval.app import CONF_DIR, run

    class Slow:
        name = "Slow"

        def __init__(self):
            self.info, self.warm_calls = {}, []

        def warmup(self, n_vertices=None):
            self.warm_calls.append(n_vertices)
            if len(self.warm_calls) > 1:
                return 0.0
            time.sleep(0.4)
            return 0.4

        def deform(self, V, F, handles, targets):
            time.sleep(0.25)  # 0.2 s of it is a late compilation the method reports
            self.info = {"compile_s": 0.2}
            Vd = V.copy()
            Vd[handles] = targets
            return Vd

    m = Slow()
    monkeypatch.setattr(em, "make_methods", lambda cfg: [m])
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=["dataset=faust", f"dataset.root={root}", "dataset.limit=2",
                                                       "reference.cases=none", f"out_dir={tmp_path}"])
    run(check_config(cfg))
    assert m.warm_calls == [6890, 6890]
    rows = pd.read_csv(tmp_path / "cases.csv")
    assert list(rows["compile_s"].round(1)) == [0.6, 0.2]
    assert (rows["time_s"] < 0.15).all() and (rows["time_s"] >= 0.04).all()
    assert "info_compile_s" not in rows.columns
    assert json.loads((tmp_path / "run.json").read_text())["compile_s"]["Slow"] == pytest.approx(0.8, abs=0.05)


@pytest.mark.slow
def test_scaling_keeps_compilation_out_of_its_timings(tmp_path, shared_data, monkeypatch):
    """eval.experiments.scaling.scaling_experiment: warm-ups before SShaDe and Elastic, reported as *_compile_s."""
    base = shared_data / "classic" / "armadillo.obj"
    if not base.is_file():
        pytest.skip(f"{base} not found")
    from hydra import compose, initialize_config_dir

    import eval.experiments.scaling.scaling_experiment as sc
    from eval.app import CONF_DIR
    from eval.experiments.scaling.scaling_experiment import run_scaling
    real_s, real_f = sc.warm_sshade, sc.warm_fullres  # sshade.pipeline's and sshade.warmup's, as scaling calls them

    def slow(real):
        def f(*a, **k):
            real(*a, **k)
            time.sleep(0.5)
            return 0.5
        return f
    monkeypatch.setattr(sc, "warm_sshade", slow(real_s))
    monkeypatch.setattr(sc, "warm_fullres", slow(real_f))
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=[
            "experiment=scaling", "scaling.meshes=null", f"scaling.base_mesh={base}", "scaling.sizes=[3000]",
            "sshade.n_low=300", "sshade.n_samplings=2", "sshade.workers=1", "scaling.elastic_budget_s=30",
            "scaling.first_call=false", f"scaling.cache={tmp_path}/c", f"out_dir={tmp_path}/out"])
    res = run_scaling(check_config(cfg))
    row = res["table"].iloc[0]
    assert row["sshade_compile_s"] == pytest.approx(0.5) and row["elastic_compile_s"] == pytest.approx(0.5)
    assert row["sshade_total_s"] < 0.5 and row["elastic_precompute_s"] + row["elastic_s_per_iter"] < 0.5

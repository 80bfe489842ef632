"""The evaluator's cost model (eval/run/progress.py): priors from the method files, measured runs."""
from __future__ import annotations

from types import SimpleNamespace

import pytest

from eval.run.progress import CostModel, default_cost_model
from harness.method_registry import method_meta


def test_cost_model_weights_by_method():
    m = CostModel({"ARAP": "vertices", "SShaDe": "const"}, prior_s_per_vertex=1e-3, prior_const_s=20)
    assert CostModel.scale_of(SimpleNamespace(name="SShaDe")) == "const"
    assert CostModel.scale_of(SimpleNamespace(name="Elastic")) == "vertices"
    assert CostModel.scale_of(SimpleNamespace(name="X", cost_scale="const")) == "const"
    # 4 baseline cases + 40 SShaDe cases at 150k: the baselines dominate from the start
    total = 4 * m.estimate("ARAP", 150_000) + 40 * m.estimate("SShaDe", 150_000)
    assert total == pytest.approx(4 * 150 + 40 * 20)
    m.observe("SShaDe", 150_000, 10.0)
    m.observe("SShaDe", 170_000, 30.0)
    assert m.estimate("SShaDe", 10) == 20.0  # constant: the mean of the measured runs
    m.observe("ARAP", 100_000, 200.0)
    assert m.estimate("ARAP", 150_000) == pytest.approx(300.0)  # per vertex
    m.observe("ARAP", 100_000, float("nan"))  # ignored
    assert m.estimate("ARAP", 150_000) == pytest.approx(300.0)


def test_paper_protocol_has_its_own_prior():
    """ARAP-SR under the paper protocol (its plain iteration to its energy stop) is planned
    at its own measured prior, linear in the vertices, not at the converged solve's (slower
    at DeFAUST's 169k; benchmarks/records/machine_speed.md, "The ARAP-SR paper prior")."""
    conv = default_cost_model([SimpleNamespace(name="ARAP-SR", protocol="converged")])
    paper = default_cost_model([SimpleNamespace(name="ARAP-SR", protocol="paper")])
    assert paper.estimate("ARAP-SR", 169_000) > 1.3 * conv.estimate("ARAP-SR", 169_000)  # both with ~2.5 s overhead
    grow = paper.estimate("ARAP-SR", 338_000) - paper.estimate("ARAP-SR", 169_000)
    assert grow == pytest.approx(169_000 * method_meta("ARAP-SR")["cost"]["paper"], rel=0.1)
    assert paper.priors["ARAP-SR"] == method_meta("ARAP-SR")["cost"]["paper"]
    assert conv.priors["ARAP-SR"] == method_meta("ARAP-SR")["cost"]["prior"]


def test_implicit_arap_cpu_preset_prior_is_constant():
    """Implicit-ARAP's cost does not grow with the mesh: its cpu preset is planned at a
    measured constant, any other preset (paper: hours on a CPU) at the generic guess."""
    cpu = default_cost_model([SimpleNamespace(name="Implicit-ARAP", preset="cpu", )])
    assert cpu.basis("Implicit-ARAP") == "prior"
    assert cpu.estimate("Implicit-ARAP", 169_000) - cpu.estimate("Implicit-ARAP", 6_890) < 5  # only the overhead grows
    assert cpu.estimate("Implicit-ARAP", 6_890) == pytest.approx(method_meta("Implicit-ARAP")["cost"]["prior"], abs=1.0)
    paper = default_cost_model([SimpleNamespace(name="Implicit-ARAP", preset="paper", )])
    assert paper.basis("Implicit-ARAP") == "guess"


#: Mean time_s of each method, one run at a time, on FAUST's 8 cases of 6890 vertices, in the
#: probe's reference seconds (measured / the run's factor x1.079;
#: benchmarks/records/machine_speed.md, "The solvers' probe").
SMALL_VERTICES, SMALL_MEAN_S = 6890, {"ARAP": 0.406, "Elastic": 0.368, "ARAP-SR": 2.307, "SShaDe": 0.245}


def test_the_priors_hold_at_their_size_and_their_exponent_carries_them_to_small_meshes():
    """At PRIOR_VERTICES each estimate is its file's prior (plus the overhead); at FAUST's 6890
    vertices, where the prior without its exponent would plan ARAP 5x and SShaDe 13x what they took, the
    exponent brings each method's estimate within 25 % of its measured mean; a run that
    is measured replaces the prior at any size, scaled by the same exponent."""
    from eval.run.progress import OVERHEAD_S_PER_VERTEX, PRIOR_VERTICES
    cm = default_cost_model([SimpleNamespace(name=n) for n in SMALL_MEAN_S])
    for name, measured in SMALL_MEAN_S.items():
        cost = method_meta(name)["cost"]
        at_prior = cost["prior"] * (PRIOR_VERTICES if cost["scale"] == "vertices" else 1)
        assert cm.estimate(name, PRIOR_VERTICES) == pytest.approx(at_prior + OVERHEAD_S_PER_VERTEX * PRIOR_VERTICES)
        small = cm.estimate(name, SMALL_VERTICES) - OVERHEAD_S_PER_VERTEX * SMALL_VERTICES
        assert abs(small / measured - 1) < 0.25, (name, small, measured)
    cm.observe("ARAP", SMALL_VERTICES, 0.5)
    p = cm.exponents["ARAP"]
    assert cm.estimate("ARAP", 2 * SMALL_VERTICES) == pytest.approx(0.5 * 2 ** p)


def test_a_cost_exponent_out_of_range_is_refused_naming_the_file(tmp_path, monkeypatch):
    import shutil
    from pathlib import Path

    import harness.method_registry as reg
    from sshade.errors import SShaDeError
    conf = tmp_path / "conf"
    shutil.copytree(Path(__file__).resolve().parents[1] / "conf", conf)
    f = conf / "method" / "ARAP.yaml"
    f.write_text(f.read_text().replace("exponent: 1.50", "exponent: 7"))
    monkeypatch.setattr(reg, "config_dir", lambda sub="": str(conf / sub) if sub else str(conf))
    with pytest.raises(SShaDeError, match=r"conf/method/ARAP.yaml: cost.exponent must be a number in \[0, 3\], got 7"):
        default_cost_model([SimpleNamespace(name="ARAP")])


def test_the_weighted_bar_never_goes_back_whatever_the_estimates_do():
    """Runs longer than estimated, estimates raised and lowered in any order: the fraction
    shown never decreases, never passes 1, and ends at 1 when the last run is counted (a
    bar that counts: a disabled tqdm bar counts nothing, and held this test to nothing)."""
    import random

    from eval.run.progress import weighted_bar
    rng = random.Random(3)
    counted = 0
    for _ in range(50):
        bar = weighted_bar(10.0, 5)  # writes to the captured stderr
        shown = [0.0]
        for _step in range(rng.randint(1, 12)):
            if rng.random() < 0.5:
                bar.advance(rng.uniform(0.0, 8.0))
            else:
                bar.retotal(bar.n + rng.uniform(0.0, 30.0))
            f = bar.n / bar.total
            assert shown[-1] - 1e-12 <= f <= 1.0 + 1e-12, (shown[-1], f)
            shown.append(f)
        bar.retotal(bar.n)  # nothing left
        assert bar.n / bar.total == 1.0 or bar.n == 0
        counted += bar.n > 0
        bar.close()
    assert counted > 25

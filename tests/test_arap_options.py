"""The ARAP solvers' one options record (sshade/arap/options.py): every field checked when
made, one default per option (the iteration cap per protocol, the window per accelerator,
``"auto"`` per energy), a field a solver does not read refused rather than ignored, the
set-up fields of a prepared solver or deformer held, and the record giving the iterates
its explicit equivalents give, bit for bit."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from sshade import check_params
from sshade.arap import (
    DEFAULT_CRITERION,
    DEFAULT_MAX_ITER,
    ArapDeformer,
    ArapOptions,
    ArapSolver,
    Criterion,
    SRProblem,
    arap_deform,
    arap_sr_deform,
    solve_arap,
    solve_arap_sr,
)
from sshade.arap.problems import twisted_bar
from sshade.errors import SShaDeError


@pytest.fixture(scope="module")
def bar():
    return twisted_bar(90.0, h=0.25)


def _same(a, b) -> bool:
    """The same iterates: positions bit for bit, the same iterations and energies."""
    return (np.array_equal(a.V, b.V) and a.iterations == b.iterations
            and a.info.get("energy_history") == b.info.get("energy_history"))


#: (field, a bad value, the refusal's message): every field at least once
BAD_VALUES = [
    ("energy", "elements", "unknown ARAP energy 'elements'"),
    ("energy", None, "unknown ARAP energy None"),
    ("protocol", "fast", "unknown ARAP protocol 'fast'"),
    ("criterion", (1e-7, 1e-3), "criterion must be a Criterion, got tuple"),
    ("max_iter", -1, "max_iter must be an integer >= 0 or None, got -1"),
    ("max_iter", 10.5, "max_iter must be an integer >= 0 or None, got 10.5"),
    ("max_iter", True, "max_iter must be an integer >= 0 or None, got True"),
    ("accelerate", "newton", r"accelerate must be one of .* \(or True/False\), got 'newton'"),
    ("accelerate", None, r"accelerate must be one of .*, got None"),
    ("history", 0, "history must be an integer >= 1 or None, got 0"),
    ("time_budget_s", -1.0, "time_budget_s must be a number >= 0 or None, got -1.0"),
    ("time_budget_s", float("nan"), "time_budget_s must be a number >= 0 or None, got nan"),
    ("tol", 0.0, "tol must be a finite number > 0, got 0.0"),
    ("tol", float("inf"), "tol must be a finite number > 0, got inf"),
    ("stop", "gradient", r"ARAP-SR: stop must be one of \('energy', 'move'\), got 'gradient'"),
    ("linear_solver", "mumps", "unknown linear solver 'mumps'"),
    ("threads", 0, "threads must be an integer >= 1 or None, got 0"),
    ("reorder", "yes", "reorder must be True or False or None, got 'yes'"),
    ("alpha", -0.1, "ARAP-SR: alpha must be a finite number >= 0, got -0.1"),
    ("alpha", float("inf"), "ARAP-SR: alpha must be a finite number >= 0, got inf"),
    ("alpha_scaling", "area", r"ARAP-SR: alpha_scaling must be one of \('valence', 'none'\), got 'area'"),
    ("jacobi", 1, "jacobi must be True or False, got 1"),
    ("reset_on_reject", None, "reset_on_reject must be True or False, got None"),
]


@pytest.mark.parametrize("field, value, message", BAD_VALUES)
def test_each_field_is_refused_when_made_with_a_bad_value(field, value, message):
    with pytest.raises(SShaDeError, match=message):
        ArapOptions(**{field: value})


def test_every_field_has_a_refusal_case():
    assert {f.name for f in dataclasses.fields(ArapOptions)} == {c[0] for c in BAD_VALUES}


def test_the_record_is_frozen_and_checked_again_when_replaced():
    o = ArapOptions()
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.max_iter = 3
    with pytest.raises(SShaDeError, match="history"):
        dataclasses.replace(o, history=0)


def test_max_iter_none_is_the_protocols_cap():
    assert DEFAULT_MAX_ITER == {"converged": 10000, "paper": 1000}
    assert ArapOptions().iteration_cap() == 10000
    assert ArapOptions(protocol="paper").iteration_cap() == 1000
    assert ArapOptions().iteration_cap("paper") == 1000  # arap_sr_deform: the paper protocol
    assert ArapOptions(max_iter=7).iteration_cap("paper") == ArapOptions(max_iter=7).iteration_cap() == 7


def test_auto_is_lbfgs_for_arap_and_anderson_for_arap_sr():
    assert ArapOptions().acceleration() == ArapOptions(energy="spokes").acceleration() == "lbfgs"
    assert ArapOptions(energy="arap_sr").acceleration() == "anderson"
    assert ArapOptions().acceleration("arap_sr") == "anderson"
    assert ArapOptions(accelerate="none", energy="arap_sr").acceleration() == "none"


def test_history_none_is_10_for_lbfgs_and_5_for_anderson():
    o = ArapOptions()
    assert (o.window("lbfgs"), o.window("anderson"), o.window("none")) == (10, 5, 5)
    assert ArapOptions(history=3).window("lbfgs") == 3


def test_true_false_and_none_are_normalised():
    assert ArapOptions(accelerate=True).accelerate == "anderson"
    assert ArapOptions(accelerate=False).accelerate == "none"
    assert ArapOptions(criterion=None).criterion is DEFAULT_CRITERION
    o = ArapOptions(max_iter=np.int64(5), alpha=np.float32(0.5), time_budget_s=2)
    assert type(o.max_iter) is int and type(o.alpha) is float and type(o.time_budget_s) is float


@pytest.mark.parametrize("call, field", [
    (lambda V, F, h, T: solve_arap(V, F, h, T, ArapOptions(alpha=0.05)), "alpha"),
    (lambda V, F, h, T: solve_arap(V, F, h, T, ArapOptions(protocol="paper")), "protocol"),
    (lambda V, F, h, T: solve_arap(V, F, h, T, ArapOptions(tol=1e-3)), "tol"),
    (lambda V, F, h, T: ArapSolver(V, F, h, ArapOptions(jacobi=True)), "jacobi"),
    (lambda V, F, h, T: solve_arap_sr(V, F, h, T, ArapOptions(threads=1)), "threads"),
    (lambda V, F, h, T: solve_arap_sr(V, F, h, T, ArapOptions(stop="move")), "stop"),
    (lambda V, F, h, T: arap_sr_deform(V, F, h, T, ArapOptions(accelerate="none")), "accelerate"),
    (lambda V, F, h, T: arap_sr_deform(V, F, h, T, ArapOptions(reset_on_reject=True)), "reset_on_reject"),
    (lambda V, F, h, T: arap_deform(V, F, h, T, ArapOptions(tol=1e-3)), "tol"),
    (lambda V, F, h, T: arap_deform(V, F, h, T, ArapOptions(protocol="paper", accelerate="anderson")), "accelerate"),
    (lambda V, F, h, T: arap_deform(V, F, h, T, ArapOptions(protocol="paper", threads=2)), "threads"),
    (lambda V, F, h, T: arap_deform(V, F, h, T, ArapOptions(alpha=0.05)), "alpha"),
    (lambda V, F, h, T: arap_deform(V, F, h, T, ArapOptions(energy="arap_sr", protocol="paper", stop="move")),
     "stop"),
    (lambda V, F, h, T: ArapDeformer(V, F, h, ArapOptions(energy="arap_sr", reorder=True)), "reorder"),
])
def test_a_field_the_solver_does_not_read_is_refused_before_any_work(bar, call, field):
    with pytest.raises(SShaDeError, match=rf"does not read the option {field} \(given .*\); it is read by"):
        call(*bar)


def test_the_arap_sr_solvers_take_arap_srs_energy_or_the_default_and_no_lbfgs(bar):
    V, F, h, T = bar
    for solver in (solve_arap_sr, arap_sr_deform):
        with pytest.raises(SShaDeError, match="solves ARAP-SR's energy"):
            solver(V, F, h, T, ArapOptions(energy="spokes"))
    assert _same(solve_arap_sr(V, F, h, T, ArapOptions(energy="arap_sr")), solve_arap_sr(V, F, h, T))
    with pytest.raises(SShaDeError, match="ARAP-SR has no L-BFGS"):
        solve_arap_sr(V, F, h, T, ArapOptions(accelerate="lbfgs"))
    with pytest.raises(SShaDeError, match="unknown ARAP energy 'arap_sr'.*solve_arap_sr"):
        solve_arap(V, F, h, T, ArapOptions(energy="arap_sr"))


def test_a_problem_built_for_another_alpha_is_refused(bar):
    V, F, h, T = bar
    pb = SRProblem(V, F, h, T, 0.02)
    with pytest.raises(SShaDeError, match="alpha=0.01, but the problem given was built with 0.02"):
        solve_arap_sr(V, F, h, T, problem=pb)
    with pytest.raises(SShaDeError, match="alpha_scaling='none'"):
        arap_sr_deform(V, F, h, T, ArapOptions(alpha=0.02, alpha_scaling="none"), problem=pb)
    assert solve_arap_sr(V, F, h, T, ArapOptions(alpha=0.02), problem=pb).converged


def test_options_must_be_an_arap_options(bar):
    V, F, h, T = bar
    for call in (lambda: solve_arap(V, F, h, T, {"energy": "spokes"}), lambda: arap_deform(V, F, h, T, "paper"),
                 lambda: solve_arap_sr(V, F, h, T, Criterion()), lambda: ArapSolver(V, F, h).solve(T, options=3)):
        with pytest.raises(SShaDeError, match="options must be an ArapOptions"):
            call()


@pytest.mark.parametrize("field, value", [("energy", "spokes"), ("linear_solver", "scipy"), ("threads", 1),
                                          ("reorder", True)])
def test_a_prepared_solver_refuses_another_set_up(bar, field, value):
    V, F, h, T = bar
    solver = ArapSolver(V, F, h)
    with pytest.raises(SShaDeError, match=rf"ArapSolver.solve: {field}={value!r}, but it was set up with"):
        solver.solve(T, options=ArapOptions(**{field: value}))
    assert solver.solve(T, options=ArapOptions(accelerate="anderson", history=4)).info["history"] == 4


def test_a_deformer_refuses_another_set_up(bar):
    V, F, h, T = bar
    d = ArapDeformer(V, F, h, ArapOptions(energy="arap_sr"))
    for changed in ({"protocol": "paper"}, {"alpha": 0.05}, {"energy": "spokes"}):
        with pytest.raises(SShaDeError, match=f"ArapDeformer.deform: {next(iter(changed))}="):
            d.deform(T, options=ArapOptions(**{"energy": "arap_sr", **changed}))


def test_the_defaults_give_the_iterates_of_their_explicit_values(bar):
    """``"auto"`` and None give the iterates of what they stand for: L-BFGS with a memory
    of 10 and the converged cap for ARAP, Anderson with a window of 5 for ARAP-SR; ``True``
    is ``"anderson"``; the prepared solver and the deformer give solve_arap's."""
    V, F, h, T = bar
    for energy in ("spokes", "spokes_and_rims"):
        auto = solve_arap(V, F, h, T, ArapOptions(energy=energy))
        explicit = ArapOptions(energy=energy, accelerate="lbfgs", history=10, max_iter=10000,
                               criterion=Criterion(1e-7, 1e-3))
        assert auto.converged and _same(auto, solve_arap(V, F, h, T, explicit))
        assert _same(auto, ArapSolver(V, F, h, ArapOptions(energy=energy)).solve(T))
        assert _same(auto, arap_deform(V, F, h, T, ArapOptions(energy=energy)))
        anderson = solve_arap(V, F, h, T, ArapOptions(energy=energy, accelerate="anderson", history=5))
        assert _same(anderson, solve_arap(V, F, h, T, ArapOptions(energy=energy, accelerate=True)))
        assert not _same(anderson, auto)
    sr = solve_arap_sr(V, F, h, T)
    assert sr.info["accelerate"] == "anderson"
    assert _same(sr, solve_arap_sr(V, F, h, T, ArapOptions(accelerate="anderson", history=5, max_iter=10000)))
    deformed = arap_deform(V, F, h, T, ArapOptions(energy="arap_sr", accelerate="lbfgs"))  # ARAP-SR: Anderson
    assert _same(sr, deformed) and np.array_equal(sr.info["R"], deformed.info["R"])


def test_arap_srs_paper_protocol_in_arap_deform_is_arap_sr_deform_with_the_move_rule(bar):
    V, F, h, T = bar
    a = arap_deform(V, F, h, T, ArapOptions(energy="arap_sr", protocol="paper"))
    b = arap_sr_deform(V, F, h, T, ArapOptions(stop="move", protocol="paper"))
    assert a.info["protocol"] == "paper" and _same(a, b) and a.iterations <= 1000


def test_sshades_low_res_options_take_tol_only_under_the_paper_protocol():
    converged = check_params(tol=1e-3, etol=1e-8).arap_options()
    assert converged.tol == ArapOptions().tol and converged.criterion == Criterion(1e-8, 1e-3)
    paper = check_params(tol=1e-3, protocol="paper", energy="spokes").arap_options()
    assert (paper.tol, paper.protocol, paper.energy, paper.max_iter) == (1e-3, "paper", "spokes", None)

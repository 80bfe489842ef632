"""sshade.arap.paper_protocol: the paper's protocol (libigl's iteration, the move rule, the
gradient test) gives what arap_deform gives under it, refuses what it does not read, and
runs only code its rows' identity holds (no converged solver)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from eval.run.code_identity import PACKAGES, code_identity
from sshade.arap import ArapOptions, arap_deform, iterate
from sshade.arap.paper_protocol import PaperSolver, paper_deform
from sshade.arap.problems import twisted_bar
from sshade.errors import SShaDeError

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("energy", ["spokes", "spokes_and_rims"])
def test_paper_deform_is_arap_deform_under_the_paper_protocol_bit_for_bit(energy):
    V, F, h, T = twisted_bar(60.0, h=0.25)
    o = ArapOptions(energy=energy, protocol="paper", tol=1e-3)
    a, b = arap_deform(V, F, h, T, o), paper_deform(V, F, h, T, o)
    assert np.array_equal(a.V, b.V) and a.iterations == b.iterations and a.info == b.info
    assert b.info["status"] in ("converged", "stalled") and b.last_move < 1e-3 * np.linalg.norm(np.ptp(V, 0))


def test_a_prepared_paper_solver_gives_each_targets_what_a_fresh_one_gives():
    V, F, h, T = twisted_bar(60.0, h=0.25)
    o = ArapOptions(protocol="paper", max_iter=30)
    s = PaperSolver(V, F, h, "spokes")
    s.deform(T * 1.01, o)
    again, fresh = s.deform(T, o), PaperSolver(V, F, h, "spokes").deform(T, o)
    assert np.array_equal(again.V, fresh.V) and again.precompute_s < fresh.precompute_s  # libigl set up once


def test_rigidly_moved_handles_give_the_rigid_motion_without_iterating():
    V, F, h, _ = twisted_bar(60.0, h=0.25)
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    res = paper_deform(V, F, h, V[h] @ R.T + [1.0, 2.0, 3.0], ArapOptions(protocol="paper"))
    assert res.iterations == 0 and res.info["status"] == "rigid"
    assert np.allclose(res.V, V @ R.T + [1.0, 2.0, 3.0], atol=1e-12)


@pytest.mark.parametrize("options, word", [(ArapOptions(), "protocol"),
                                           (ArapOptions(protocol="paper", energy="arap_sr"), "energy"),
                                           (ArapOptions(protocol="paper", accelerate="anderson"), "accelerate")])
def test_paper_deform_refuses_another_protocol_energy_or_an_unread_field(options, word):
    V, F, h, T = twisted_bar(20.0, h=0.5)
    with pytest.raises(SShaDeError, match=word):
        paper_deform(V, F, h, T, options)


def test_iterate_stops_at_the_first_move_below_the_threshold():
    U, it, converged, move = iterate(lambda X: X * 0.5, np.ones((4, 3)), thresh=0.1, max_iter=100)
    assert converged and it == 5 and move < 0.1 <= 2 * move and np.allclose(U, 0.5 ** 5)


def _project_modules_run(call) -> set[str]:
    """The project modules whose Python code runs during ``call()`` (a profile hook)."""
    seen: set[str] = set()

    def hook(frame, event, arg):
        f = Path(frame.f_code.co_filename)
        if event == "call" and f.suffix == ".py" and f.is_relative_to(ROOT) and f.parts[len(ROOT.parts)] in PACKAGES:
            parts = f.relative_to(ROOT).with_suffix("").parts
            seen.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    sys.setprofile(hook)
    try:
        call()
    finally:
        sys.setprofile(None)
    return seen


@pytest.mark.parametrize("protocol", ["paper", "converged"])
def test_a_baseline_runs_no_project_code_outside_its_rows_identity(protocol):
    """Built, warmed and run under ``protocol``, ARAP, Elastic and ARAP-SR run Python code
    of no project module outside their rows' code identity (eval.run.code_identity), and
    under the paper protocol none of the converged solvers'."""
    import baselines
    V, F, h, T = twisted_bar(30.0, h=0.5)
    for cls, target in ((baselines.ARAP, "baselines.ARAP"), (baselines.Elastic, "baselines.Elastic"),
                        (baselines.ARAPSR, "baselines.ARAPSR")):
        spec = {"class": f"{cls.__module__}.{cls.__qualname__}", "_target_": target, "protocol": protocol}
        held = set(code_identity(None, spec, references=False)["modules"])
        ran = _project_modules_run(lambda c=cls: (m := c(protocol=protocol)).warmup() + m.deform(V, F, h, T).sum())
        packages = {".".join(x.split(".")[:i]) for x in held for i in range(1, x.count(".") + 1)}
        assert ran - held - packages == set(), ran - held - packages
        if protocol == "paper":
            assert not {"sshade.arap.solver", "sshade.arap.accelerate", "sshade.arap.local_global",
                        "sshade.arap.sr_solver"} & ran

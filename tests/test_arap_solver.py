"""Converged ARAP solver (sshade.arap.solver): L-BFGS with the Laplacian as initial
Hessian (default) and safeguarded Anderson acceleration, the convergence criterion's
guarantee, rigid motions, linear-solver backends."""
import numpy as np
import pytest

from sshade.arap import (
    DEEP_CRITERION,
    DEFAULT_CRITERION,
    ArapOptions,
    ArapResult,
    Criterion,
    LaplacianSolver,
    bbox_diag,
    build_operators,
    solve_arap,
)
from sshade.arap.problems import bent_cylinder, lifted_plane, twisted_bar
from sshade.errors import SShaDeError

try:
    import cholespy  # noqa: F401
    HAVE_CHOLESPY = True
except ImportError:  # pragma: no cover
    HAVE_CHOLESPY = False


@pytest.fixture(scope="module")
def bar():
    return twisted_bar(135.0, h=0.12)  # ~1,300 vertices


@pytest.fixture(scope="module")
def bent():
    return bent_cylinder(90.0, h=0.15)  # small bent bar (capped cylinder), ~700 vertices


def _dist(U, Uref, diag):
    d = np.linalg.norm(U - Uref, axis=1) / diag
    return d.mean(), d.max()


@pytest.mark.parametrize("energy", ["spokes", "spokes_and_rims"])
def test_safeguard_never_increases_energy(bar, energy):
    V, F, h, T = bar
    res = solve_arap(V, F, h, T, ArapOptions(energy=energy, criterion=Criterion(1e-10, 1e-6), accelerate="anderson",
                                             history=5))
    assert isinstance(res, ArapResult)
    E = np.array(res.info["energy_history"])
    assert len(E) == res.iterations + 1
    assert (np.diff(E) <= 0).all()
    assert res.converged and res.info["status"] == "converged"
    assert res.info["n_local"] == res.iterations + 1 + res.info["n_fallback"]
    assert res.info["gnorm"] < 1e-6


def test_safeguard_fallback_path_is_exercised(bent):
    V, F, h, T = bent
    res = solve_arap(V, F, h, T, ArapOptions(criterion=DEFAULT_CRITERION, accelerate="anderson"))
    assert res.info["n_fallback"] > 0  # Anderson steps were rejected on this case
    E = np.array(res.info["energy_history"])
    assert (np.diff(E) <= 0).all()


@pytest.mark.parametrize("energy", ["spokes", "spokes_and_rims"])
def test_lbfgs_line_search_never_increases_energy(bent, energy):
    V, F, h, T = bent
    res = solve_arap(V, F, h, T, ArapOptions(energy=energy, criterion=Criterion(1e-10, 1e-6)))
    assert res.info["accelerate"] == "lbfgs" and res.converged
    E = np.array(res.info["energy_history"])
    assert len(E) == res.iterations + 1
    assert (np.diff(E) < 0).all()  # Armijo: every accepted step lowers the energy
    # one local step per accepted iterate, plus the start and the backtracking trials
    assert res.info["n_local"] >= res.iterations + 1


@pytest.mark.parametrize("energy", ["spokes", "spokes_and_rims"])
def test_rigid_handle_motion_is_reproduced_exactly(bar, energy):
    V, F, h, _ = bar
    rng = np.random.default_rng(5)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    t = rng.normal(size=3)
    res = solve_arap(V, F, h, V[h] @ Q.T + t, ArapOptions(energy=energy))
    assert res.converged
    assert np.abs(res.V - (V @ Q.T + t)).max() <= 1e-9 * bbox_diag(V)
    assert res.iterations == 0 and res.info["status"] == "rigid"


@pytest.mark.parametrize("energy", ["spokes", "spokes_and_rims"])
def test_criterion_guarantee_on_bent_bar(bent, energy):
    V, F, h, T = bent
    ops = build_operators(V, F, energy)
    diag = ops.diag
    ref = solve_arap(V, F, h, T, ArapOptions(energy=energy, criterion=DEEP_CRITERION, max_iter=20000), operators=ops)
    assert ref.info["gnorm"] < 1e-6
    for accelerate in ("lbfgs", "anderson", False):
        res = solve_arap(V, F, h, T, ArapOptions(energy=energy, accelerate=accelerate, max_iter=20000), operators=ops)
        assert res.converged, res.info["status"]
        assert res.info["gnorm"] < DEFAULT_CRITERION.gtol
        mean, mx = _dist(res.V, ref.V, diag)
        assert mean <= 5e-4 and mx <= 5e-3, (accelerate, mean, mx)
        assert res.info["energy"] >= ref.info["energy"] * (1 - 1e-12)


def test_accelerated_and_plain_reach_the_same_minimum():
    # 90 degrees: one minimum. (At 135 degrees on this coarse bar the symmetric twist is a
    # saddle: Anderson converges to it, plain local/global leaves it after ~4000
    # iterations through rounding noise and reaches a 2.5 % lower energy.)
    V, F, h, T = twisted_bar(90.0, h=0.12)
    a = solve_arap(V, F, h, T, ArapOptions(criterion=Criterion(1e-12, 1e-7)))
    p = solve_arap(V, F, h, T, ArapOptions(criterion=Criterion(1e-12, 1e-7), accelerate=False, max_iter=20000))
    assert a.converged and p.converged
    assert a.iterations * 3 < p.iterations
    mean, mx = _dist(a.V, p.V, bbox_diag(V))
    assert mx < 1e-6


@pytest.mark.skipif(not HAVE_CHOLESPY, reason="cholespy not installed")
def test_cholesky_and_scipy_fallback_agree(bar):
    V, F, h, T = bar
    plain = {}
    for backend in ("cholespy", "scipy", "igl"):
        options = ArapOptions(accelerate=False, criterion=Criterion(0.0, 0.0), max_iter=15, linear_solver=backend)
        plain[backend] = solve_arap(V, F, h, T, options)
        assert plain[backend].info["linear_solver"] == backend
    diag = bbox_diag(V)
    assert np.abs(plain["cholespy"].V - plain["scipy"].V).max() <= 1e-10 * diag
    assert np.abs(plain["igl"].V - plain["scipy"].V).max() <= 1e-10 * diag
    acc = {b: solve_arap(V, F, h, T, ArapOptions(linear_solver=b)) for b in ("cholespy", "scipy")}
    assert acc["cholespy"].converged and acc["scipy"].converged
    assert np.abs(acc["cholespy"].V - acc["scipy"].V).max() <= 1e-4 * diag


def test_auto_backend_falls_back_to_scipy(monkeypatch, bar):
    from sshade.arap import linear
    monkeypatch.setattr(linear, "CholeskySolverD", None)  # as when cholespy cannot be imported
    V, F, h, T = bar
    res = solve_arap(V, F, h, T, ArapOptions(max_iter=3, criterion=Criterion(0.0, 0.0)))
    assert res.info["linear_solver"] == "scipy"
    with pytest.raises(SShaDeError):
        solve_arap(V, F, h, T, ArapOptions(linear_solver="cholespy"))


def test_free_region_without_handle_raises():
    # two disjoint bars, handles only on the first: the second is a free component
    V, F, h, T = twisted_bar(90.0, h=0.5)
    V2 = np.concatenate([V, V + [10.0, 0, 0]])
    F2 = np.concatenate([F, F + len(V)])
    for backend in ("scipy",) + (("cholespy",) if HAVE_CHOLESPY else ()):
        with pytest.raises(SShaDeError, match="no handle"):
            solve_arap(V2, F2, h, T, ArapOptions(linear_solver=backend))
    if HAVE_CHOLESPY:  # an indefinite matrix is refused by the Cholesky backend
        with pytest.raises(SShaDeError, match="positive definite"):
            LaplacianSolver(np.array([[1.0, -2.0], [-2.0, 1.0]]), backend="cholespy")
    # with a handle on each component it works
    h2 = np.concatenate([h, h + len(V)])
    res = solve_arap(V2, F2, h2, np.concatenate([T, T + [10.0, 0, 0]]))
    assert res.converged


def test_plane_lift_small():
    V, F, h, T = lifted_plane(0.2, n_target=1500)
    res = solve_arap(V, F, h, T)
    assert res.converged
    np.testing.assert_allclose(res.V[h], T)
    assert res.V[:, 2].max() == pytest.approx(0.2)
    assert res.info["gnorm"] < DEFAULT_CRITERION.gtol


def test_time_budget_and_callback(bar):
    V, F, h, T = bar
    seen = []

    def cb(k, U, E, g):
        seen.append((k, E, g))
        return k >= 4

    res = solve_arap(V, F, h, T, ArapOptions(criterion=Criterion(0.0, 0.0)), callback=cb)
    assert res.info["status"] == "callback" and res.iterations == 4 and not res.converged
    assert [s[0] for s in seen] == [1, 2, 3, 4]
    res = solve_arap(V, F, h, T, ArapOptions(time_budget_s=0.0, criterion=Criterion(0.0, 0.0)))
    assert res.info["status"] == "time_budget" and not res.converged


def test_bad_input_raises(bar):
    V, F, h, T = bar
    with pytest.raises(SShaDeError, match="unknown ARAP energy 'arap_sr'"):
        solve_arap(V, F, h, T, ArapOptions(energy="arap_sr"))
    with pytest.raises(SShaDeError):
        solve_arap(V, F, h, T[:-1])
    with pytest.raises(SShaDeError):
        solve_arap(V, F, h, T, U0=V[:-1])
    with pytest.raises(SShaDeError, match="options must be an ArapOptions"):
        solve_arap(V, F, h, T, {"energy": "spokes"})
    with pytest.raises(SShaDeError):
        Criterion(etol=-1.0)
    with pytest.raises(SShaDeError):
        solve_arap(V, F, h, T, ArapOptions(energy="spokes"), operators=build_operators(V, F, "spokes_and_rims"))
    with pytest.raises(SShaDeError):
        LaplacianSolver(np.eye(3), backend="nope")


@pytest.mark.parametrize("accelerate", ["lbfgs", "anderson"])
def test_threads_and_numbering_do_not_change_the_iterates(bar, accelerate):
    V, F, h, T = bar
    ops = build_operators(V, F, "spokes_and_rims")
    runs = {}
    for threads in (1, 2):
        for reorder in (False, True):
            options = ArapOptions(criterion=Criterion(0.0, 0.0), max_iter=30, threads=threads, reorder=reorder,
                                  accelerate=accelerate)
            runs[threads, reorder] = solve_arap(V, F, h, T, options, operators=ops)
    a = runs[1, False]
    assert a.info["threads"] == 1 and not a.info["reordered"] and runs[2, True].info["reordered"]
    assert set(a.info["stage_s"]) == {"local", "rhs", "solve", "gradient", "anderson"}
    for reorder in (False, True):  # threads: bit-identical
        np.testing.assert_array_equal(runs[1, reorder].V, runs[2, reorder].V)
        assert runs[1, reorder].info["energy_history"] == runs[2, reorder].info["energy_history"]
    b = runs[1, True]  # renumbering: the Cholesky factor rounds differently
    assert np.abs(a.V - b.V).max() <= 1e-9 * bbox_diag(V)
    np.testing.assert_allclose(b.info["energy_history"], a.info["energy_history"], rtol=1e-9)


def test_numpy_fallback_solver_agrees(monkeypatch, bar):
    from sshade.arap import kernels
    V, F, h, T = bar
    ref = solve_arap(V, F, h, T, ArapOptions(criterion=Criterion(1e-10, 1e-6)))
    monkeypatch.setattr(kernels, "_POLAR", False)
    monkeypatch.setattr(kernels, "_ENERGY", False)
    res = solve_arap(V, F, h, T, ArapOptions(criterion=Criterion(1e-10, 1e-6), reorder=True))
    assert not res.info["reordered"]  # numpy path: mesh numbering
    assert res.converged
    assert np.abs(res.V - ref.V).max() <= 1e-6 * bbox_diag(V)
    assert res.info["energy"] == pytest.approx(ref.info["energy"], rel=1e-8)


def test_thread_picker_follows_the_faster_mode():
    from sshade.arap.threads import ThreadPicker
    p = ThreadPicker(2, probe=4)
    assert p.cur == 2
    p.record(2, 1.0)
    assert p.cur == 1  # the other mode is timed once
    seen = []
    for _ in range(12):
        p.record(p.cur, 0.5 if p.cur == 1 else 1.0)
        seen.append(p.cur)
    assert p.best == 1 and seen.count(2) == 3  # serial faster: parallel re-timed every 4th
    for _ in range(12):
        p.record(p.cur, 0.5 if p.cur == 2 else 1.0)  # the load changed
    assert p.best == 2 and p.cur in (1, 2)


def test_automatic_threads_same_iterates():
    V, F, h, T = lifted_plane(0.2, n_target=22000)  # above the parallel threshold
    a = solve_arap(V, F, h, T, ArapOptions(criterion=Criterion(0.0, 0.0), max_iter=20))
    b = solve_arap(V, F, h, T, ArapOptions(criterion=Criterion(0.0, 0.0), max_iter=20, threads=1))
    assert a.info["reordered"]
    if a.info["threads"] > 1:  # NUMBA_NUM_THREADS > 1: the automatic mode timed both
        assert 0.0 < a.info["parallel_fraction"] < 1.0
    np.testing.assert_array_equal(a.V, b.V)
    assert a.info["energy_history"] == b.info["energy_history"]


# ----------------------------------------------------------------------------- prepared solver
def test_a_prepared_solver_gives_solve_arap_bit_for_bit():
    from sshade.arap.solver import ArapSolver
    V, F, h, T = twisted_bar(90.0, h=0.25)
    for energy in ("spokes", "spokes_and_rims"):
        one = solve_arap(V, F, h, T, ArapOptions(energy=energy))
        two = ArapSolver(V, F, h, ArapOptions(energy=energy)).solve(T)
        assert np.array_equal(one.V, two.V) and one.iterations == two.iterations
        assert one.info["energy"] == two.info["energy"]


def test_frames_share_one_factorisation_and_each_lands_on_the_one_shot_solution():
    """A 6-frame twist, each frame warm-started from the last: the Cholesky factor is made
    once, every frame converges, and each is the one-shot solve of its targets within
    1e-4 of the diagonal (mean)."""
    from sshade.arap.solver import ArapSolver
    V, F, h, _ = twisted_bar(0.0, h=0.25)
    solver = ArapSolver(V, F, h, ArapOptions(energy="spokes_and_rims"))
    lin = solver.factorisation
    diag = np.linalg.norm(V.max(0) - V.min(0))
    prev = None
    for k, angle in enumerate(np.linspace(15.0, 90.0, 6)):
        _, _, _, T = twisted_bar(angle, h=0.25)
        r = solver.solve(T, U0=prev)
        ref = solve_arap(V, F, h, T, ArapOptions(energy="spokes_and_rims"))
        assert r.converged and ref.converged
        assert np.linalg.norm(r.V - ref.V, axis=1).mean() < 1e-4 * diag
        if k == 0:
            assert r.precompute_s >= solver.precompute_s  # the set-up, counted once
        prev = r.V
    assert solver.factorisation is lin and lin is not None  # factorised once


def test_a_prepared_solver_checks_each_solves_targets():
    from sshade.arap.solver import ArapSolver
    V, F, h, T = twisted_bar(45.0, h=0.25)
    solver = ArapSolver(V, F, h)
    with pytest.raises(SShaDeError, match="targets"):
        solver.solve(T[:-1])
    with pytest.raises(SShaDeError, match="NaN"):
        solver.solve(np.full_like(T, np.nan))
    with pytest.raises(SShaDeError, match="out of range"):
        ArapSolver(V, F, [0, len(V)])
    assert solver.solve(T).converged  # still usable after refused targets


@pytest.mark.parametrize("accelerate, m", [("lbfgs", 6), ("anderson", 8)])
def test_carried_history_converges_to_each_frames_one_shot_solution(accelerate, m):
    """Frames of a twist solved with the last solve's accelerator history carried over
    (L-BFGS pairs, Anderson differences): every frame meets the criterion and is the
    one-shot solve of its targets within 1e-4 of the diagonal (mean); the carried history
    changes the path (other iterates than a fresh one) and, over the frames, takes no more
    iterations in all."""
    from sshade.arap.solver import ArapSolver
    V, F, h, _ = twisted_bar(0.0, h=0.25)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    carried, fresh = ArapSolver(V, F, h), ArapSolver(V, F, h)
    prev_c = prev_f = None
    its_c = its_f = 0
    for k, angle in enumerate(np.linspace(10.0, 90.0, 9)):
        _, _, _, T = twisted_bar(angle, h=0.25)
        options = ArapOptions(accelerate=accelerate, history=m)
        rc = carried.solve(T, options=options, U0=prev_c, carry_history=True)
        rf = fresh.solve(T, options=options, U0=prev_f)
        ref = solve_arap(V, F, h, T)
        assert rc.converged and rf.converged
        assert np.linalg.norm(rc.V - ref.V, axis=1).mean() < 1e-4 * diag
        if k == 0:  # nothing to carry yet: the same solve
            assert np.array_equal(rc.V, rf.V)
        elif k == 1:
            assert not np.array_equal(rc.V, rf.V)
        its_c, its_f = its_c + rc.iterations, its_f + rf.iterations
        prev_c, prev_f = rc.V, rf.V
    assert its_c <= its_f


def test_carried_history_needs_the_same_accelerator_and_window():
    """A solve with another L-BFGS memory, or with Anderson after L-BFGS, starts afresh:
    the same iterates as a solver without history."""
    from sshade.arap.solver import ArapSolver
    V, F, h, T = twisted_bar(60.0, h=0.25)
    _, _, _, T2 = twisted_bar(70.0, h=0.25)
    for options in (ArapOptions(history=5), ArapOptions(accelerate="anderson")):
        a, b = ArapSolver(V, F, h), ArapSolver(V, F, h)
        r1 = a.solve(T, options=ArapOptions(history=6))
        ra = a.solve(T2, options=options, U0=r1.V, carry_history=True)
        rb = b.solve(T2, options=options, U0=r1.V)
        assert np.array_equal(ra.V, rb.V) and ra.iterations == rb.iterations


@pytest.mark.parametrize("criterion", [DEFAULT_CRITERION, Criterion(1e-10, 1e-6), DEEP_CRITERION],
                         ids=["default", "etol 1e-10", "deep"])
def test_the_energy_takes_the_trace_form_only_under_a_criterion_its_noise_cannot_reach(bar, criterion, monkeypatch):
    from sshade.arap.criterion import TRACE_ETOL
    from sshade.arap.operators import ArapOperators
    V, F, h, T = bar
    seen, step = [], ArapOperators.local_step

    def spy(self, *args):
        seen.append(args[6] is not None)  # Et: the trace form's edge terms
        return step(self, *args)

    monkeypatch.setattr(ArapOperators, "local_step", spy)
    res = solve_arap(V, F, h, T, ArapOptions(criterion=criterion, max_iter=30))
    assert seen and len(seen) == res.info["n_local"]
    assert set(seen) == {criterion.etol >= TRACE_ETOL}

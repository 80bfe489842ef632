"""sshade/prepared.py: prepare once, solve per frame. The first solve is deform bit for
bit; a sequence of frames lands on the one-shot deform of each frame, and within a bound
of the frames of the earlier start (handle rows alone moved); the set-up is made once;
bad targets and meshes are refused."""
from __future__ import annotations

import numpy as np
import pytest

from sshade import deform, prepare
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh

from .conftest import SHARED_DATA


@pytest.fixture(scope="module")
def faust_pair():
    a, b = SHARED_DATA / "faust_reg" / "tr_reg_000.ply", SHARED_DATA / "faust_reg" / "tr_reg_001.ply"
    if not (a.is_file() and b.is_file()):
        pytest.skip(f"FAUST registrations not found in {a.parent}")
    V, F = read_mesh(a)
    V2, _ = read_mesh(b)
    return V, F, np.arange(0, len(V), 41), V2


@pytest.mark.parametrize("anchor", ["projection", "barycenter"])
def test_the_first_solve_is_deform_bit_for_bit(faust_pair, anchor):
    V, F, h, V2 = faust_pair
    kw = dict(n_low=500, n_samplings=3, seed=7, anchor=anchor)
    prepared = prepare(V, F, h, **kw)
    Vd, info = prepared.solve(V2[h], return_info=True)
    for workers in (1, 2):  # deform's samplings in processes or in this one: the same numbers
        assert np.array_equal(Vd, deform(V, F, h, V2[h], workers=workers, **kw))
    assert info["converged"] and info["solve"] == 0 and np.array_equal(Vd[h], V2[h])


def test_sixty_frames_match_one_shot_deforms_and_reuse_the_set_up(faust_pair):
    """Rest pose to pose 1 in 60 frames, each solve warm-started from the previous frame:
    every frame converged and within 0.05 % of the diagonal (mean) of deform on its targets;
    the low-res Cholesky factors are the ones of the first frame."""
    V, F, h, V2 = faust_pair
    kw = dict(n_low=500, n_samplings=2, seed=0)
    prepared = prepare(V, F, h, **kw)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    factors = None
    for t in np.linspace(1 / 60, 1.0, 60):
        T = V[h] + t * (V2[h] - V[h])
        Vd, info = prepared.solve(T, return_info=True)
        assert info["converged"], info["status"]
        if round(t * 60) % 10 == 0:  # every 10th frame against a one-shot deform
            assert np.linalg.norm(Vd - deform(V, F, h, T, workers=1, **kw), axis=1).mean() < 5e-4 * diag
        now = prepared.factorisations
        factors = factors or now
        assert all(a is b and a is not None for a, b in zip(now, factors, strict=True))
    assert prepared.n_solves == 60


def test_refused_inputs(faust_pair):
    V, F, h, V2 = faust_pair
    prepared = prepare(V, F, h, n_low=500, n_samplings=1)
    with pytest.raises(SShaDeError, match="targets"):
        prepared.solve(V2[h][:-1])
    with pytest.raises(SShaDeError, match="NaN"):
        prepared.solve(np.full((len(h), 3), np.nan))
    far = V2[h].copy()
    far[0, 2] += 1e30 * np.linalg.norm(np.ptp(V, 0))
    with pytest.raises(SShaDeError, match="targets are out of scale: they lie 1e\\+30 x"):
        prepared.solve(far)
    assert prepared.n_solves == 0  # nothing was solved
    with pytest.raises(SShaDeError, match="out of range"):
        prepare(V, F, [0, len(V)], n_low=500)
    two = np.r_[V, V + [2.0, 0, 0]], np.r_[F, F + len(V)]
    with pytest.raises(SShaDeError, match="several connected components"):
        prepare(*two, h, n_low=500)
    with pytest.raises(SShaDeError, match="anchor"):
        prepare(V, F, h, anchor="corner")


@pytest.mark.parametrize("average, transfer", [("uniform", "vertex"), ("proximity", "vertex"),
                                               ("uniform", "triangle")])
def test_threads_do_not_change_the_results(faust_pair, average, transfer):
    """The samplings on one thread or on three (their decodings then added chunk by chunk
    in whatever order the threads end): the same numbers, first solve and later ones
    (their starts extrapolated from the earlier results), uniform or weighted average,
    blended or per-triangle (Alg. 1) transfer."""
    V, F, h, V2 = faust_pair
    kw = dict(n_low=500, n_samplings=3, seed=3, average=average, transfer=transfer)
    with prepare(V, F, h, workers=1, **kw) as one, prepare(V, F, h, workers=3, **kw) as three:
        assert (one.workers, three.workers) == (1, 3)
        for t in (0.25, 0.5, 0.75, 1.0):
            T = V[h] + t * (V2[h] - V[h])
            assert np.array_equal(one.solve(T), three.solve(T))


def test_solves_from_several_threads_each_land_on_their_own_targets(faust_pair):
    """Four threads solving on one prepared object at once (a viewer's callback beside an
    animation loop): each result is within 0.05 % of the diagonal (mean) of a one-shot
    deform of its own targets, and every solve is counted once."""
    import threading
    V, F, h, V2 = faust_pair
    kw = dict(n_low=500, n_samplings=2, seed=0)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    fractions = [0.2, 0.45, 0.7, 0.95]
    results, start = {}, threading.Barrier(len(fractions))

    def caller(t: float) -> None:
        T = V[h] + t * (V2[h] - V[h])
        start.wait()
        for rep in range(2):
            results[t, rep] = prepared.solve(T)

    with prepare(V, F, h, workers=1, **kw) as prepared:
        prepared.solve(V[h])
        threads = [threading.Thread(target=caller, args=(t,)) for t in fractions]
        for th in threads:
            th.start()
        for th in threads:
            th.join(timeout=300)
        assert prepared.n_solves == 1 + 2 * len(fractions)
    assert len(results) == 2 * len(fractions)
    for t in fractions:
        ref = deform(V, F, h, V[h] + t * (V2[h] - V[h]), workers=1, **kw)
        for rep in range(2):
            assert np.linalg.norm(results[t, rep] - ref, axis=1).mean() < 5e-4 * diag, (t, rep)


def test_the_start_follows_the_path_and_stops_with_the_handles(faust_pair):
    """A steady path is extrapolated (degree 2 once three results exist); targets where the
    last solve's were keep its result (degree 0), and so do handles that stop moving."""
    V, F, h, V2 = faust_pair
    with prepare(V, F, h, n_low=500, n_samplings=1) as p:
        degrees = []
        for t in [0.1, 0.2, 0.3, 0.4, 0.5, 0.5, 0.5]:
            _, info = p.solve(V[h] + t * (V2[h] - V[h]), return_info=True)
            degrees.append(info["samplings"][0].get("start_degree"))
    assert degrees[:2] == [None, 0] and degrees[4] == 2 and degrees[5:] == [0, 0], degrees


def _fit_ahead(h, x):
    """The fit through results ``h`` (newest first) at positions ``x``, formed directly."""
    from sshade.prepared import _fit_weights
    c, degree = _fit_weights(x)
    return sum(cj * hj for cj, hj in zip(c, h)), degree


def _pushed(h, pos):
    """A _PathResults holding results ``h`` at positions ``pos`` (both newest first)."""
    from sshade.prepared import _PathResults
    path = _PathResults()
    for x, t in zip(h[::-1], pos[::-1]):
        path.push(x, float(t))
    return path


def test_the_fitted_start_continues_a_quadratic_path_exactly_at_uneven_positions():
    """The least-squares polynomial through twelve results of a path quadratic in its
    position, taken at uneven positions (a smoothstep's), gives the positions at the next
    one to rounding, and so do the interpolating ones through three; through two results
    it continues a straight line; positions that do not move give their results' mean."""
    rng = np.random.default_rng(0)
    a, b, c = rng.normal(size=(3, 40, 3))
    s = np.linspace(0, 1, 14) ** 2 * (3 - 2 * np.linspace(0, 1, 14))
    path = [a + b * t + c * t * t for t in s]
    for r in (12, 3):
        h = path[13 - r:13][::-1]  # newest first
        out, degree = _fit_ahead(h, s[13 - r:13][::-1] - s[13])
        assert degree == 2 and np.allclose(out, path[13], rtol=0, atol=1e-10)
    out, degree = _fit_ahead([a + b * s[1], a + b * s[0]], s[1::-1] - s[2])
    assert degree == 1 and np.allclose(out, a + b * s[2], rtol=0, atol=1e-12)
    out, degree = _fit_ahead([path[3], path[2]], np.zeros(2))
    assert degree == 0 and np.allclose(out, (path[3] + path[2]) / 2, rtol=0, atol=1e-15)


def test_the_fitted_start_caps_its_degree_at_the_distinct_positions():
    """Results at two positions (one repeated: handles stopped, then moved on) are fitted by
    a line, not by a quadratic that the repeated position leaves undetermined."""
    a, b = np.ones((5, 3)), np.arange(15.0).reshape(5, 3)
    h = [a + b, a + b, a + b, a]  # newest first, at positions 1, 1, 1, 0
    out, degree = _fit_ahead(h, np.array([1.0, 1.0, 1.0, 0.0]) - 2.0)
    assert degree == 1 and np.allclose(out, a + 2 * b, rtol=0, atol=1e-12)


def test_the_start_fits_through_the_count_of_results_that_predicted_best():
    """Results on a straight path, each off by a convergence error, are fitted through the
    most results (12: the errors averaged out); exact results on a path that bends fast
    through the fewest (3: a long quadratic cannot follow it). The fit formed from the
    successive differences is the one formed directly, to rounding."""
    from sshade.prepared import START_FITS, START_RESULTS
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 30, 3))
    pos = np.linspace(1.0, 0.0, START_RESULTS) ** 1.5  # newest first, uneven
    at = 1.08
    noisy = [a + b * t + 1e-3 * rng.normal(size=a.shape) for t in pos]
    bent = [a * np.cos(6 * t) + b * np.sin(6 * t) for t in pos]
    for h, r in ((noisy, START_FITS[-1]), (bent, START_FITS[0])):
        start, degree = _pushed(h, pos).start(at)
        assert degree == 2 and np.allclose(start, _fit_ahead(h[:r], pos[:r] - at)[0], rtol=0, atol=1e-12), r


def test_the_start_after_more_solves_than_kept_is_the_directly_scored_one():
    """Twenty results pushed (the ring of differences wrapped): the start is the one chosen
    and formed directly from the newest kept results, each candidate's prediction error
    computed as the norm of its difference from the newest result."""
    from sshade.prepared import START_FITS, START_RESULTS
    rng = np.random.default_rng(3)
    a, b, c = rng.normal(size=(3, 25, 3))
    pos = np.cumsum(rng.uniform(0.5, 1.5, 20))[::-1] / 20  # newest first
    h = [a + b * t + c * np.sin(3 * t) + 1e-4 * rng.normal(size=a.shape) for t in pos]
    path = _pushed(h, pos)
    kh, kp, at = h[:START_RESULTS], pos[:START_RESULTS], pos[0] + 0.06
    best, err = 0, np.linalg.norm(kh[1] - kh[0])
    for r in START_FITS:
        e = np.linalg.norm(_fit_ahead(kh[1:r + 1], kp[1:r + 1] - kp[0])[0] - kh[0])
        best, err = (r, e) if e < err else (best, err)
    start, degree = path.start(at)
    assert best > 0 and degree == 2
    assert np.allclose(start, _fit_ahead(kh[:best], kp[:best] - at)[0], rtol=0, atol=1e-12)


def test_the_handles_moves_extend_a_translation_exactly(faust_pair):
    """The harmonic extension of the handles' moves (the later frames' start) carries the
    free vertices along a common translation of every handle exactly (the Laplacian's rows
    sum to zero), and puts the handle rows at their targets."""
    from sshade.prepared import _HandleMoves
    V, F, h, _ = faust_pair
    moves = _HandleMoves(V, F, h)
    t = np.array([0.3, -0.2, 0.1])
    U = moves.extend(V, V[h] + t)
    assert np.allclose(U, V + t, rtol=0, atol=1e-12) and np.array_equal(U[h], V[h] + t)


def test_the_extended_start_keeps_the_frames_of_the_handle_rows_start_within_a_bound(faust_pair, monkeypatch):
    """Later frames start with the free vertices moved with the handles and a window of 32:
    not the numbers of the start whose handle rows alone jump (window 16, the earlier
    default), but each frame within 2e-6 of the diagonal (mean) of that one, both
    converged. (Iteration counts: benchmarks/records/frames_scalar_decode.md, on the
    benchmark's meshes over several seeds; on a path this short they are within noise.)"""
    import sshade.prepared as prepared_module
    V, F, h, V2 = faust_pair
    kw = dict(n_low=500, n_samplings=2, seed=1, workers=1)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    path = [V[h] + t * (V2[h] - V[h]) for t in np.linspace(0.05, 1.0, 20)]

    def frames():
        with prepare(V, F, h, **kw) as p:
            return [p.solve(T, return_info=True) for T in path]

    new = frames()
    monkeypatch.setattr(prepared_module._HandleMoves, "extend", lambda self, U0, targets: U0)
    monkeypatch.setitem(prepared_module.FRAME_ACCELERATION, "history", 16)
    old = frames()
    assert np.array_equal(new[0][0], old[0][0])  # the first solve: deform's, bit for bit
    assert all(a[1]["converged"] and b[1]["converged"] for a, b in zip(new, old))
    gap = [np.linalg.norm(a[0] - b[0], axis=1).mean() / diag for a, b in zip(new, old)]
    assert max(gap) < 2e-6 and max(gap[1:]) > 0, gap


def test_a_closed_prepared_refuses_to_solve(faust_pair):
    V, F, h, V2 = faust_pair
    with prepare(V, F, h, n_low=500, n_samplings=2, workers=2) as p:
        p.solve(V2[h])
    with pytest.raises(SShaDeError, match="closed"):
        p.solve(V2[h])


_BLAS_PROBE = r"""
import os, threading, time, numpy as np, trimesh
from sshade import prepare

def others_ticks():  # CPU ticks of this process's threads that Python did not start
    py = {t.native_id for t in threading.enumerate()}
    total = 0
    for tid in os.listdir("/proc/self/task"):
        if int(tid) not in py:
            with open(f"/proc/self/task/{tid}/stat") as f:
                total += sum(int(v) for v in f.read().rsplit(")", 1)[1].split()[11:13])
    return total

m = trimesh.creation.icosphere(subdivisions=5)
V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
h = np.flatnonzero(np.abs(V[:, 2]) > 0.95)
with prepare(V, F, h, n_low=7000, n_samplings=2, seed=0, workers=2) as p:
    p.solve(V[h])
    c0, t0 = others_ticks(), time.perf_counter()
    for i in range(1, 13):
        T = V[h].copy()
        T[V[h, 2] > 0, 2] += 0.02 * i
        p.solve(T)
    wall = (time.perf_counter() - t0) * os.sysconf("SC_CLK_TCK")
print(others_ticks() - c0, wall)
"""


@pytest.mark.skipif(not __import__("os").path.isdir("/proc/self/task"), reason="needs Linux's /proc")
def test_solves_leave_native_worker_threads_idle():
    """A solve's threads are the only busy ones: no library thread (OpenBLAS's, whose
    workers spin for a while after a threaded call, e.g. ``np.linalg.norm`` of a large
    array) takes a core from them between frames. Run in a fresh process, where only the
    solves can have woken such a thread."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _BLAS_PROBE], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    busy, wall = map(float, out.stdout.split()[-2:])
    assert busy <= 0.1 * wall + 2, f"threads not started by Python ran {busy:.0f} of {wall:.0f} ticks"


def test_a_solve_after_an_interrupted_one_waits_for_its_decodings_and_lands_as_without(faust_pair, monkeypatch):
    """Ctrl-C in the calling thread while a solve's tasks run (here: right after they are
    queued): the tasks go on, and the next solve waits for all of them, the decoding chunks
    their ARAPs queued meanwhile included, before it touches the samplings: its result is
    the one of the same solves uninterrupted."""
    import sshade.prepared as prepared_module
    V, F, h, V2 = faust_pair
    kw = dict(n_low=500, n_samplings=3, seed=3, workers=2)
    path = [V[h] + t * (V2[h] - V[h]) for t in (0.3, 0.6, 0.9)]
    with prepare(V, F, h, **kw) as p:
        want = [p.solve(T) for T in path]
    real_wait = prepared_module.Prepared._wait

    def interrupted(futs):
        raise KeyboardInterrupt

    with prepare(V, F, h, **kw) as p:
        assert np.array_equal(p.solve(path[0]), want[0])
        monkeypatch.setattr(prepared_module.Prepared, "_wait", staticmethod(interrupted))
        with pytest.raises(KeyboardInterrupt):
            p.solve(path[1])
        monkeypatch.setattr(prepared_module.Prepared, "_wait", staticmethod(real_wait))
        assert np.array_equal(p.solve(path[2]), want[2])

"""ARAP-SR's fused local step and its numbering (sshade/arap/sr_local.py): the same
rotations, energies and right-hand sides as the scipy / numpy formulas, bit for bit, and
a chunked Gauss-Seidel order that is still a descent sweep to the same minimiser."""
from __future__ import annotations

import numpy as np
import pytest

from sshade.arap import DEEP_CRITERION, ArapOptions, SRProblem, solve_arap_sr
from sshade.arap.problems import twisted_bar

TWISTED = {"angle_deg": 90.0, "h": 0.12}


@pytest.mark.parametrize("reorder", [False, True])
@pytest.mark.parametrize("alpha", [0.0, 0.05])
@pytest.mark.parametrize("jacobi", [False, True])
def test_fused_local_step_equals_numpy_path_bit_for_bit(monkeypatch, alpha, jacobi, reorder):
    """SRProblem.local_step's one numba pass (covariances, the neighbours' rotations,
    polar decompositions, cell energies) gives the rotations and the energy of the scipy
    and numpy path (its fallback) to the last bit, Gauss-Seidel and Jacobi, alpha 0 too,
    in the mesh's numbering and in the cache-friendly one of large meshes."""
    from sshade.arap import kernels, smooth_rotations

    monkeypatch.setattr(smooth_rotations, "REORDER_MIN_VERTICES", 0 if reorder else 10 ** 9)
    V, F, h, T = twisted_bar(**TWISTED)
    U = V + 0.05 * np.random.default_rng(3).standard_normal(V.shape)
    R0 = SRProblem(V, F, h, T, alpha).ops.rotations(V + 0.02 * np.random.default_rng(4).standard_normal(V.shape))
    pb = SRProblem(V, F, h, T, alpha)
    assert pb.fused is not None and np.array_equal(np.sort(pb.fused.perm), np.arange(pb.n))
    R_fused, E_fused = pb.local_step(U, R0.copy(), jacobi)
    monkeypatch.setattr(kernels, "_SR_LOCAL", {1: False, 2: False})
    pb_np = SRProblem(V, F, h, T, alpha)
    assert pb_np.fused is None
    R_np, E_np = pb_np.local_step(U, R0.copy(), jacobi)
    assert np.array_equal(R_fused, R_np) and E_fused == E_np == pb_np.energy(U, R_np)
    B = pb.ops.rhs(R_np)
    assert np.array_equal(pb.work_rhs(pb.to_work(R_np)), B) and np.array_equal(pb_np.work_rhs(R_np), B)


def test_gauss_seidel_order_is_the_colour_classes_and_the_solve_reaches_the_same_minimiser(monkeypatch):
    """The Gauss-Seidel batches are the colour classes in turn (each an independent set,
    every cell once), in the kernel's numbering a sweep never raises the energy, and the
    converged protocol there (Anderson's vectors in that numbering) reaches the mesh
    numbering's minimiser."""
    from sshade.arap import smooth_rotations

    V, F, h, T = twisted_bar(**TWISTED)
    want = solve_arap_sr(V, F, h, T, ArapOptions(alpha=0.05, criterion=DEEP_CRITERION))
    monkeypatch.setattr(smooth_rotations, "REORDER_MIN_VERTICES", 0)
    pb = SRProblem(V, F, h, T, 0.05)
    cells, bptr = pb.fused.gs
    assert np.array_equal(np.sort(cells), np.arange(pb.n)) and len(bptr) == len(pb.classes) + 1
    edges = pb.fused.inv[pb.ops.edges]  # the kernel's numbering
    for b in range(len(bptr) - 1):
        inside = np.zeros(pb.n, bool)
        inside[cells[bptr[b]:bptr[b + 1]]] = True
        assert not (inside[edges[:, 0]] & inside[edges[:, 1]]).any()
        assert np.array_equal(np.sort(pb.fused.perm[cells[bptr[b]:bptr[b + 1]]]), pb.classes[b])
    U = V + 0.05 * np.random.default_rng(0).standard_normal(V.shape)
    R, E = pb.local_step(U, pb.ops.rotations(U))
    for _ in range(5):
        R, En = pb.local_step(U, R)
        assert En <= E * (1 + 1e-13)
        E = En
    got = solve_arap_sr(V, F, h, T, ArapOptions(alpha=0.05, criterion=DEEP_CRITERION), problem=pb)
    assert got.info["status"] in ("converged", "stalled") and got.info["gnorm"] < 1e-6  # stalled: float64's floor
    assert abs(got.info["energy"] - want.info["energy"]) <= 1e-12 * want.info["energy"]
    assert np.abs(got.V - want.V).max() < 1e-8 * np.ptp(V, 0).max()


def test_two_threads_sharing_a_problem_get_each_their_own_local_step(monkeypatch):
    """The fused local step keeps no state between calls (its scratch is the call's): two
    threads sweeping different states of one problem at once get what each gets alone."""
    from concurrent.futures import ThreadPoolExecutor

    from sshade.arap import smooth_rotations

    monkeypatch.setattr(smooth_rotations, "REORDER_MIN_VERTICES", 0)
    V, F, h, T = twisted_bar(**TWISTED)
    pb = SRProblem(V, F, h, T, 0.05)
    rng = np.random.default_rng(5)
    states = [(V + 0.05 * rng.standard_normal(V.shape), pb.ops.rotations(V + 0.02 * rng.standard_normal(V.shape)))
              for _ in range(2)]
    alone = [pb.local_step(U, R.copy()) for U, R in states]
    for _ in range(3):
        with ThreadPoolExecutor(2) as ex:
            both = list(ex.map(lambda st: pb.local_step(st[0], st[1].copy()), states))
        for (Ra, Ea), (Rb, Eb) in zip(alone, both):
            assert np.array_equal(Ra, Rb) and Ea == Eb


@pytest.mark.parametrize("jacobi", [False, True])
def test_parallel_local_step_gives_the_serial_bits_at_every_share_count(monkeypatch, jacobi):
    """The local step on numba's threads (:func:`sshade.arap.kernels.sr_local_kernel` with
    ``parallel``), its runs of cells split into 1, 2, 3 or 7 shares, sets the serial
    kernel's rotations and cell energies to the last bit, Jacobi and Gauss-Seidel, and
    ``SRProblem.local_step`` on two threads gives the serial one's rotations and energy."""
    import numba

    from sshade.arap import kernels, smooth_rotations
    from sshade.arap.threads import max_threads, numba_threads

    monkeypatch.setattr(smooth_rotations, "REORDER_MIN_VERTICES", 0)
    V, F, h, T = twisted_bar(**TWISTED)
    pb = SRProblem(V, F, h, T, 0.05)
    f = pb.fused
    rng = np.random.default_rng(6)
    U = V + 0.05 * rng.standard_normal(V.shape)
    Rk = f.to_kernel(pb.ops.rotations(V + 0.02 * rng.standard_normal(V.shape)))
    Uk = np.ascontiguousarray(U[f.perm])
    order = f.jacobi_order if jacobi else f.gs

    def run(kern, *nt):
        R = Rk.copy()
        Ek = np.empty(f.n)
        kern(Uk, *f.kd.local_arrays(), *order, *f.graph, f.wR, Rk.copy() if jacobi else R, R,
             np.empty((f.n, 3, 3)), Ek, *nt)
        return R, Ek
    R1, E1 = run(kernels.sr_local_kernel())
    threads = min(2, max_threads(), numba.config.NUMBA_NUM_THREADS)
    for shares in (1, 2, 3, 7):
        with numba_threads(threads):
            R2, E2 = run(kernels.sr_local_kernel(True), shares)
        assert np.array_equal(R1, R2) and np.array_equal(E1, E2), shares
    R0 = pb.ops.rotations(V)
    want = pb.local_step(U, R0.copy(), jacobi)
    f.threads = threads
    got = pb.local_step(U, R0.copy(), jacobi)
    assert np.array_equal(want[0], got[0]) and want[1] == got[1]

"""Prepare once, solve every frame: SShaDe split by what depends on the handles' targets
(paper §3), for animations and handles dragged in a viewer.

:func:`prepare` does per sampling what the targets do not enter (remesh and projection
§3.1, local coordinates §3.2, the low-res ARAP's deformer) and returns a :class:`Prepared`;
:meth:`Prepared.solve` runs per sampling the low-res ARAP and the decoding (Alg. 1) and
averages them (§3.3). The first solve is :func:`sshade.deform` of the same parameters, bit
for bit; later ones start from the earlier results extrapolated along the targets' path
(:data:`FRAME_ACCELERATION`).
Starts, threads and timings: docs/implementation.md ("Implementation notes: sshade/prepared.py").
"""
from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import replace

import igl
import numpy as np

from .arap import ArapDeformer, ArapOptions, LaplacianSolver, beside_others
from .averaging import combine, proximity_weights, sampling_weights
from .cores import pool_size
from .errors import SShaDeError
from .lrf import decode_with_frames, deformed_frames, encode, frame_functions
from .mesh.bounds import bounding_box
from .mesh.halfedge import count_components, large_mesh
from .mesh.unit_frame import UnitFrame, unit_frame
from .mesh.validate import validate_handle_indices, validate_mesh, validate_targets
from .params import SShaDeParams, check_params
from .pipeline import SamplingJob, handle_pre_pct, low_res_size, prepare_samplings
from .remesh import mesh_topology
from .sampling import sampling_seeds, warm_kernels
from .smooth_transfer import corner_maps, jacobian_rest, smooth_decode_with, smooth_offsets, vertex_jacobians

__all__ = ["prepare", "prepare_with", "Prepared", "FRAME_ACCELERATION"]

#: The low-res ARAP's acceleration from the second solve on under the converged protocol
#: (fields ``accelerate`` and ``history`` of :class:`sshade.arap.ArapOptions`), with the history kept
#: from solve to solve (``carry_history``); the first solve keeps
#: :func:`sshade.pipeline.deform`'s L-BFGS, so that it is ``deform`` bit for bit. From a start
#: as near as the extrapolated one, Anderson acceleration met the same stopping rule in
#: fewer iterations than L-BFGS on both meshes of ``benchmarks/frames.py``, and a window of
#: 32 in fewer than one of 16 or 8 (a longer one saved almost no more iterations;
#: benchmarks/records/frames_scalar_decode.md).
FRAME_ACCELERATION = {"accelerate": "anderson", "history": 32}


#: How many results a later solve's start may be fitted through: the count whose fit
#: best predicted the newest result from those before it (:meth:`_Sampling.start`).
START_FITS = (3, 5, 8, 12)
#: Results kept per sampling: the longest fit's and the newest one it is checked against.
START_RESULTS = START_FITS[-1] + 1
#: Path positions closer than this share of the fitted span count as one point when the
#: fit's degree is capped at the distinct points less one (:func:`_fit_ahead`).
DISTINCT_POSITIONS = 1e-3


def _fit_weights(x: np.ndarray, most: int = 2) -> tuple[np.ndarray, int]:
    """The weights ``c`` ((r,) float64) with which the least-squares polynomial of degree
    at most ``most`` through r results at path positions ``x`` ((r,) float64, relative to
    the position predicted) gives its value there, ``sum_j c_j h_j``, and its degree: at
    most the distinct positions less one (:data:`DISTINCT_POSITIONS`); positions all equal
    give their mean. The weights sum to 1 (to rounding): a constant path is continued."""
    span = float(np.abs(x).max())
    degree = 0
    if span > 0:
        x = x / span
        degree = min(most, int(np.count_nonzero(np.diff(np.sort(x)) > DISTINCT_POSITIONS)))
    c = np.linalg.pinv(np.vander(x, degree + 1, increasing=True))[0] if degree else np.full(len(x), 1 / len(x))
    return c, degree


class _PathResults:
    """One sampling's last low-res results along the targets' path (at most
    :data:`START_RESULTS`, newest first) and their path positions, with the differences of
    successive results and their inner products, so that a start's candidate fits are scored
    and the chosen one formed in one pass over the results each (:meth:`start`).

    A fit's prediction error is ``sum_j w_j h_j`` with weights summing to zero, that is
    ``sum_i W_i d_i`` over the differences ``d_i = h_i - h_(i+1)`` (``W`` the running sums of
    ``w``): its squared norm is ``W' D W``, ``D`` the differences' Gram matrix, small numbers
    with no cancellation against the positions.
    """

    def __init__(self, keep: int = START_RESULTS):
        self.keep = keep
        self.results: list = []  # (k, 3) float64 results, newest first
        self.at: list = []  # their path positions
        self.slots: list = []  # the slot in ``diffs`` of d_0, d_1, ...
        self.diffs: np.ndarray | None = None  # (keep - 1, k, 3) by slot
        self.gram = np.zeros((keep - 1, keep - 1))  # inner products of the slots' differences

    def push(self, x: np.ndarray, at: float) -> None:
        """Add the newest result ``x`` ((k, 3) float64, kept, not copied) at position ``at``."""
        if self.results:
            if self.diffs is None:
                self.diffs = np.zeros((self.keep - 1, *x.shape))
            m = len(self.diffs)
            slot = self.slots[-1] if len(self.slots) == m else len(self.slots)
            np.subtract(x, self.results[0], out=self.diffs[slot])
            row = np.einsum("rij,ij->r", self.diffs, self.diffs[slot])
            self.gram[slot, :] = row
            self.gram[:, slot] = row
            self.slots = [slot] + self.slots[:m - 1]
        self.results = [x] + self.results[:self.keep - 1]
        self.at = [at] + self.at[:self.keep - 1]

    def _error(self, c: np.ndarray) -> float:
        """Squared norm of ``sum_j c_j h_(j+1) - h_0`` (``c`` summing to 1)."""
        W = np.cumsum(np.r_[-1.0, c])[:len(c)]
        idx = self.slots[:len(c)]
        return float(W @ self.gram[np.ix_(idx, idx)] @ W)

    def _combine(self, c: np.ndarray) -> np.ndarray:
        """``sum_j c_j h_j`` over the newest ``len(c)`` results, as ``(sum c) h_0 - sum_i
        T_i d_i``, ``T_i = sum_(j > i) c_j``: a new (k, 3) array."""
        coef = np.zeros(len(self.gram))
        coef[self.slots[:len(c) - 1]] = np.cumsum(c[::-1])[::-1][1:]
        out = np.einsum("r,rij->ij", coef, self.diffs)
        np.subtract(self.results[0] * float(c.sum()), out, out=out)
        return out

    def start(self, at: float) -> tuple[np.ndarray, int]:
        """The start at path position ``at`` and its degree: :meth:`_Sampling.start`."""
        h, pos = self.results, np.asarray(self.at)
        if len(h) == 1 or pos[0] == at:
            return h[0], 0
        best, err = 0, float(self.gram[self.slots[0], self.slots[0]])
        for r in START_FITS:
            r = min(r, len(h) - 1)
            e = self._error(_fit_weights(pos[1:r + 1] - pos[0])[0])
            if e < err:
                best, err = r, e
            if r == len(h) - 1:
                break
        if best == 0:
            return h[0], 0
        c, degree = _fit_weights(pos[:best] - at)
        return self._combine(c), degree


def _norm(a: np.ndarray) -> float:
    """Euclidean norm of ``a`` without BLAS: ``np.linalg.norm`` of a large array calls
    OpenBLAS's threaded dot, whose worker thread then spins for a while after the call,
    taking a core from the solve's threads at every frame."""
    return float(np.sqrt(np.einsum("ij,ij->", a, a)))


def _done(fn, x) -> Future:
    """``fn(x)`` run here, as a finished future (its result or its exception)."""
    f = Future()
    try:
        f.set_result(fn(x))
    except Exception as e:  # noqa: BLE001 (re-raised by result, as a pool's future does)
        f.set_exception(e)
    return f


class _HandleMoves:
    """The harmonic extension of the handles' moves on a low-res mesh: a start whose handle
    rows move to the targets takes its free vertices along, ``d_f = -L_ff^-1 L_fb d_h``
    (``L = -igl.cotmatrix``, the Laplacian of the ARAP global step, factored once), so that
    it has no kink at the handles for the iterations to smooth out.

    Parameters
    ----------
    VN : (k, 3) float64 low-res vertices. F : (t, 3) int64 low-res faces.
    handles : (h,) int64 low-res handle vertices, in the targets' order.
    """

    def __init__(self, VN: np.ndarray, F: np.ndarray, handles: np.ndarray):
        L = (-igl.cotmatrix(VN, F)).tocsr()
        self.h = np.asarray(handles, np.int64)
        self.free = np.setdiff1d(np.arange(len(VN)), self.h)
        self.Lfb = L[self.free][:, self.h].tocsr()
        self.lin = LaplacianSolver(L[self.free][:, self.free]) if len(self.free) else None

    def extend(self, U0: np.ndarray, targets: np.ndarray) -> np.ndarray:
        """``U0`` ((k, 3) float64) with its handle rows at ``targets`` ((h, 3) float64) and
        its free rows moved by the harmonic extension of those moves: a new array."""
        U = np.array(U0, dtype=np.float64)
        if self.lin is not None:
            U[self.free] += self.lin.solve(np.ascontiguousarray(-(self.Lfb @ (targets - U[self.h]))))
        U[self.h] = targets
        return U


class _Sampling:
    """One sampling's prepared state: its low-res mesh and projection (``prep``), the
    frames' axis and local coordinates, its ARAP deformer, its last low-res results."""

    def __init__(self, V, prep: dict, info: dict, p: SShaDeParams):
        self.prep, self.info, self.V = prep, info, V
        self.VN = V[prep["seeds"]]
        self.bary = prep["bary"] if p.anchor == "projection" else None
        self.axis = frame_functions(self.VN, prep["F"])
        self.gradient, self.transfer, self.average = p.gradient, p.transfer, p.average
        self.proximity = (proximity_weights(V, prep["tri"], self.bary, self.VN, prep["F"])
                          if p.average == "proximity" else None)
        if p.transfer == "triangle":
            self.C = encode(V, prep["tri"], self.VN, prep["F"], self.axis, p.gradient, self.bary)
        else:  # the blended transfer's rest parts, known before the targets
            self.g = smooth_offsets(V, prep["tri"], self.bary, self.VN, prep["F"])
            self.jac_rest = jacobian_rest(self.VN, prep["F"])
        self.arap = ArapDeformer(self.VN, prep["F"], prep["low_handles"], p.arap_options())
        self.moves = _HandleMoves(self.VN, prep["F"], prep["low_handles"])
        self.path = _PathResults()  # the last results and their path positions (Prepared.solve)
        self.last_iterations = 0  # of the last solve

    def start(self, at: float) -> tuple[np.ndarray, int]:
        """The start of the solve at path position ``at`` (:meth:`Prepared.solve`: the arc
        length of the targets' path), (k, 3), and its degree: the last result (degree 0),
        or the least-squares polynomial of degree at most 2 through the newest ``r``
        results at their path positions evaluated at ``at`` (:func:`_fit_weights`), ``r`` of
        :data:`START_FITS`: whichever predicted the newest result best from the results
        before it (least Euclidean distance, scored by :class:`_PathResults`; a tie keeps
        the fewer results, the last result first). A smooth path takes a fit, a handle
        that stops the last result; targets where the last solve's were keep its result.
        Fitting over the arc length rather than the frame number follows a path that slows
        down or speeds up (a smoothstep); a long fit damps the results' convergence errors
        on a path that bends slowly, a short one follows one that bends faster
        (benchmarks/records/frames_arc_length_start.md)."""
        return self.path.start(at)

    def solve(self, targets, at: float, V0, arap: ArapOptions, carry: bool = False) -> dict:
        """The low-res ARAP at path position ``at`` (:meth:`start`) from ``V0`` ((k, 3) or
        None: the rigid fit); when ``carry`` (a
        later frame) with the last solve's accelerator history and ``V0``'s free vertices
        moved with its handle rows to the targets (:class:`_HandleMoves`): the info of the
        ARAP run. Its result's frames are made by the first :meth:`decode` after it (on
        the decoding thread)."""
        t0 = time.perf_counter()
        if carry and V0 is not None:
            V0 = self.moves.extend(V0, targets)
        with beside_others():  # the samplings' solves share the cores (sshade.arap.threads)
            res = self.arap.deform(targets, options=arap, U0=V0, carry_history=carry)
        self.low, self.frames = res.V, None
        self.path.push(res.V, at)
        self.last_iterations = res.iterations
        return {"arap_s": time.perf_counter() - t0, "iterations": res.iterations, "converged": res.converged,
                "status": res.info.get("status"), "warm_start": V0 is not None}

    def make_frames(self):
        """The last solve's frames (Alg. 1) or corners' affine maps (``transfer="vertex"``:
        :func:`sshade.smooth_transfer.corner_maps`), made by the first call after the solve
        (threads racing here compute the same ones): what :meth:`decode` applies."""
        if self.frames is None:
            if self.transfer == "vertex":
                Jv = vertex_jacobians(self.VN, self.low, self.prep["F"], rest=self.jac_rest)
                self.frames = corner_maps(Jv, self.VN, self.low)
            else:
                self.frames = deformed_frames(self.VN, self.low, self.prep["F"], self.axis, self.gradient)
        return self.frames

    def decode(self, rows=None, out: np.ndarray | None = None, add: bool = False) -> np.ndarray:
        """The last solve's high-res positions at ``rows`` (Alg. 1, or
        :func:`sshade.smooth_transfer.smooth_decode_with` for ``transfer="vertex"``;
        :func:`sshade.lrf.decode_with_frames`: rows, out and add as there)."""
        frames = self.make_frames()
        if self.transfer == "vertex":
            return smooth_decode_with(frames, self.g, self.prep["tri"], self.bary, self.prep["F"],
                                      rows=rows, out=out, add=add)
        return decode_with_frames(frames, self.C, self.prep["tri"], self.low, self.prep["F"], self.bary,
                                  rows=rows, out=out, add=add)

    def weights(self, rows=None) -> np.ndarray | None:
        """The last solve's averaging weights at ``rows`` ((r,) float64), or None for the
        uniform mean (:func:`sshade.averaging.sampling_weights`)."""
        if self.proximity is not None:  # known before the targets: made once, in __init__
            return self.proximity if rows is None else self.proximity[rows]
        idx = slice(0, len(self.V)) if rows is None else rows
        bary = None if self.bary is None else self.bary[idx]
        return sampling_weights(self.average, self.V[idx], self.prep["tri"][idx], bary, self.VN, self.low,
                                self.prep["F"])


class _Average:
    """One solve's decodings averaged chunk by chunk of rows, on the ARAP threads.

    Sampling ``i``'s decoding of chunk ``c`` (:meth:`decode`, queued when its ARAP ends,
    so behind the ARAPs still waiting: a thread left without an ARAP decodes for the
    others) goes onto ``out[c]`` when it is the chunk's next in sampling order, else aside
    until the chunk's earlier ones are added: so every row gets the additions of
    :func:`sshade.sampling.average` (sampling order), whatever order the threads run in.
    The thread adding a chunk's last decoding divides it by ``k`` and maps it out of the
    unit frame. A weighted average (``average`` not ``"uniform"``) keeps every decoding
    whole in ``parts`` ((k, n, 3)) for :func:`sshade.averaging.combine`.
    """

    def __init__(self, n: int, k: int, chunks: int, weighted: bool, frame: UnitFrame):
        self.k, self.frame, self.weighted = k, frame, weighted
        self.out = np.empty((n, 3))
        self.parts = np.empty((k, n, 3)) if weighted else None
        self.chunks = chunks
        self.bounds = np.linspace(0, n, chunks + 1).astype(np.int64)
        self.lock = threading.Lock()
        self.nxt = [0] * chunks  # the next sampling to add onto each chunk
        self.busy = [False] * chunks  # a thread is adding onto the chunk
        self.aside: list[dict] = [{} for _ in range(chunks)]

    def decode(self, sampling: _Sampling, i: int, c: int) -> float:
        """Sampling ``i``'s decoding of chunk ``c``, added in order (class docstring): its seconds."""
        t = time.perf_counter()
        rows = slice(int(self.bounds[c]), int(self.bounds[c + 1]))
        if self.weighted:
            sampling.decode(rows, self.parts[i, rows])
            return time.perf_counter() - t
        with self.lock:
            mine = not self.busy[c] and self.nxt[c] == i
            self.busy[c] |= mine
        if mine:
            sampling.decode(rows, self.out[rows], add=i > 0)
        else:
            a = sampling.decode(rows)
            with self.lock:
                mine = not self.busy[c] and self.nxt[c] == i
                self.busy[c] |= mine
                if not mine:
                    self.aside[c][i] = a
            if mine:
                self._add(rows, i, a)
        if mine:
            self._drain(c, rows)
        return time.perf_counter() - t

    def _add(self, rows: slice, i: int, a: np.ndarray) -> None:
        if i == 0:
            self.out[rows] = a
        else:
            self.out[rows] += a

    def _drain(self, c: int, rows: slice) -> None:
        """After an addition onto chunk ``c`` (its thread holds ``busy``): the decodings
        set aside for it in order, then, with all ``k`` added, the chunk's average in mesh
        units; ``busy`` released when the next one is not there yet."""
        while True:
            with self.lock:
                self.nxt[c] += 1
                i = self.nxt[c]
                a = self.aside[c].pop(i, None)
                if a is None:
                    self.busy[c] = False
                    break
            self._add(rows, i, a)
        if i == self.k:
            chunk = self.out[rows]
            chunk /= self.k
            self.frame.from_unit(chunk, out=chunk)


class Prepared:
    """SShaDe prepared for one mesh and one handle set (:func:`prepare`); a context manager
    (leaving it, or :meth:`close`, ends the worker threads; a later solve refuses).

    Attributes
    ----------
    V, F, handles : (n, 3) float64, (m, 3) int64, (h,) int64
        The validated inputs.
    params : SShaDeParams
        The checked parameters (:class:`sshade.params.SShaDeParams`).
    workers : int
        Threads the samplings run on.
    prepare_s : float
        Seconds :func:`prepare` took.
    n_solves : int
        Solves so far.
    frame : UnitFrame
        The :class:`sshade.mesh.unit_frame.UnitFrame` the samplings are held in (targets
        are mapped into it, results out of it).

    Solves from several threads at once are run one after the other (a lock per object):
    each starts from the samplings' state the one before left, as in one thread, so each
    result is that of its own targets.
    """

    def __init__(self, V, F, handles, params: SShaDeParams, samplings: list, prepare_s: float, pool, workers: int,
                 frame: UnitFrame):
        self.V, self.F, self.handles, self.params = V, F, handles, params
        self.frame = frame  # the samplings live in V's unit frame (sshade.mesh.unit_frame)
        self._samplings, self.prepare_s = samplings, prepare_s
        self._pool, self.workers, self._pending = pool, workers, []
        self._arap = params.arap_options()
        self._frame_arap = (replace(self._arap, **FRAME_ACCELERATION) if self._arap.protocol == "converged"
                            else self._arap)
        self.n_solves = 0
        self._path, self._last_T = 0.0, None  # the targets' path so far (arc length, unit frame), its last point
        self._corners = np.array(bounding_box(V))  # V's bounding box, for the per-solve checks
        self._unit_corners = frame.to_unit(self._corners)
        self._lock = threading.Lock()  # one solve at a time: the samplings' state is the previous solve's

    def __enter__(self) -> Prepared:
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def __del__(self):
        self.close()

    def close(self) -> None:
        """End the worker threads (after the sampling they run, if any)."""
        pool, self._pool = getattr(self, "_pool", None), None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)

    @property
    def factorisations(self) -> list:
        """Each sampling's factorised low-res ``L_ff`` (None before its first solve that
        needs one, and under the paper protocol): the same objects for every solve."""
        return [s.arap.factorisation for s in self._samplings]

    def _submit(self, fn, items, order=None) -> list:
        """Futures of ``fn(x)`` for the ``items`` (in their order), on the ARAP threads
        (``workers`` of them), started in ``order`` (positions in ``items``; default theirs),
        or done here in order with one worker."""
        if self._pool is None:
            raise SShaDeError("this prepared SShaDe was closed; prepare again")
        items = list(items)
        if self.workers == 1:
            return [_done(fn, x) for x in items]
        futs = [None] * len(items)
        for j in (range(len(items)) if order is None else order):
            futs[j] = self._pool.submit(fn, items[j])
        self._pending += futs
        return futs

    def _settle(self) -> None:
        """Wait for every task of the solves before, the decoding chunks their ARAP tasks
        queued while this waited included (a task adds its chunks before it ends, so none
        is left once every listed task is done), then forget them."""
        while True:
            running = [f for f in self._pending if not f.done()]
            if not running:
                break
            wait(running)
        self._pending = []

    def solve(self, targets, *, return_info: bool = False):
        """Deform for ``targets`` ((h, 3) float, one per handle, in :attr:`handles`' order).
        From the second solve on each sampling starts from its earlier results fitted over
        the targets' path: the arc length of the solves' targets so far (the sum of the
        Euclidean distances between successive targets, all handles together;
        :meth:`_Sampling.start`); the result is that of the stopping rule whatever the start.

        Returns
        -------
        (n, 3) float64 deformed positions (handles at their targets); with ``return_info``
        ``(Vd, info)``: ``total_s`` (wall seconds of this solve), ``arap_s`` and
        ``iterations`` summed over the samplings, ``transfer_s`` (seconds of the decoding
        and the average, all samplings; beside later samplings' ARAP with several
        workers), ``converged`` (every sampling's low-res ARAP met its stopping rule),
        ``status``, ``handle_pre_pct``, ``solve`` (0 for the first), ``workers``,
        per-sampling details in ``samplings`` (``start_degree`` from the second solve
        on: :meth:`_Sampling.start`).

        Raises
        ------
        SShaDeError on targets of the wrong shape or with NaN/inf
        (:func:`sshade.mesh.validate.validate_targets`), or after :meth:`close`.

        Thread-safe: a solve called while another runs on this object waits for it.
        """
        T = validate_targets(self._corners, len(self.handles), targets)
        with self._lock:
            return self._solve(T, return_info)

    def _solve(self, T_mesh: np.ndarray, return_info: bool):
        T = self.frame.to_unit(T_mesh)
        t0 = time.perf_counter()
        if self._last_T is not None:
            self._path += _norm(T - self._last_T)
        self._last_T, at = T, self._path
        self._settle()  # an interrupted solve's tasks end before their samplings are reused
        first, S = self.n_solves == 0, self._samplings
        arap, first_arap = self._arap, Future()
        avg = _Average(len(self.V), len(S), 2 * self.workers if self.workers > 1 else 1,
                       self.params.average != "uniform", self.frame)

        def decoded(i: int, info: dict) -> tuple[dict, list, float]:
            """Sampling i's ARAP info, the futures of its decoding's chunks (queued) and the
            seconds of its frames, made here first (once, not by each chunk's thread)."""
            t = time.perf_counter()
            S[i].make_frames()
            frames_s = time.perf_counter() - t
            return info, self._submit(lambda c: avg.decode(S[i], i, c), range(avg.chunks)), frames_s

        def run(i: int, V0) -> tuple:
            try:
                info = S[i].solve(T, at, V0, arap)
            except BaseException as e:
                if i == 0:
                    first_arap.set_exception(e)
                raise
            if i == 0:
                first_arap.set_result(None)
            return decoded(i, info)

        def later(i: int) -> tuple:  # the earlier frames extrapolated, the accelerator's history kept
            V0, degree = S[i].start(at)
            return decoded(i, {**S[i].solve(T, at, V0, self._frame_arap, carry=True), "start_degree": degree})

        def from_first(i: int) -> tuple:  # as deform: from sampling 0's result
            first_arap.result()
            return run(i, S[0].decode(S[i].prep["seeds"]))

        if not first:  # the samplings that took longest last time start first
            longest_first = np.argsort([-s.last_iterations for s in S], kind="stable")
            futs = self._submit(later, range(len(S)), order=longest_first)
        elif self.params.warm_start and len(S) > 1:
            futs = self._submit(lambda i: run(i, None), [0])
            futs += self._submit(from_first, range(1, len(S)))
        else:  # from the rigid fit of the handles
            futs = self._submit(lambda i: run(i, None), range(len(S)))
        infos, transfer_s = self._wait(futs)
        Vd = avg.out
        if avg.parts is not None:
            Vd = combine(list(avg.parts), [s.weights() for s in S])
            self.frame.from_unit(Vd, out=Vd)
        pre = combine([s.decode(self.handles) - T for s in S], [s.weights(self.handles) for s in S])
        Vd[self.handles] = T_mesh
        self.n_solves += 1
        if not return_info:
            return Vd
        others = [str(d["status"]) for d in infos if not d["converged"]]
        info = {"total_s": time.perf_counter() - t0, "solve": self.n_solves - 1, "samplings": infos,
                "workers": self.workers, "arap_s": float(sum(d["arap_s"] for d in infos)),
                "transfer_s": transfer_s, "iterations": int(sum(d["iterations"] for d in infos)),
                "converged": not others, "status": others[0] if others else "converged",
                "handles": "overwritten", "handle_pre_pct": handle_pre_pct(pre, self._unit_corners)}
        return Vd, info

    @staticmethod
    def _wait(futs: list) -> tuple[list, float]:
        """Every sampling's ARAP (``futs``, in sampling order) and the decoding chunks each
        queued, waited for: the ARAP infos and the seconds of the frames and decodings,
        summed. Raises the first failure after every task ended."""
        infos, chunks, secs = [], [], 0.0
        try:
            for f in futs:
                info, fc, frames_s = f.result()
                infos.append(info)
                chunks += fc
                secs += frames_s
            return infos, float(secs + sum(f.result() for f in chunks))
        except BaseException:
            wait(futs)
            wait([c for f in futs if not f.cancelled() and f.exception() is None for c in f.result()[1]])
            raise


def prepare(V, F, handles, params: SShaDeParams | Mapping | None = None, **overrides) -> Prepared:
    """Everything of SShaDe that does not depend on the handles' targets (module docstring).

    Parameters
    ----------
    V : (n, 3) float64 rest positions; F : (m, 3) int faces of a connected manifold
        triangle mesh; handles : (h,) int vertex indices (a new selection needs a new
        :func:`prepare`).
    params, **overrides : as :func:`sshade.pipeline.deform` (:class:`sshade.params.SShaDeParams`);
        ``workers`` is the threads the samplings run on (:func:`sshade.cores.pool_size`:
        None = the cores this process may use, at most ``n_samplings``); the results do
        not depend on it.

    Returns
    -------
    :class:`Prepared`; ``prepared.solve(targets)`` deforms; ``prepared.close()`` (or a
    ``with`` block) ends its threads.

    Raises
    ------
    SShaDeError on an invalid mesh or handle indices, a bad parameter
    (:func:`sshade.pipeline.check_params`), or a mesh of several connected components
    (:func:`sshade.pipeline.deform` handles those).

    Warns
    -----
    :class:`sshade.pipeline.LowResSkippedWarning` when ``n_low`` is not below the vertex count.

    Examples
    --------
    >>> from sshade.arap.problems import twisted_bar
    >>> V, F, h, T = twisted_bar(45.0, h=0.25)
    >>> with prepare(V, F, h, n_low=100, n_samplings=2) as p:
    ...     bool(np.allclose(p.solve(T)[h], T))
    True
    """
    return prepare_with(V, F, handles, check_params(params, **overrides))


def prepare_with(V, F, handles, params: SShaDeParams) -> Prepared:
    """:func:`prepare` with its parameters checked already (:func:`sshade.params.check_params`):
    the same result, warnings and errors."""
    t0 = time.perf_counter()
    p = params
    warm_kernels(large_mesh(F))
    V, F, he = validate_mesh(V, F, return_halfedges=True, allow_components=True)
    h = validate_handle_indices(V, handles)
    if count_components(he.E, len(V)) > 1:
        raise SShaDeError("prepare: the mesh has several connected components; deform it with sshade.deform")
    _, n_low_used = low_res_size(len(V), p.n_low, stacklevel=4)  # warns when there is no low-res step
    frame = unit_frame(V)  # as deform: every stage runs centred and scaled
    U = frame.to_unit(V)
    job = SamplingJob(V=U, F=F, handles=h, n_low=n_low_used, seeds=sampling_seeds(p.seed, p.n_samplings),
                      topology=mesh_topology(U, F, he))
    n_workers = pool_size(p.workers, p.n_samplings)
    # the remeshes and projections on forked processes (as deform: they hold the GIL), the rest on threads
    preps = prepare_samplings(job, n_workers)
    pool = ThreadPoolExecutor(n_workers, thread_name_prefix="sshade-sampling")
    try:
        samplings = list(pool.map(lambda pi: _Sampling(U, *pi, p), preps))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    arap_pool = ThreadPoolExecutor(n_workers, thread_name_prefix="sshade-arap")
    return Prepared(V, F, h, p, samplings, time.perf_counter() - t0, arap_pool, n_workers, frame)

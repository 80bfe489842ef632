"""Prepare once, solve every frame: SShaDe split by what depends on the handles' targets
(paper §3), for animations and handles dragged in a viewer.

:func:`prepare` does per sampling what the targets do not enter (remesh and projection
§3.1, local coordinates §3.2, the low-res ARAP's deformer) and returns a :class:`Prepared`;
:meth:`Prepared.solve` runs per sampling the low-res ARAP and the decoding (Alg. 1) and
averages them (§3.3). The first solve is :func:`sshade.deform` of the same parameters, bit
for bit; later ones start from the earlier results extrapolated (:data:`FRAME_ACCELERATION`).
Starts, threads and timings: docs/methods.md ("Implementation notes: sshade/prepared.py").
"""
from __future__ import annotations

import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor, as_completed, wait

import igl
import numpy as np

from .arap import ArapDeformer, LaplacianSolver
from .averaging import combine, proximity_weights, sampling_weights
from .cores import pool_size
from .errors import SShaDeError
from .lrf import decode_with_frames, deformed_frames, encode, frame_functions
from .mesh.halfedge import count_components
from .mesh.unit_frame import UnitFrame, unit_frame
from .mesh.validate import validate_handle_indices, validate_mesh, validate_targets
from .params import SShaDeParams, check_params
from .pipeline import SamplingJob, handle_pre_pct, low_res_size, prepare_samplings
from .remesh import mesh_topology
from .sampling import sampling_seeds, warm_kernels
from .smooth_transfer import jacobian_rest, smooth_decode_with, smooth_offsets, vertex_jacobians

__all__ = ["prepare", "prepare_with", "Prepared", "FRAME_ACCELERATION"]

#: The low-res ARAP's acceleration from the second solve on (``accelerate``,
#: ``anderson_m`` of :meth:`sshade.arap.solver.ArapSolver.solve`), with the history kept
#: from solve to solve (``carry_history``); the first solve keeps
#: :func:`sshade.pipeline.deform`'s L-BFGS, so that it is ``deform`` bit for bit. From a start
#: as near as the extrapolated one, Anderson acceleration met the same stopping rule in
#: fewer iterations than L-BFGS on both meshes of ``benchmarks/frames.py``, and a window of
#: 32 in fewer than one of 16 or 8 (a longer one saved almost no more iterations;
#: benchmarks/records/frames_scalar_decode.md).
FRAME_ACCELERATION = {"accelerate": "anderson", "anderson_m": 32}


def _extrapolate(h: list, degree: int) -> np.ndarray:
    """One step on from the results ``h`` ((k, 3) each, newest first) along the polynomial
    of ``degree`` (0, 1 or 2) through the newest ``degree + 1`` of them."""
    if degree == 0:
        return h[0]
    if degree == 1:
        return 2.0 * h[0] - h[1]
    return 3.0 * (h[0] - h[1]) + h[2]


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
            self.G = smooth_offsets(V, prep["tri"], self.bary, self.VN, prep["F"])
            self.jac_rest = jacobian_rest(self.VN, prep["F"])
        self.arap = ArapDeformer(self.VN, prep["F"], prep["low_handles"], energy=p.energy, protocol=p.protocol)
        self.moves = _HandleMoves(self.VN, prep["F"], prep["low_handles"])
        self.history: list = []  # (k, 3) low-res results of the last four solves, newest first
        self.last_iterations = 0  # of the last solve

    def start(self) -> tuple[np.ndarray, int]:
        """The next solve's start, (k, 3), and its order: the polynomial of degree 0, 1 or 2
        through the newest results, evaluated one step on (frames taken as equally
        spaced), of the degree that, from the results before it, best predicted the
        newest one (least Euclidean distance; a smooth path picks 2, a handle that stops
        picks 0 after one solve, a jittery one the degree that copes)."""
        h = self.history
        if len(h) == 1:
            return h[0], 0
        errs = [_norm(_extrapolate(h[1:], d) - h[0]) for d in range(min(3, len(h) - 1))]
        d = int(np.argmin(errs))
        return _extrapolate(h, d), d

    def solve(self, targets, V0, arap: dict, carry: bool = False) -> dict:
        """The low-res ARAP from ``V0`` ((k, 3) or None: the rigid fit); when ``carry`` (a
        later frame) with the last solve's accelerator history and ``V0``'s free vertices
        moved with its handle rows to the targets (:class:`_HandleMoves`): the info of the
        ARAP run. Its result's frames are made by the first :meth:`decode` after it (on
        the decoding thread)."""
        t0 = time.perf_counter()
        if carry and V0 is not None:
            V0 = self.moves.extend(V0, targets)
        res = self.arap.deform(targets, V0=V0, carry_history=carry, **arap)
        self.low, self.frames = res.V, None
        self.history = [res.V] + self.history[:3]
        self.last_iterations = res.iterations
        return {"arap_s": time.perf_counter() - t0, "iterations": res.iterations, "converged": res.converged,
                "status": res.info.get("status"), "warm_start": V0 is not None}

    def decode(self, rows=None, out: np.ndarray | None = None, add: bool = False) -> np.ndarray:
        """The last solve's high-res positions at ``rows`` (Alg. 1, or
        :func:`sshade.smooth_transfer.smooth_decode_with` for ``transfer="vertex"``;
        :func:`sshade.lrf.decode_with_frames`: rows, out and add as there)."""
        if self.transfer == "vertex":
            return self._decode_smooth(rows, out, add)
        frames = self.frames
        if frames is None:  # threads racing here compute the same frames
            frames = self.frames = deformed_frames(self.VN, self.low, self.prep["F"], self.axis, self.gradient)
        return decode_with_frames(frames, self.C, self.prep["tri"], self.low, self.prep["F"], self.bary,
                                  rows=rows, out=out, add=add)

    def _decode_smooth(self, rows, out, add: bool) -> np.ndarray:
        """:meth:`decode` for ``transfer="vertex"``: the corners' deformation gradients of
        the last solve (made once, by the first decoding after it) blended at ``rows``."""
        Jv = self.frames
        if Jv is None:  # threads racing here compute the same gradients
            Jv = self.frames = vertex_jacobians(self.VN, self.low, self.prep["F"], rest=self.jac_rest)
        return smooth_decode_with(Jv, self.G, self.prep["tri"], self.bary, self.low, self.prep["F"], rows=rows,
                                  out=out, add=add)

    def weights(self, rows=None) -> np.ndarray | None:
        """The last solve's averaging weights at ``rows`` ((r,) float64), or None for the
        uniform mean (:func:`sshade.averaging.sampling_weights`)."""
        if self.proximity is not None:  # known before the targets: made once, in __init__
            return self.proximity if rows is None else self.proximity[rows]
        idx = slice(0, len(self.V)) if rows is None else rows
        bary = None if self.bary is None else self.bary[idx]
        return sampling_weights(self.average, self.V[idx], self.prep["tri"][idx], bary, self.VN, self.low,
                                self.prep["F"])


class Prepared:
    """SShaDe prepared for one mesh and one handle set (:func:`prepare`); a context manager
    (leaving it, or :meth:`close`, ends the worker threads; a later solve refuses).

    Attributes
    ----------
    V : (n, 3) float64; F : (m, 3) int64; handles : (h,) int64 (the validated inputs).
    params : :class:`sshade.params.SShaDeParams`, the checked parameters.
    workers : int, threads the samplings run on. prepare_s : float, seconds
    :func:`prepare` took. n_solves : int, solves so far. frame : the
    :class:`sshade.mesh.unit_frame.UnitFrame` the samplings are held in (targets are
    mapped into it, results out of it).

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
        for made_for in ("protocol", "energy"):  # the deformers were made for them
            self._arap.pop(made_for)
        self._frame_arap = {**self._arap, **FRAME_ACCELERATION}
        self.n_solves = 0
        self._corners = np.array([V.min(0), V.max(0)])  # V's bounding box, for the per-solve checks
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

    def solve(self, targets, *, return_info: bool = False):
        """Deform for ``targets`` ((h, 3) float, one per handle, in :attr:`handles`' order).

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
        wait(self._pending)  # an interrupted solve's tasks end before their samplings are reused
        self._pending = []
        first, S = self.n_solves == 0, self._samplings
        arap = self._arap

        def run(i: int, V0) -> dict:
            return S[i].solve(T, V0, arap)

        def later(i: int) -> dict:  # the earlier frames extrapolated, the accelerator's history kept
            V0, degree = S[i].start()
            return {**S[i].solve(T, V0, self._frame_arap, carry=True), "start_degree": degree}

        def from_first(i: int) -> dict:  # as deform: from sampling 0's result
            futs[0].result()
            return run(i, S[0].decode(S[i].prep["seeds"]))

        if not first:  # the samplings that took longest last time start first
            longest_first = np.argsort([-s.last_iterations for s in S], kind="stable")
            futs = self._submit(later, range(len(S)), order=longest_first)
        elif self.params.warm_start and len(S) > 1:
            futs = self._submit(lambda i: run(i, None), [0])
            futs += self._submit(from_first, range(1, len(S)))
        else:  # from the rigid fit of the handles
            futs = self._submit(lambda i: run(i, None), range(len(S)))
        Vd, infos, transfer_s = self._decode_average(futs)
        pre = combine([s.decode(self.handles) - T for s in S], [s.weights(self.handles) for s in S])
        self.frame.from_unit(Vd, out=Vd)
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

    def _decode_average(self, futs: list) -> tuple[np.ndarray, list, float]:
        """The samplings' decodings averaged, (n, 3), each sampling decoded here as soon as
        its ARAP (future in ``futs``) is done: onto the running sum when it is the next in
        sampling order, else into an (n, 3) array of its own, added when its turn comes;
        so the additions are those of :func:`sshade.sampling.average` (sampling order),
        whatever order the ARAPs end in (at most ``k - 1`` such arrays held during a
        solve). A weighted average (``average`` not ``"uniform"``) keeps every decoding and
        combines them at the end (:func:`sshade.averaging.combine`, as :func:`sshade.deform`).
        The ARAP infos and the decoding's seconds. Waits for every ARAP even when one fails."""
        out, infos, secs = np.empty((len(self.V), 3)), [None] * len(futs), 0.0
        early, nxt, index = {}, 0, {f: i for i, f in enumerate(futs)}
        weighted = self.params.average != "uniform"
        try:
            for f in as_completed(futs):
                i = index[f]
                infos[i] = f.result()
                t = time.perf_counter()
                if i != nxt or weighted:  # ended before an earlier sampling: decoded aside
                    early[i] = self._samplings[i].decode(slice(0, len(out)))
                else:
                    self._samplings[i].decode(slice(0, len(out)), out, add=i > 0)
                    nxt += 1
                    while nxt in early:  # the same additions as decoding onto the sum
                        out += early.pop(nxt)
                        nxt += 1
                secs += time.perf_counter() - t
        except BaseException:
            wait(futs)
            raise
        if weighted:
            S = self._samplings
            return combine([early[i] for i in range(len(S))], [s.weights() for s in S]), infos, secs
        out /= len(futs)
        return out, infos, secs


def prepare(V, F, handles, *, n_low: int = 6000, n_samplings: int = 5, seed: int = 0, tol: float = 1e-4,
            max_iter: int | None = None, gradient: str = "normalized", warm_start: bool = True,
            protocol: str = "converged", etol: float | None = None, gtol: float | None = None,
            anchor: str = "projection", workers: int | None = None, energy: str = "spokes_and_rims",
            transfer: str = "vertex", average: str = "uniform") -> Prepared:
    """Everything of SShaDe that does not depend on the handles' targets (module docstring).

    Parameters
    ----------
    V : (n, 3) float64 rest positions; F : (m, 3) int faces of a connected manifold
        triangle mesh; handles : (h,) int vertex indices (a new selection needs a new
        :func:`prepare`). workers : int >= 1 or None, threads the samplings run on
        (:func:`sshade.cores.pool_size`: None = the cores this process may use, at most
        ``n_samplings``); the results do not depend on it. The other parameters as
        :func:`sshade.pipeline.deform`.

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
    params = check_params(n_low=n_low, n_samplings=n_samplings, seed=seed, workers=workers, tol=tol,
                          max_iter=max_iter, gradient=gradient, warm_start=warm_start, protocol=protocol, etol=etol,
                          gtol=gtol, anchor=anchor, energy=energy, transfer=transfer, average=average)
    return prepare_with(V, F, handles, params)


def prepare_with(V, F, handles, params: SShaDeParams) -> Prepared:
    """:func:`prepare` with its parameters checked already (:func:`sshade.params.check_params`):
    the same result, warnings and errors."""
    t0 = time.perf_counter()
    p = params
    warm_kernels()
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

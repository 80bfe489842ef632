"""SShaDe: the whole pipeline (paper §3, Fig. 1): remesh -> low-res ARAP (spokes-and-rims
by default, ``energy``) -> LRF transfer, averaged over k samplings run in parallel
processes (§3.3, the pool of :mod:`sshade.sampling`, every sampling working on one
:class:`SamplingJob`).
:func:`deform` checks its keywords into a :class:`sshade.params.SShaDeParams`
(:func:`check_params`) and runs :func:`deform_with`; :class:`SShaDe` is the method object.
"""
from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .arap import ArapOptions, arap_deform, bbox_diag, beside_others
from .averaging import combine, sampling_weights
from .components import deform_components
from .mesh.halfedge import count_components, large_mesh
from .mesh.unit_frame import unit_frame
from .mesh.validate import validate_handles, validate_mesh
from .params import (
    MAX_SEED,
    MIN_N_LOW,
    SShaDeParams,
    check_params,
    document_params,
    effective_params,
    only_params,
    params_signature,
)
from .projection import project_to_fans
from .remesh import mesh_topology, remesh_drawn
from .sampling import SamplingPool, pool_size, sampling_seeds, warm_kernels
from .smooth_transfer import rebuild
from .warmup import WARMED, warm_once

__all__ = ["deform", "deform_with", "deform_once", "SShaDe", "SShaDeParams", "SamplingJob", "auto_n_low",
           "check_params", "effective_params", "MAX_SEED", "warm_sshade", "LowResSkippedWarning", "prepare_sampling",
           "prepare_samplings", "low_res_size", "handle_pre_pct"]


@dataclass(frozen=True)
class SamplingJob:
    """What every sampling of one deformation works on (the job of its
    :class:`sshade.sampling.SamplingPool`, inherited by the forked workers).

    Attributes
    ----------
    V : (n, 3) float64
        Rest positions (in the unit frame).
    F : (m, 3) int64
        Faces.
    handles : (h,) int64
        Vertex indices.
    n_low : int
        Farthest-point samples per low-res mesh.
    seeds : list of k ints
        :func:`sshade.sampling.sampling_seeds`.
    topology : MeshTopology or None
        :func:`sshade.remesh.mesh_topology` of ``(V, F)``.
    targets : (h, 3) float64 or None
        None from :func:`prepare_samplings` (not known yet).
    gradient, anchor : str
        LRF modes (:data:`sshade.lrf.GRADIENTS`, :data:`sshade.lrf.ANCHORS`).
    transfer, average : str
        The transfer and the samplings' average (:data:`sshade.smooth_transfer.TRANSFERS`,
        :data:`sshade.averaging.AVERAGES`).
    arap : ArapOptions or None
        The options of :func:`sshade.arap.arap_deform` (:meth:`SShaDeParams.arap_options`:
        the energy and the stopping rule); None: its defaults.
    """

    V: np.ndarray
    F: np.ndarray
    handles: np.ndarray
    n_low: int
    seeds: list
    topology: object = None
    targets: np.ndarray | None = None
    gradient: str = "normalized"
    anchor: str = "projection"
    arap: ArapOptions | None = None
    transfer: str = "vertex"
    average: str = "uniform"


def prepare_sampling(V, F, handles, n_low: int, seed: int, topology) -> tuple[dict, dict]:
    """Remesh + projection of one sampling (paper §3.1): what does not depend on the targets.

    Parameters
    ----------
    V, F : (n, 3) float64, (m, 3) int64
        The validated mesh.
    handles : (h,) int64
        Added to the low-res vertices.
    n_low : int
        Farthest-point samples.
    seed : int
        The sampling's seed.
    topology : MeshTopology or None
        The :func:`sshade.remesh.mesh_topology` of ``(V, F)``.

    Returns
    -------
    prep : dict ``seeds`` (k,) low-res vertex indices into V, ``F`` (t, 3) low-res faces,
    ``tri`` (n,) int32 triangle P(v), ``bary`` (n, 3) its barycentric coordinates,
    ``low_handles`` (h,) the handles' low-res indices; info : dict of seconds and counts
    (remesh_s, project_s, n_low, n_repair, rounds, n_flipped, seed, first, redrawn: the
    seeds of the draws given up for a degenerate low-res face, :func:`sshade.remesh.remesh_drawn`;
    ``first`` is the first sample of the draw kept).
    """
    t0 = time.perf_counter()
    rm, given_up = remesh_drawn(V, F, n_low, seed=seed, required=handles, topology=topology)
    t1 = time.perf_counter()
    proj = project_to_fans(V, rm.label, V[rm.seeds], rm.F)
    t2 = time.perf_counter()
    prep = {"seeds": rm.seeds, "F": rm.F, "tri": proj.tri.astype(np.int32), "low_handles": rm.label[handles],
            "bary": proj.bary}
    info = {"remesh_s": t1 - t0, "project_s": t2 - t1, "n_low": int(len(rm.seeds)), "n_repair": rm.n_repair,
            "rounds": int(rm.iterations), "n_flipped": rm.n_flipped, "seed": int(seed), "first": rm.first,
            "redrawn": given_up}
    return prep, info


def prepare_samplings(job: SamplingJob, workers: int) -> list[tuple[dict, dict]]:
    """:func:`prepare_sampling` of each of ``job.seeds``, side by side on ``workers`` forked
    processes (:class:`sshade.sampling.SamplingPool`; one: in this process), in seed order.

    Parameters
    ----------
    job : :class:`SamplingJob` (its targets, gradient, anchor and arap unused).
    workers : int >= 1.

    Returns
    -------
    list of k ``(prep, info)`` pairs, the same as :func:`prepare_sampling` of each seed.
    """
    with SamplingPool(job, workers) as pool:
        futures = [pool.submit_with_job(_task_prepare, i) for i in range(len(job.seeds))]
        return [f.result()[1:] for f in futures]


def _finish(job: SamplingJob, prep: dict, U0=None):
    """Low-res ARAP of ``job.arap``'s energy (spokes-and-rims by default, §3.3, §4.1) + LRF
    transfer (Alg. 1) of one sampling of ``job``, from ``U0`` ((k, 3) or None: the rigid
    fit of the handles)."""
    V, targets, handles = job.V, job.targets, job.handles
    t0 = time.perf_counter()
    VN = V[prep["seeds"]]
    with beside_others():  # the samplings' solves share the cores (sshade.arap.threads)
        res = arap_deform(VN, prep["F"], prep["low_handles"], targets, job.arap, U0=U0)
    t1 = time.perf_counter()
    bary = prep["bary"] if job.anchor == "projection" else None
    Vd = rebuild(V, prep["tri"], bary, VN, res.V, prep["F"], transfer=job.transfer, gradient=job.gradient)
    weights = sampling_weights(job.average, V, prep["tri"], bary, VN, res.V, prep["F"])
    # handles are low-res vertices: anchored at their projection (themselves) the transfer
    # rebuilds them exactly; at the barycenter (Alg. 1) only where P(v) moves rigidly (the
    # frame is not the triangle's affine map). Overwritten here, the residual kept for the
    # handle error before the overwrite
    resid = Vd[handles] - targets
    Vd[handles] = targets
    t2 = time.perf_counter()
    return Vd, {"arap_s": t1 - t0, "transfer_s": t2 - t1, "iterations": res.iterations,
                "converged": res.converged, "status": res.info.get("status"), "warm_start": U0 is not None,
                "energy": res.info.get("energy"), "gnorm": res.info.get("gnorm"), "handle_resid": resid,
                "weights": weights}


def deform_once(V, F, handles, targets, params: SShaDeParams | Mapping | None = None, *, topology=None,
                V_init=None, **overrides) -> tuple[np.ndarray, dict]:
    """One sampling of SShaDe (no averaging): remesh, low-res ARAP, transfer.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; handles : (h,) int64; targets : (h, 3) float64
        (all validated).
    params : :class:`sshade.params.SShaDeParams` or a mapping of some of its keys, or None.
    topology : optional :func:`sshade.remesh.mesh_topology` of ``(V, F)``.
    V_init : (n, 3) float64 or None, a deformed high-res shape whose values at the
        low-res vertices start the ARAP iterations (default: rigid fit of the handles).
    **overrides : those of :data:`ONCE_KEYS` (:class:`sshade.params.SShaDeParams`: ``n_low``
        an int here; ``seed`` the sampling's own seed), over ``params``.

    Returns
    -------
    Vd : (n, 3) float64 deformed positions; info : dict with per-stage seconds
    (remesh_s, project_s, arap_s, transfer_s), n_low (actual low-res vertex count),
    iterations (low-res ARAP), converged, seed, first (first seed vertex), n_repair (seeds
    added by the remesh's repairs), rounds (its check-and-repair rounds), n_flipped,
    redrawn (seeds of draws given up for a degenerate low-res face), handle_pre_pct
    (largest handle error before the handles are overwritten with their targets, % of the
    bounding-box diagonal).

    Raises
    ------
    SShaDeError on a bad parameter or one it does not use (:func:`check_params`), before any work.

    Notes
    -----
    Runs in the caller's coordinates (:func:`deform` and :func:`sshade.prepared.prepare`
    move the mesh to its unit frame first, :mod:`sshade.mesh.unit_frame`).
    """
    p = check_params(params, **only_params("deform_once", overrides, ONCE_KEYS))
    job = SamplingJob(V=V, F=F, handles=handles, n_low=p.n_low, seeds=[p.seed], topology=topology, targets=targets,
                      gradient=p.gradient, anchor=p.anchor, arap=p.arap_options(), transfer=p.transfer)
    _, prep, info = _task_prepare(job, 0)
    V0 = None if V_init is None else V_init[prep["seeds"]]
    Vd, info2 = _finish(job, prep, V0)
    info2.pop("weights")  # one sampling: nothing to average
    info.update(info2, handle_pre_pct=handle_pre_pct(info2.pop("handle_resid"), V))
    return Vd, info


#: The parameters :func:`deform_once` uses (one sampling: no average, no workers)
ONCE_KEYS = ("n_low", "seed", "tol", "max_iter", "gradient", "protocol", "etol", "gtol", "anchor", "energy",
             "transfer")


def _task_full(job: SamplingJob, i: int):
    """Sampling i of ``job``: remesh and projection, then ARAP and transfer from the rigid fit."""
    _, prep, info = _task_prepare(job, i)
    Vd, info2 = _finish(job, prep)
    info.update(info2)
    return i, Vd, info


def _task_prepare(job: SamplingJob, i: int):
    """Sampling i of ``job``: remesh and projection (:func:`prepare_sampling`)."""
    prep, info = prepare_sampling(job.V, job.F, job.handles, job.n_low, job.seeds[i], job.topology)
    return i, prep, info


def _task_finish(job: SamplingJob, i: int, prep: dict, V0: np.ndarray):
    """Sampling i of ``job`` after :func:`_task_prepare`: ARAP from ``V0`` and transfer."""
    Vd, info = _finish(job, prep, V0)
    return i, Vd, info


class LowResSkippedWarning(UserWarning):
    """``n_low`` is at or above the mesh's vertex count: SShaDe has no low-resolution
    step (the "low-res" ARAP runs on the whole mesh). Recorded as ``low_res_skipped``
    in :func:`deform`'s info."""


def auto_n_low(n: int) -> int:
    """Default low-res size for an n-vertex mesh: min(6000, n // 7), at least 100
    (6000 is the paper's setting for 150k-200k vertices; n // 7 keeps small meshes
    such as FAUST's 6890-vertex registrations about 7x coarser)."""
    return int(max(100, min(6000, n // 7)))


@document_params
def deform(V, F, handles, targets, params: SShaDeParams | Mapping | None = None, *, return_info: bool = False,
           **overrides):
    """Deform a high-resolution mesh with SShaDe (paper §3, Alg. 1, §3.3 averaging).

    Parameters
    ----------
    V : (n, 3) float64 rest vertex positions (any length unit).
    F : (m, 3) int faces of a manifold triangle mesh (boundary allowed); several connected
        components are deformed apart (:func:`sshade.components.deform_components`; info
        gains ``n_components``).
    handles : (h,) int vertex indices. targets : (h, 3) float target positions.
    params : :class:`sshade.params.SShaDeParams` (:func:`check_params`) or a mapping of
        some of its keys, or None; ``**overrides`` (its keys) over it, the rest its defaults:
    {sshade_params}
    return_info : also return a dict of timings (seconds; ``total_s`` excludes
        ``compile_s``), seeds, per-sampling details, ``handle_pre_pct``, ``frame`` and
        ``low_res_energy`` (docs/implementation.md, "Implementation notes: sshade/pipeline.py").

    Returns
    -------
    Vd : (n, 3) float64 deformed positions (same connectivity F), handles at their
    targets; with ``return_info`` the tuple ``(Vd, info)``.

    Raises
    ------
    SShaDeError on an invalid mesh or handles (:func:`sshade.mesh.validate.validate_mesh`)
    or a bad parameter (:func:`check_params`), before any work.

    Warns
    -----
    LowResSkippedWarning when ``n_low`` is at or above the vertex count (no low-res
    step; recorded as ``low_res_skipped`` and ``n_low_requested`` in the info).

    Examples
    --------
    Example::

        Vd = deform(V, F, handles, targets, n_low=6000, n_samplings=5, seed=0)
    """
    return deform_with(V, F, handles, targets, check_params(params, **overrides), return_info=return_info)


def deform_with(V, F, handles, targets, params: SShaDeParams, *, return_info: bool = False):
    """:func:`deform` with its parameters checked already (:func:`check_params`): the same
    arrays, result, info, warnings and errors (paper §3, Alg. 1, §3.3)."""
    p = params
    compile_s = warm_kernels(large_mesh(F))  # numba compilation / cache loads: not part of the timings below
    t0 = time.perf_counter()
    V, F, he = validate_mesh(V, F, return_halfedges=True, allow_components=True)
    handles, targets = validate_handles(V, handles, targets)
    if count_components(he.E, len(V)) > 1:  # each component apart, handle-less ones rigidly (sshade.components)
        return deform_components(SShaDe.from_params(p), V, F, handles, targets, return_info=return_info)
    n_low_asked, n_low = low_res_size(len(V), p.n_low, stacklevel=4)
    frame = unit_frame(V)  # every stage runs centred and scaled (sshade.mesh.unit_frame)
    U, T = frame.to_unit(V), frame.to_unit(targets)
    job = SamplingJob(V=U, F=F, handles=handles, n_low=n_low, seeds=sampling_seeds(p.seed, p.n_samplings),
                      topology=mesh_topology(U, F, he), targets=T, gradient=p.gradient, anchor=p.anchor,
                      arap=p.arap_options(), transfer=p.transfer, average=p.average)
    workers = pool_size(p.workers, p.n_samplings)
    t1 = time.perf_counter()
    with SamplingPool(job, workers) as pool:
        results, infos = _run_samplings(pool, p.n_samplings, p.warm_start)
    weights = [d.pop("weights") for d in infos]
    Vd = combine(results, weights)
    frame.from_unit(Vd, out=Vd)
    Vd[handles] = targets  # overwritten after averaging (the paper does not say; docs/differences.md)
    pre = combine([d.pop("handle_resid") for d in infos],  # the averaged result's residual before the overwrite
                  [None if w is None else w[handles] for w in weights])  # the averaged result's residual before it
    if not return_info:
        return Vd
    info = {"total_s": time.perf_counter() - t0, "setup_s": t1 - t0, "compile_s": compile_s, "workers": workers,
            "seed": p.seed, "sampling_seeds": job.seeds, "warm_start": p.warm_start,
            "n_low_requested": int(n_low_asked), "low_res_skipped": bool(n_low_asked >= len(V)), "samplings": infos}
    return Vd, {**info, **_summary(infos, frame), "protocol": p.protocol, "low_res_energy": p.energy,
                "anchor": p.anchor, "transfer": p.transfer, "average": p.average, "handles": "overwritten",
                "handle_pre_pct": handle_pre_pct(pre, U)}


def handle_pre_pct(resid: np.ndarray, V: np.ndarray) -> float:
    """Largest handle residual (h, 3) of the averaged result before the handles are
    overwritten, in % of the bounding-box diagonal of ``V`` (n, 3); 0.0 without handles."""
    if not len(resid):
        return 0.0
    return float(100.0 * np.linalg.norm(resid, axis=1).max() / bbox_diag(V))


def low_res_size(n: int, n_low, *, stacklevel: int = 3) -> tuple[int, int]:
    """(requested, actual) low-res vertex count of an ``n``-vertex mesh for the checked
    ``n_low`` (int or ``"auto"``: :func:`auto_n_low`); warns :class:`LowResSkippedWarning`
    (``stacklevel`` as :func:`warnings.warn`'s, counted from this function's caller: at the
    caller of :func:`deform` or :func:`sshade.prepared.prepare`) when the request is not
    below ``n``."""
    asked = auto_n_low(n) if n_low == "auto" else n_low
    if asked >= n:
        # a valid n_low is at least MIN_N_LOW (check_params) and below n: advise one only when it exists
        advice = (f"pass n_low between {MIN_N_LOW} and {n - 1}" if n - 1 >= MIN_N_LOW else
                  f"no n_low gives one: it must be at least {MIN_N_LOW} and below the vertex count")
        warnings.warn(f"SShaDe: n_low={asked} is not below the mesh's {n} vertices: there is no "
                      f"low-resolution step, the low-res ARAP runs on the whole mesh ({advice})",
                      LowResSkippedWarning, stacklevel=stacklevel)
    return asked, int(min(asked, n))


def _run_samplings(pool: SamplingPool, k: int, warm_start: bool) -> tuple[list, list]:
    """The k samplings' deformed meshes ((n, 3) each) and info dicts, in order. With
    ``warm_start``, sampling 0 runs first while the others remesh and project; their
    low-res ARAP then starts from sampling 0's result."""
    results: list = [None] * k
    infos: list = [None] * k
    if not warm_start or k == 1:
        for f in [pool.submit_with_job(_task_full, i) for i in range(k)]:
            i, results[i], infos[i] = f.result()
        return results, infos
    f0 = pool.submit_with_job(_task_full, 0)
    preps = [pool.submit_with_job(_task_prepare, i) for i in range(1, k)]
    _, results[0], infos[0] = f0.result()
    fins = []
    for f in preps:
        i, prep, info = f.result()
        infos[i] = info
        fins.append(pool.submit_with_job(_task_finish, i, prep, results[0][prep["seeds"]]))
    for f in fins:
        i, results[i], info2 = f.result()
        infos[i].update(info2)
    return results, infos


def _summary(infos: list, frame) -> dict:
    """Per-stage seconds and iterations summed over the samplings' ``infos``, mean
    ``n_low``, ``converged`` (every sampling's low-res ARAP), ``status`` (``"converged"``,
    else the first other status among the samplings', e.g. ``"stalled"``) and
    ``iterations_max``, ``redrawn`` (samplings drawn again for a degenerate low-res face,
    :func:`sshade.remesh.remesh_drawn`), ``frame`` (the unit frame's numbers); each
    sampling's ``energy`` is put back in mesh units (``frame``, a
    :class:`sshade.mesh.unit_frame.UnitFrame`)."""
    for d in infos:
        d["energy"] = frame.energy(d.get("energy"))
    out = {k: float(np.sum([d[k] for d in infos])) for k in ("remesh_s", "project_s", "arap_s", "transfer_s",
                                                                 "iterations")}
    out["n_low"] = int(np.mean([d["n_low"] for d in infos]))
    out["converged"] = bool(all(d["converged"] for d in infos))
    others = [str(d.get("status")) for d in infos if not d["converged"]]
    out["status"] = others[0] if others else "converged"
    out["iterations_max"] = int(max(d["iterations"] for d in infos))
    out["redrawn"] = int(sum(len(d.get("redrawn") or ()) for d in infos))
    out["frame"] = frame.as_dict()
    return out


def warm_sshade(params: SShaDeParams) -> float:
    """Warm :func:`deform` with SShaDe's checked ``params`` (:func:`check_params`): one
    in-process run on :func:`sshade.warmup.tiny_problem` with the same ARAP protocol, energy
    and gradient mode (two samplings, warm-started, so every stage runs), once per process
    (:func:`sshade.warmup.warm_once`). Returns the seconds spent (0.0 when warm)."""
    p = params.replace(n_low=40, n_samplings=2, workers=1, warm_start=True, seed=0)
    return warm_once(WARMED, ("sshade", p.protocol, p.gradient, p.energy),
                     lambda V, F, h, T: deform_with(V, F, h, T, p))


class SShaDe:
    """SShaDe behind the :class:`sshade.method_interface.Deformer` interface.

    ``params`` and ``**overrides`` as :func:`deform` (:class:`sshade.params.SShaDeParams`).
    After :meth:`deform`, ``info`` holds remesh_s / project_s / arap_s / transfer_s (summed
    CPU-side over samplings), total_s (wall time), the sampling seeds and per-sampling details.

    Examples
    --------
    Example::

        m = SShaDe(n_low=6000, n_samplings=5, seed=0)
        Vd = m.deform(V, F, handles, targets)
    """

    name = "SShaDe"

    def __init__(self, params: SShaDeParams | Mapping | None = None, **overrides):
        # validated here, so a bad parameter fails when the method is built, before any work
        self.params = check_params(params, **overrides)
        self.info: dict = {}

    __signature__ = params_signature(__init__)  # the keywords it takes: SShaDeParams' fields

    @classmethod
    def from_params(cls, params: SShaDeParams) -> SShaDe:
        """The method with the checked ``params`` (:func:`check_params`)."""
        return cls(params)

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """See :func:`deform`; returns (n, 3) float64."""
        Vd, self.info = deform_with(V, F, handles, targets, self.params, return_info=True)
        return Vd

    def effective_params(self) -> dict:
        """The parameters :meth:`deform` runs with, every default resolved
        (:func:`effective_params`)."""
        return effective_params(self.params)

    def warmup(self, n_vertices: int | None = None) -> float:
        """Compile (or load from numba's cache) every kernel :meth:`deform` runs, by one
        in-process run on a tiny mesh with this method's protocol, energy and gradient mode
        (:func:`warm_sshade`), so that a timed call measures no compilation.
        ``n_vertices`` is accepted for the common interface (SShaDe's kernels run on the
        low-resolution meshes, serially). Returns the seconds spent (0.0 when warm)."""
        return warm_sshade(self.params)

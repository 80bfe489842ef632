"""Deformation transfer through a known 1:1 correspondence: non-rigid isometric
deformations (paper §4.2, Fig. "diagrams" a) and pose transfer (§4.3, Fig. "diagrams" b).

Per sampling: remesh the rest mesh M to N, read the deformed low-res mesh N' off M'
(``V_M'[seeds]`` with N's faces) instead of running a low-res ARAP, encode M (or a third
shape S, 1:1 with M and aligned with it) in N's triangle frames and decode on N' (Alg. 1);
the k samplings (one :class:`TransferJob`) are averaged (§3.3) in the pool of
:mod:`sshade.sampling`. Steps and formulas: docs/implementation.md ("Implementation notes:
sshade/isometric.py").
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .averaging import combine, sampling_weights
from .errors import SShaDeError
from .mesh.halfedge import large_mesh
from .mesh.validate import check_points, validate_mesh
from .params import SShaDeParams, check_params, only_params
from .pipeline import auto_n_low
from .projection import project_to_fans
from .remesh import mesh_topology, remesh_drawn
from .sampling import SamplingPool, pool_size, sampling_seeds, warm_kernels
from .smooth_transfer import rebuild

__all__ = ["isometric_transfer", "pose_transfer", "correspondence_transfer", "transfer_with", "transfer_params",
           "TransferJob", "rigid_align", "TRANSFER_KEYS", "TRANSFER_DEFAULTS"]


@dataclass(frozen=True)
class TransferJob:
    """What every sampling of one correspondence transfer works on (the job of its
    :class:`sshade.sampling.SamplingPool`, inherited by the forked workers).

    Attributes
    ----------
    V : (n, 3) float64
        The rest mesh M.
    F : (m, 3) int64
        Its faces.
    S : (n, 3) float64
        The positions encoded.
    T : (n, 3) float64
        M in the target pose (M').
    n_low : int
        Farthest-point samples per low-res mesh.
    seeds : list of k ints
        The samplings' seeds.
    topology : MeshTopology
        :func:`sshade.remesh.mesh_topology` of ``(V, F)``.
    gradient, anchor : str
        LRF modes.
    transfer, average : str
        The transfer and the samplings' average (:data:`sshade.smooth_transfer.TRANSFERS`,
        :data:`sshade.averaging.AVERAGES`).
    """

    V: np.ndarray
    F: np.ndarray
    S: np.ndarray
    T: np.ndarray
    n_low: int
    seeds: list
    topology: object
    gradient: str
    anchor: str
    transfer: str = "vertex"
    average: str = "uniform"


def _positions(X, n: int | None, name: str, ref: str = "the rest mesh") -> np.ndarray:
    """(n, 3) float64 finite positions (:func:`sshade.mesh.validate.check_points`) in 1:1
    correspondence with ``ref`` (n vertices; None: any count)."""
    X = check_points(X, name)
    if n is not None and len(X) != n:
        raise SShaDeError(f"{name} has {len(X)} vertices but {ref} has {n}: the shapes must be "
                          "in 1:1 vertex correspondence (same vertex count and order)")
    return X


def rigid_align(X, Y) -> np.ndarray:
    """Best rigid motion of X onto Y in the least-squares sense (Kabsch, no scaling).

    Parameters
    ----------
    X, Y : (n, 3) float, point sets in 1:1 correspondence (same length unit).

    Returns
    -------
    (n, 3) float64, ``X @ R.T + t`` with the rotation R (det +1) and translation t
    minimising ``sum ||X R^T + t - Y||^2``.

    Raises
    ------
    SShaDeError on shape mismatch or NaN/inf.

    Examples
    --------
    >>> X = np.random.default_rng(0).normal(size=(10, 3))
    >>> bool(np.allclose(rigid_align(X + 1.0, X), X))
    True
    """
    Y = _positions(Y, None, "Y")
    X = _positions(X, len(Y), "X", "Y")
    cx, cy = X.mean(axis=0), Y.mean(axis=0)
    U, _, Wt = np.linalg.svd((X - cx).T @ (Y - cy))
    d = np.sign(np.linalg.det(Wt.T @ U.T)) or 1.0
    R = Wt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return (X - cx) @ R.T + cy


def _one(job: TransferJob, i: int) -> tuple[int, np.ndarray, dict]:
    """Sampling i of ``job``: remesh M, project M onto N, encode S on N, decode on N' (Alg. 1)."""
    V, F = job.V, job.F
    t0 = time.perf_counter()
    rm, given_up = remesh_drawn(V, F, job.n_low, seed=job.seeds[i], topology=job.topology)
    t1 = time.perf_counter()
    VN = V[rm.seeds]
    proj = project_to_fans(V, rm.label, VN, rm.F)
    t2 = time.perf_counter()
    bary = proj.bary if job.anchor == "projection" else None  # M's own projection, also for S
    TN = job.T[rm.seeds]
    out = rebuild(job.S, proj.tri, bary, VN, TN, rm.F, transfer=job.transfer, gradient=job.gradient)
    weights = sampling_weights(job.average, job.S, proj.tri, bary, VN, TN, rm.F)
    t3 = time.perf_counter()
    return i, out, {"weights": weights, "seed": int(job.seeds[i]), "first": int(rm.first), "n_low": int(len(rm.seeds)),
                    "n_repair": int(rm.n_repair), "n_flipped": int(rm.n_flipped), "redrawn": given_up,
                    "remesh_s": t1 - t0, "project_s": t2 - t1, "transfer_s": t3 - t2}


#: The parameters the transfers use (:class:`sshade.params.SShaDeParams`; no low-res ARAP)
TRANSFER_KEYS = ("n_low", "n_samplings", "seed", "gradient", "workers", "anchor", "transfer", "average")
#: The transfers' own defaults over :class:`sshade.params.SShaDeParams`' (the paper's k for §4.2-4.3)
TRANSFER_DEFAULTS = {"n_samplings": 10}


def transfer_params(where: str, params: SShaDeParams | Mapping | None, overrides: Mapping) -> SShaDeParams:
    """The checked parameters of the transfer ``where``: ``params`` (None:
    :data:`TRANSFER_DEFAULTS`) with ``overrides``, which must be of :data:`TRANSFER_KEYS`.
    Raises SShaDeError on a bad value or another parameter."""
    return check_params(TRANSFER_DEFAULTS if params is None else params,
                        **only_params(where, overrides, TRANSFER_KEYS))


def correspondence_transfer(V_M, F, V_S, V_Mprime, params: SShaDeParams | Mapping | None = None,
                            **overrides) -> tuple[np.ndarray, dict]:
    """Encode ``V_S`` in the LRFs of the remeshed ``M`` and decode them on ``M'`` (§4.2-4.3).

    The common core of :func:`isometric_transfer` (``V_S = V_M``) and
    :func:`pose_transfer` (docs/implementation.md, "Implementation notes: sshade/isometric.py").

    Parameters
    ----------
    V_M : (n, 3) float, rest mesh M (any length unit). F : (m, 3) int, faces of M,
        a single-component 2-manifold (boundary allowed).
    V_S : (n, 3) float, positions encoded (1:1 with M, aligned with M in space).
    V_Mprime : (n, 3) float, M in the target pose (1:1 with M).
    params : :class:`sshade.params.SShaDeParams` or a mapping of some of its keys, or None
        (:data:`TRANSFER_DEFAULTS`: 10 samplings, the paper's); ``**overrides`` over it,
        those of :data:`TRANSFER_KEYS` only (meanings and defaults:
        :class:`sshade.params.SShaDeParams`): ``n_low`` (capped at n), ``n_samplings``,
        ``seed``, ``gradient``, ``workers`` (the result does not depend on it), ``anchor``
        (for pose transfer, S's vertex v is anchored at M's vertex v's projection),
        ``transfer``, ``average`` (``"proximity"`` fits here: the low-res positions are
        exact, docs/differences.md).

    Returns
    -------
    V_out : (n, 3) float64, the transferred positions (connectivity F).
    info : dict, ``total_s``, summed ``remesh_s`` / ``project_s`` / ``transfer_s``,
        mean ``n_low`` (actual low-res vertex count), ``seed``, ``sampling_seeds``,
        ``workers`` and per-sampling details in ``samplings``.

    Raises
    ------
    SShaDeError on an invalid mesh (:func:`sshade.mesh.validate.validate_mesh`), position
    arrays of the wrong shape / vertex count / with NaN, a bad parameter or one it does
    not use (:func:`transfer_params`).
    """
    t0 = time.perf_counter()
    arrays = _checked_arrays(V_M, F, V_S, V_Mprime)
    return _transfer(*arrays, transfer_params("correspondence_transfer", params, overrides), t0)


def transfer_with(V_M, F, V_S, V_Mprime, params: SShaDeParams) -> tuple[np.ndarray, dict]:
    """:func:`correspondence_transfer` with its parameters checked already
    (:func:`sshade.params.check_params`; its n_low, n_samplings, seed, workers, gradient
    and anchor are used): the same arrays, result, info and errors."""
    t0 = time.perf_counter()
    return _transfer(*_checked_arrays(V_M, F, V_S, V_Mprime), params, t0)


def _checked_arrays(V_M, F, V_S, V_Mprime) -> tuple:
    """(V, F, half-edges, S, T) of :func:`correspondence_transfer`'s inputs, validated."""
    V, F, he = validate_mesh(V_M, F, name="rest mesh M", return_halfedges=True)
    S = _positions(V_S, len(V), "V_S")
    T = _positions(V_Mprime, len(V), "target pose V_Mprime")
    return V, F, he, S, T


def _transfer(V, F, he, S, T, params: SShaDeParams, t0: float) -> tuple[np.ndarray, dict]:
    """The samplings of :func:`correspondence_transfer` on validated arrays, averaged; its
    info with ``total_s`` counted from ``t0``."""
    n = len(V)
    k = params.n_samplings
    warm_kernels(large_mesh(F))
    n_low = auto_n_low(n) if params.n_low == "auto" else params.n_low
    job = TransferJob(V=V, F=F, S=S, T=T, n_low=int(min(n_low, n)), seeds=sampling_seeds(params.seed, k),
                      topology=mesh_topology(V, F, he), gradient=params.gradient, anchor=params.anchor,
                      transfer=params.transfer, average=params.average)
    workers = pool_size(params.workers, k)
    results: list = [None] * k
    infos: list = [None] * k
    with SamplingPool(job, workers) as pool:
        for f in [pool.submit_with_job(_one, i) for i in range(k)]:
            i, results[i], infos[i] = f.result()
    out = combine(results, [d.pop("weights") for d in infos])  # fixed order: independent of the worker count
    info = {"total_s": time.perf_counter() - t0, "seed": params.seed, "sampling_seeds": job.seeds,
            "n_samplings": k, "workers": workers, "gradient": params.gradient, "anchor": params.anchor,
            "transfer": params.transfer, "average": params.average,
            "samplings": infos}
    for key in ("remesh_s", "project_s", "transfer_s"):
        info[key] = float(np.sum([d[key] for d in infos]))
    info["n_low"] = int(round(np.mean([d["n_low"] for d in infos])))
    info["n_flipped"] = int(np.sum([d["n_flipped"] for d in infos]))
    return out, info


def isometric_transfer(V_rest, F, V_target, params: SShaDeParams | Mapping | None = None,
                       **overrides) -> tuple[np.ndarray, dict]:
    """Rebuild a pose of a subject from its rest pose and a low-res copy of the pose (paper §4.2).

    Only the ~``n_low`` low-res vertices of the target are used (``V_target[seeds]``, per
    sampling); the rest of ``V_target`` is the ground truth the result is compared with.

    Parameters
    ----------
    V_rest : (n, 3) float, rest pose M (any length unit). F : (m, 3) int, its faces
        (single-component 2-manifold, boundary allowed).
    V_target : (n, 3) float, the target pose M' (1:1 with ``V_rest``).
    params, **overrides : as :func:`correspondence_transfer` (10 samplings by default, the
        paper's; the per-sampling seeds in ``info["sampling_seeds"]``).

    Returns
    -------
    V_pred : (n, 3) float64, the rest pose deformed into the target pose (faces F).
    info : dict of timings (seconds), seeds and per-sampling details
        (see :func:`correspondence_transfer`).

    Raises
    ------
    SShaDeError on an invalid mesh, ``V_target`` of another vertex count or shape or
    with NaN/inf, a bad parameter or one it does not use.

    Notes
    -----
    A rigid motion of the rest pose (``V_target = V_rest @ R.T + t``) is reproduced
    exactly, in either gradient mode and with either anchor.

    Examples
    --------
    Example::

        from sshade.isometric import isometric_transfer
        V_pred, info = isometric_transfer(V0, F0, V1, n_low=6000, n_samplings=10)
    """
    n_rest = len(_positions(V_rest, None, "V_rest"))
    T = _positions(V_target, n_rest, "target pose V_target")
    t0 = time.perf_counter()
    p = transfer_params("isometric_transfer", params, overrides)
    return _transfer(*_checked_arrays(V_rest, F, V_rest, T), p, t0)


def pose_transfer(V_M, F, V_S, V_Mprime, params: SShaDeParams | Mapping | None = None, *, align: bool = False,
                  return_info: bool = False, **overrides):
    """Put shape S in the pose of M' (paper §4.3, Fig. "diagrams" b).

    S's vertices are encoded in the frames of M's remesh N and decoded on N' (M's
    low-res vertices in the pose of M'), averaged over ``n_samplings`` samplings (§3.3);
    with ``V_S = V_M`` the result is :func:`isometric_transfer`'s. S must be aligned with
    M in space (``align=True`` moves it rigidly onto M first). Formulas: docs/implementation.md
    ("Implementation notes: sshade/isometric.py").

    Parameters
    ----------
    V_M : (n, 3) float, the rest pose M (any length unit). F : (m, 3) int, faces shared
        by M, S and M' (single-component 2-manifold, boundary allowed).
    V_S : (n, 3) float, the shape to pose (1:1 with M, same connectivity, aligned with M
        in space, e.g. another subject in the same rest pose).
    V_Mprime : (n, 3) float, M in the target pose (1:1 with M).
    params, **overrides : as :func:`correspondence_transfer` (10 samplings by default).
    align : bool, rigidly align S onto M first (for shapes not already aligned).
    return_info : bool, also return the info dict (timings, seeds).

    Returns
    -------
    V_Sprime : (n, 3) float64, S in the pose of M'; with ``return_info`` the tuple
    ``(V_Sprime, info)``.

    Raises
    ------
    SShaDeError on an invalid mesh M, ``V_S`` / ``V_Mprime`` of another vertex count
    or shape or with NaN/inf, a bad parameter or one it does not use.

    Examples
    --------
    Example::

        from sshade.isometric import pose_transfer
        V_Sp = pose_transfer(V_M, F, V_S, V_Mp, n_low=1000, n_samplings=5)
    """
    p = transfer_params("pose_transfer", params, overrides)  # before any work
    if align:
        V_S = rigid_align(V_S, V_M)
    out, info = correspondence_transfer(V_M, F, V_S, V_Mprime, p)
    return (out, info) if return_info else out

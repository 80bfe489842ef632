"""Deformation transfer through a known correspondence: non-rigid isometric deformations
(paper §4.2, Fig. "diagrams" a) and pose transfer (paper §4.3, Fig. "diagrams" b).

Both start from a rest mesh ``M`` and a second shape ``M'`` of the same subject, in
1:1 vertex correspondence with ``M`` (same connectivity), and skip the low-res ARAP of
the handle pipeline: the deformed low-res mesh ``N'`` is read off ``M'`` directly.

Isometric deformation (§4.2), per sampling:

1. remesh ``M`` to ``N`` (:func:`sshade.remesh.remesh`; ``V_N = V_M[seeds]``);
2. ``V_N' = V_M'[seeds]`` (low-res vertices are high-res vertices, and ``M <-> M'`` is 1:1);
3. ``N' = (V_N', T_N)``: the connectivity of ``N``;
4. encode ``M`` in the per-triangle frames of ``N`` (projection P: V_M -> T_N,
   :func:`sshade.projection.project_to_fans`) and decode on ``N'`` (Alg. 1, LRFT).

The k samplings (seeds from :func:`sshade.sampling.sampling_seeds`) are averaged (§3.3),
in the process pool of :mod:`sshade.sampling` (that of :func:`sshade.deform`).

Pose transfer (§4.3): a third shape ``S`` (pose 0 of another subject, 1:1 with ``M``,
same connectivity, aligned with ``M`` in space) is to be put in the pose of ``M'``. The
remesh ``N``, the projection P and the frames are all those of ``M`` (S is never
remeshed or projected); what is encoded is S's vertex positions: for vertex v with
``t = P(v)`` (the triangle of M's vertex v), ``s_t = L_t^-1 (v_S - b_t)`` with L_t, b_t
built on ``N`` (M's positions), then ``v_S' = L'_t s_t + b'_t`` on ``N'`` (M''s
positions). With ``S = M`` this is exactly the isometric transfer.

All positions are in the input's length unit; nothing here reads or writes files.
"""
from __future__ import annotations

import time

import numpy as np

from .deform import auto_n_low, check_params
from .errors import SShaDeError
from .lrf import decode, encode, frame_functions
from .mesh.validate import check_points, validate_mesh
from .projection import project_to_fans
from .remesh import mesh_topology, remesh_drawn
from .sampling import SamplingPool, average, pool_size, sampling_seeds, warm_kernels, worker_state

__all__ = ["isometric_transfer", "pose_transfer", "correspondence_transfer", "rigid_align"]


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


def _one(i: int) -> tuple[int, np.ndarray, dict]:
    """Sampling i: remesh M, project M onto N, encode S on N, decode on N' (Alg. 1)."""
    w = worker_state()
    V, F = w["V"], w["F"]
    t0 = time.perf_counter()
    rm, given_up = remesh_drawn(V, F, w["n_low"], seed=w["seeds"][i], topology=w["topology"])
    t1 = time.perf_counter()
    VN = V[rm.seeds]
    proj = project_to_fans(V, rm.label, VN, rm.F)
    t2 = time.perf_counter()
    axis = frame_functions(VN, rm.F)
    bary = proj.bary if w["anchor"] == "projection" else None  # M's own projection, also for S
    C = encode(w["S"], proj.tri, VN, rm.F, axis, w["gradient"], bary)
    out = decode(C, proj.tri, VN, w["T"][rm.seeds], rm.F, axis, w["gradient"], bary)
    t3 = time.perf_counter()
    return i, out, {"seed": int(w["seeds"][i]), "first": int(rm.first), "n_low": int(len(rm.seeds)),
                    "n_repair": int(rm.n_repair), "n_flipped": int(rm.n_flipped), "redrawn": given_up,
                    "remesh_s": t1 - t0, "project_s": t2 - t1, "transfer_s": t3 - t2}


def correspondence_transfer(V_M, F, V_S, V_Mprime, *, n_low: int = 6000, n_samplings: int = 10, seed: int = 0,
                            gradient: str = "normalized", workers: int | None = None,
                            anchor: str = "projection") -> tuple[np.ndarray, dict]:
    """Encode ``V_S`` in the LRFs of the remeshed ``M`` and decode them on ``M'`` (§4.2-4.3).

    The common core of :func:`isometric_transfer` (``V_S = V_M``) and
    :func:`pose_transfer`; see the module docstring.

    Parameters
    ----------
    V_M : (n, 3) float, rest mesh M (any length unit). F : (m, 3) int, faces of M,
        a single-component 2-manifold (boundary allowed).
    V_S : (n, 3) float, positions encoded (1:1 with M, aligned with M in space).
    V_Mprime : (n, 3) float, M in the target pose (1:1 with M).
    n_low : int >= 4, farthest-point samples per low-res mesh (capped at n), or
        ``"auto"`` (:func:`sshade.deform.auto_n_low`).
    n_samplings : int >= 1, samplings averaged (paper: 5-10).
    seed : int, master seed; sampling i uses ``sampling_seeds(seed, n_samplings)[i]``.
    gradient : ``"normalized"`` (orthonormal frames) or ``"raw"`` (paper's g_t).
    anchor : ``"projection"`` (default) or ``"barycenter"`` (paper Alg. 1): where each
        vertex is anchored in its triangle (:mod:`sshade.lrf`); for pose transfer, S's
        vertex v is anchored at M's vertex v's projection.
    workers : int or None, processes (None: min(k, CPU count)); 1 runs in-process.
        The result does not depend on it.
    n_low, n_samplings, seed, gradient, anchor and workers are checked as :func:`sshade.deform`
    checks them (:func:`sshade.deform.check_params`).

    Returns
    -------
    V_out : (n, 3) float64, the transferred positions (connectivity F).
    info : dict, ``total_s``, summed ``remesh_s`` / ``project_s`` / ``transfer_s``,
        mean ``n_low`` (actual low-res vertex count), ``seed``, ``sampling_seeds``,
        ``workers`` and per-sampling details in ``samplings``.

    Raises
    ------
    SShaDeError on an invalid mesh (:func:`sshade.mesh.validate.validate_mesh`), position
    arrays of the wrong shape / vertex count / with NaN, n_samplings < 1, n_low < 4,
    unknown gradient mode.
    """
    t0 = time.perf_counter()
    V, F, he = validate_mesh(V_M, F, name="rest mesh M", return_halfedges=True)
    n = len(V)
    S = _positions(V_S, n, "V_S")
    T = _positions(V_Mprime, n, "target pose V_Mprime")
    p = check_params(n_low=n_low, n_samplings=n_samplings, seed=seed, workers=workers, gradient=gradient,
                     anchor=anchor)
    n_samplings = p["n_samplings"]
    seeds = sampling_seeds(p["seed"], n_samplings)
    warm_kernels()
    n_low = auto_n_low(n) if p["n_low"] == "auto" else p["n_low"]
    state = dict(V=V, F=F, S=S, T=T, n_low=int(min(n_low, n)), seeds=seeds,
                 topology=mesh_topology(V, F, he), gradient=gradient, anchor=p["anchor"])
    workers = pool_size(p["workers"], n_samplings)
    results: list = [None] * n_samplings
    infos: list = [None] * n_samplings
    with SamplingPool(state, workers) as pool:
        for f in [pool.submit(_one, i) for i in range(n_samplings)]:
            i, results[i], infos[i] = f.result()
    out = average(results)  # fixed order: independent of the worker count
    info = {"total_s": time.perf_counter() - t0, "seed": p["seed"], "sampling_seeds": seeds,
            "n_samplings": n_samplings, "workers": workers, "gradient": gradient, "anchor": p["anchor"],
            "samplings": infos}
    for k in ("remesh_s", "project_s", "transfer_s"):
        info[k] = float(np.sum([d[k] for d in infos]))
    info["n_low"] = int(round(np.mean([d["n_low"] for d in infos])))
    info["n_flipped"] = int(np.sum([d["n_flipped"] for d in infos]))
    return out, info


def isometric_transfer(V_rest, F, V_target, *, n_low: int = 6000, n_samplings: int = 10, seed: int = 0,
                       gradient: str = "normalized", workers: int | None = None,
                       anchor: str = "projection") -> tuple[np.ndarray, dict]:
    """Rebuild a pose of a subject from its rest pose and a low-res copy of the pose (paper §4.2).

    Steps (per sampling, then averaged over ``n_samplings``, §3.3): remesh the rest
    pose M to N; take the low-res vertices in the target pose through the 1:1
    correspondence (``V_target[seeds]``) with N's connectivity as N'; transfer M with
    the per-triangle LRFs (Alg. 1). Only the ~``n_low`` low-res vertices of the target
    are used: the rest of ``V_target`` is the ground truth the result is compared with.

    Parameters
    ----------
    V_rest : (n, 3) float, rest pose M (any length unit). F : (m, 3) int, its faces
        (single-component 2-manifold, boundary allowed).
    V_target : (n, 3) float, the target pose M' (1:1 with ``V_rest``).
    n_low : int, farthest-point samples per low-res mesh (paper: ~6000); capped at n.
    n_samplings : int, samplings averaged (paper: 10).
    seed : int, master seed (per-sampling seeds in ``info["sampling_seeds"]``).
    gradient : ``"normalized"`` (default) or ``"raw"``. anchor : ``"projection"``
        (default) or ``"barycenter"`` (paper), see :func:`correspondence_transfer`.
    workers : int or None, processes (None: min(k, CPU count)); 1 runs in-process.

    Returns
    -------
    V_pred : (n, 3) float64, the rest pose deformed into the target pose (faces F).
    info : dict of timings (seconds), seeds and per-sampling details
        (see :func:`correspondence_transfer`).

    Raises
    ------
    SShaDeError on an invalid mesh, ``V_target`` of another vertex count or shape or
    with NaN/inf, n_samplings < 1, n_low < 4, unknown gradient mode.

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
    return correspondence_transfer(V_rest, F, V_rest, T, n_low=n_low, n_samplings=n_samplings, seed=seed,
                                   gradient=gradient, workers=workers, anchor=anchor)


def pose_transfer(V_M, F, V_S, V_Mprime, *, n_low: int = 6000, n_samplings: int = 10, seed: int = 0,
                  gradient: str = "normalized", workers: int | None = None, align: bool = False,
                  return_info: bool = False, anchor: str = "projection"):
    """Put shape S in the pose of M' (paper §4.3, Fig. "diagrams" b).

    M is remeshed to N and projected onto it (P: V_M -> T_N) exactly as in
    :func:`isometric_transfer`; then, through the 1:1 correspondence M <-> S, each S
    vertex v is written in the frame of ``t = P(v)`` built on N (M's positions):
    ``s_t = L_t^-1 (v_S - a(v))``, and rebuilt on ``N' = (V_M'[seeds], T_N)``:
    ``v_S' = L'_t s_t + a'(v)``, the anchor a(v) the projection of M's vertex v onto t
    (``anchor="projection"``) or b_t (``"barycenter"``, paper). Averaged over ``n_samplings`` samplings (§3.3).
    With ``V_S = V_M`` the result is :func:`isometric_transfer`'s.

    S must be aligned with M in space (paper §4.3): the offsets ``v_S - b_t`` are
    rotated with the local frames, so a global misplacement of S would be rotated too.
    ``align=True`` first moves S rigidly onto M (:func:`rigid_align`, through the 1:1
    correspondence); the result is then in M''s placement.

    Parameters
    ----------
    V_M : (n, 3) float, the rest pose M (any length unit). F : (m, 3) int, faces shared
        by M, S and M' (single-component 2-manifold, boundary allowed).
    V_S : (n, 3) float, the shape to pose (1:1 with M, same connectivity, aligned with M
        in space, e.g. another subject in the same rest pose).
    V_Mprime : (n, 3) float, M in the target pose (1:1 with M).
    n_low, n_samplings, seed, gradient, workers, anchor : as in :func:`isometric_transfer`.
    align : bool, rigidly align S onto M first (for shapes not already aligned).
    return_info : bool, also return the info dict (timings, seeds).

    Returns
    -------
    V_Sprime : (n, 3) float64, S in the pose of M'; with ``return_info`` the tuple
    ``(V_Sprime, info)``.

    Raises
    ------
    SShaDeError on an invalid mesh M, ``V_S`` / ``V_Mprime`` of another vertex count
    or shape or with NaN/inf, n_samplings < 1, n_low < 4, unknown gradient mode.

    Examples
    --------
    Example::

        from sshade.isometric import pose_transfer
        V_Sp = pose_transfer(V_M, F, V_S, V_Mp, n_low=1000, n_samplings=5)
    """
    if align:
        V_S = rigid_align(V_S, V_M)
    out, info = correspondence_transfer(V_M, F, V_S, V_Mprime, n_low=n_low, n_samplings=n_samplings, seed=seed,
                                        gradient=gradient, workers=workers, anchor=anchor)
    return (out, info) if return_info else out

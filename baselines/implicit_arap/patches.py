"""Local patch meshing and the patch ARAP energy of Implicit-ARAP (Baieri, Maggioli,
Lähner, Melzi, Rodolà 2024, §4; reference code github.com/dbaieri/implicit-arap, MIT
licence: ``DeformTrainer.train_step`` and ``PatchARAPLoss``). Our own code.

A patch is ``k`` points of a disk in the tangent plane of a centre (centre first),
Delaunay-triangulated once in the plane and projected onto the centre's level set of the
SDF; all patches of one step share the disk and its triangles. The energy is the ARAP
energy of Sorkine & Alexa 2007 on each patch, the rotation given by the deformation field.
Cotangent weights: correct by default, the reference code's with ``reference=True``
(docs/implementation.md, "Implementation notes: baselines/implicit_arap/patches.py").
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from sshade.errors import SShaDeError

from .backend import torch
from .sdf import project_to_level, value_and_grad

__all__ = [
    "corner_cotangents",
    "cot_weights",
    "disk",
    "edge_structure",
    "mesh_patches",
    "patch_energy",
    "tangent_frames",
]


def disk(k: int, radius: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``k`` points of a disk (the centre, then ``k - 1`` uniform by area) and their
    Delaunay triangles.

    Parameters
    ----------
    k : int >= 4; radius : float > 0 (normalised units); rng : numpy Generator.

    Returns
    -------
    points : (k, 2) float64, ``points[0] = 0``; tris : (m, 3) int64.

    Raises
    ------
    SShaDeError when ``k < 4``.
    """
    if k < 4:
        raise SShaDeError(f"Implicit-ARAP: patch_points must be at least 4, got {k}")
    rho = radius * np.sqrt(rng.uniform(0.0, 1.0, k - 1))
    theta = rng.uniform(0.0, 2 * np.pi, k - 1)
    P = np.concatenate([np.zeros((1, 2)), np.stack([rho * np.cos(theta), rho * np.sin(theta)], 1)])
    return P, Delaunay(P).simplices.astype(np.int64)


def tangent_frames(normals):
    """Two unit tangents orthogonal to each unit normal.

    Parameters
    ----------
    normals : (P, 3) tensor of unit vectors.

    Returns
    -------
    (t1, t2) : two (P, 3) tensors, ``(t1, t2, n)`` a right-handed orthonormal frame.
    """
    n = normals
    helper = torch.zeros_like(n)
    helper[torch.arange(len(n)), n.abs().argmin(dim=1)] = 1.0  # the axis least aligned with n
    t1 = torch.nn.functional.normalize(torch.linalg.cross(n, helper, dim=-1), dim=-1)
    return t1, torch.linalg.cross(n, t1, dim=-1)


def mesh_patches(sdf, centres, disk_points: np.ndarray, iters: int):
    """Place the disk in each centre's tangent plane (normal = normalised SDF gradient)
    and project it ``iters`` times onto the centre's level set
    (:func:`baselines.implicit_arap.sdf.project_to_level`).

    Parameters
    ----------
    sdf : callable (N, 3) -> (N,); centres : (P, 3) tensor;
    disk_points : (k, 2) float64 from :func:`disk`; iters : int >= 0.

    Returns
    -------
    (P, k, 3) tensor (detached), ``[:, 0]`` the centres themselves.
    """
    f, g = value_and_grad(sdf, centres)
    t1, t2 = tangent_frames(torch.nn.functional.normalize(g, dim=-1))
    d = torch.as_tensor(disk_points, dtype=centres.dtype, device=centres.device)
    X = centres[:, None, :] + d[None, :, :1] * t1[:, None, :] + d[None, :, 1:] * t2[:, None, :]
    P, k = X.shape[:2]
    X = project_to_level(sdf, X.reshape(-1, 3), f.repeat_interleave(k), iters).reshape(P, k, 3)
    X[:, 0] = centres.detach()
    return X


def edge_structure(tris: np.ndarray, reference: bool = False) -> dict:
    """Index arrays of the energy's directed edges for one triangulation.

    Returns
    -------
    dict with ``src``, ``dst`` (e,) int64, the directed edges the energy sums over, and:
    default: ``corner_edge`` (m, 3), the position in ``src`` of the edge ``b -> c``
    opposite each corner ``a`` of each triangle (``c -> b`` is at that position plus
    the number of undirected edges); ``reference=True``: ``last`` (m * 3,) bool, the
    corner cotangents that survive the overwrite (the reference's edge list order).
    """
    m = len(tris)
    if reference:
        src = np.concatenate([tris[:, 0], tris[:, 1], tris[:, 0]])
        dst = np.concatenate([tris[:, 1], tris[:, 2], tris[:, 2]])
        key = src * (tris.max() + 1) + dst
        _, first_of_reversed = np.unique(key[::-1], return_index=True)
        last = np.zeros(3 * m, bool)
        last[3 * m - 1 - first_of_reversed] = True
        return {"src": src, "dst": dst, "last": last}
    opposite = np.stack([tris[:, [1, 2]], tris[:, [2, 0]], tris[:, [0, 1]]], 1).reshape(-1, 2)  # edge facing corner
    und, inv = np.unique(np.sort(opposite, axis=1), axis=0, return_inverse=True)
    return {"src": np.concatenate([und[:, 0], und[:, 1]]), "dst": np.concatenate([und[:, 1], und[:, 0]]),
            "corner_edge": inv.reshape(m, 3), "n_edges": len(und)}


def corner_cotangents(X, tris):
    """(P, m, 3) cotangents of the angles at the corners of each triangle of each patch."""
    C = X[:, torch.as_tensor(tris, device=X.device)]  # (P, m, 3, 3): patch, triangle, corner, xyz
    u = C[:, :, [1, 2, 0]] - C
    v = C[:, :, [2, 0, 1]] - C
    cross = torch.linalg.cross(u, v, dim=-1).norm(dim=-1).clamp_min(1e-20)
    return (u * v).sum(-1) / cross


def cot_weights(X, tris: np.ndarray, edges: dict):
    """Weight of each directed edge of :func:`edge_structure` in each patch.

    Parameters
    ----------
    X : (P, k, 3) tensor of rest positions; tris : (m, 3) int64; edges : the dict of
        :func:`edge_structure` for ``tris`` (its mode picks the weights).

    Returns
    -------
    (P, e) tensor: default ``(cot a + cot b) / 2`` (one cotangent on a boundary edge),
    the same value in both directions; ``reference`` mode: the reference code's weights
    (docs/implementation.md, "Implementation notes: baselines/implicit_arap/patches.py").
    """
    cot = corner_cotangents(X, tris)
    P = X.shape[0]
    if "corner_edge" in edges:
        ne = edges["n_edges"]
        idx = torch.as_tensor(edges["corner_edge"].reshape(-1), device=X.device)
        w = torch.zeros(P, ne, dtype=X.dtype, device=X.device).index_add_(1, idx, 0.5 * cot.reshape(P, -1))
        return torch.cat([w, w], dim=1)
    k = X.shape[1]
    vals = torch.cat([cot[:, :, 0], cot[:, :, 1], cot[:, :, 2]], dim=1)  # reference order: v0, v1, v2 blocks
    keep = torch.as_tensor(edges["last"], device=X.device)
    src, dst = (torch.as_tensor(edges[s], device=X.device) for s in ("src", "dst"))
    W = torch.zeros(P, k, k, dtype=X.dtype, device=X.device)
    W[:, src[keep], dst[keep]] = vals[:, keep]
    W = W + W.transpose(1, 2)
    return W[:, src, dst]


def patch_energy(X, R, TX, tris: np.ndarray, edges: dict | None = None, weights=None):
    """Patch ARAP energy ``sum_ij w_ij |R_i (x_i - x_j) - (T(x_i) - T(x_j))|^2`` over
    the directed edges of each patch, averaged over patches.

    Parameters
    ----------
    X : (P, k, 3) rest positions; R : (P, k, 3, 3) rotations ``R(x_i)``;
    TX : (P, k, 3) deformed positions ``T(x_i)``; tris : (m, 3) the shared triangles;
    edges : :func:`edge_structure` of ``tris`` (default: the correct weights);
    weights : (P, e) precomputed :func:`cot_weights` (default: computed from ``X``).

    Returns
    -------
    scalar tensor (normalised units squared); zero for a rigid ``T``.
    """
    edges = edge_structure(tris) if edges is None else edges
    w = cot_weights(X, tris, edges) if weights is None else weights
    src, dst = (torch.as_tensor(edges[s], device=X.device) for s in ("src", "dst"))
    e = X[:, src] - X[:, dst]
    r = (R[:, src] @ e[..., None])[..., 0] - (TX[:, src] - TX[:, dst])
    return (w * (r * r).sum(-1)).sum(-1).mean()

"""How the k samplings' results are averaged (paper §3.3: a plain mean), and the
per-vertex weights of the alternatives.

``average="uniform"`` is the paper's mean (:func:`sshade.sampling.average`);
``"proximity"`` weights sampling s at vertex v by 1 / (eps + q_s(v)), q_s(v) =
sum_k b_k |v - N_k|^2 the second moment of v about its low-res triangle's corners (zero
at a low-res vertex, where the transfer is exact; known before the targets);
``"distortion"`` by 1 / (eps + s_t)^2, s_t = sum |log sigma_i| of the deformation
gradient of v's deformed low-res triangle. Measured: docs/differences.md M10.
"""
from __future__ import annotations

import numpy as np

from .mesh.bounds import bounding_box
from .sampling import average
from .smooth_transfer import triangle_jacobians

__all__ = ["AVERAGES", "proximity_weights", "distortion_weights", "sampling_weights", "normalize_weights",
           "weighted_sum", "combine"]

AVERAGES = ("uniform", "proximity", "distortion")
_EPS_Q = 1e-12     # of q, relative to the squared bounding-box diagonal of the low-res mesh
_EPS_S = 1e-3      # of s_t, dimensionless


def proximity_weights(V: np.ndarray, tri: np.ndarray, bary: np.ndarray | None, VN: np.ndarray,
                      FN: np.ndarray) -> np.ndarray:
    """Weights 1 / (eps + q(v)) with q(v) = sum_k b_k |v - N_k|^2 (module docstring).

    Parameters
    ----------
    V : (n, 3) float64 high-res rest positions. tri : (n,) int triangle P(v).
    bary : (n, 3) float64 barycentric coordinates of v's projection, or None for the
        barycenter's thirds. VN : (k, 3) float64 rest low-res positions. FN : (t, 3) int64.

    Returns
    -------
    (n,) float64, positive and finite (eps: 1e-12 of the squared bounding-box diagonal
    of ``VN``, so the weights scale with the mesh and stay finite at a low-res vertex).
    """
    C = VN[FN[tri]]                                     # (n, 3 corners, 3)
    d2 = ((V[:, None, :] - C) ** 2).sum(axis=2)         # (n, 3)
    q = d2.mean(axis=1) if bary is None else np.einsum("nk,nk->n", bary, d2)
    lo, hi = bounding_box(VN)
    eps = _EPS_Q * float(np.sum((hi - lo) ** 2))
    return 1.0 / (eps + np.maximum(q, 0.0))


def distortion_weights(tri: np.ndarray, VN: np.ndarray, VN_def: np.ndarray, FN: np.ndarray) -> np.ndarray:
    """Weights 1 / (eps + s_t)^2 of each high-res vertex's low-res triangle t, s_t =
    sum_i |log sigma_i| over the singular values of its deformation gradient
    (:func:`sshade.smooth_transfer.triangle_jacobians`; 0 for a rigid motion).

    Parameters
    ----------
    tri : (n,) int triangle P(v). VN, VN_def : (k, 3) float64 rest / deformed low-res
    positions. FN : (t, 3) int64.

    Returns
    -------
    (n,) float64, positive and finite.
    """
    J, _ = triangle_jacobians(VN, VN_def, FN)
    s = np.abs(np.log(np.linalg.svd(J, compute_uv=False))).sum(axis=1)
    return (1.0 / (_EPS_S + s) ** 2)[tri]


def sampling_weights(average: str, V: np.ndarray, tri: np.ndarray, bary: np.ndarray | None, VN: np.ndarray,
                     VN_def: np.ndarray, FN: np.ndarray) -> np.ndarray | None:
    """One sampling's weights for ``average`` (:data:`AVERAGES`): None for ``"uniform"``,
    else :func:`proximity_weights` or :func:`distortion_weights` ((n,) float64); the
    arrays as there (``VN_def`` (k, 3), the deformed low-res positions)."""
    if average == "proximity":
        return proximity_weights(V, tri, bary, VN, FN)
    if average == "distortion":
        return distortion_weights(tri, VN, VN_def, FN)
    return None


def combine(results: list, weights: list) -> np.ndarray:
    """The samplings' results averaged: the plain mean (:func:`sshade.sampling.average`'s
    additions) when every weight is None, else :func:`weighted_sum` of the normalised
    weights.

    Parameters
    ----------
    results : list of k (n, 3) float64. weights : list of k (n,) float64 or None.

    Returns
    -------
    (n, 3) float64.
    """
    if all(w is None for w in weights):
        return average(results)
    return weighted_sum(results, normalize_weights(weights))


def normalize_weights(weights: list) -> list:
    """The k samplings' weights divided by their sum at each vertex.

    Parameters
    ----------
    weights : list of k (n,) float64 arrays, positive.

    Returns
    -------
    list of k (n, 1) float64 arrays summing to 1 at each vertex.
    """
    total = np.array(weights[0], np.float64)
    for w in weights[1:]:
        total += w
    return [(w / total)[:, None] for w in weights]


def weighted_sum(results: list, weights: list) -> np.ndarray:
    """sum_s weights[s] * results[s], added in sampling order.

    Parameters
    ----------
    results : list of k (n, 3) float64 arrays. weights : list of k (n, 1) float64
        (:func:`normalize_weights`).

    Returns
    -------
    (n, 3) float64.
    """
    out = weights[0] * results[0]
    for w, r in zip(weights[1:], results[1:]):
        out += w * r
    return out

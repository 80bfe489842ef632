"""Landmark-driven handle extraction for DeFAUST-style deformation cases.

Source: SShaDe paper (Maggioli et al., Eurographics 2025), appendix "DeFAUST dataset".
For each hand-picked landmark vertex ``l`` on the rest pose ``M`` we take a random set
``H_l`` of vertices near ``l``; with the registration correspondence
``pi : M -> M'`` (same vertex index in the target pose ``M'``) we compute

    Delta_l = sum_{v in H_l} || v - pi(v) ||

and mark the group *static* (targets = rest positions) when it barely moves, *dynamic*
(targets = positions in the target pose) otherwise.

Choices the paper leaves open, fixed here:

- "near ``l``" = the ``neighbourhood`` vertices geodesically nearest to ``l``, where
  geodesic distance is the shortest path along mesh edges weighted by their Euclidean
  length (Dijkstra on the edge graph), ties broken by vertex index;
- ``H_l`` = ``n_per_landmark`` of those drawn without replacement with
  ``numpy.random.default_rng(seed)``, landmark by landmark in the given order;
- the static test compares the *mean* displacement ``Delta_l / n_per_landmark`` (mesh
  units) with ``static_threshold``, so the threshold does not depend on the group size;
- groups may overlap: a vertex drawn by several landmarks is kept once, in its first
  group (landmark order).

Pure functions over arrays; no file I/O.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from defaust.handles import edge_graph, geodesic_neighbourhood  # one implementation, data stage
from sshade.errors import SShaDeError

__all__ = ["LandmarkHandles", "landmark_handles", "geodesic_neighbourhood", "edge_graph"]


@dataclass(frozen=True)
class LandmarkHandles:
    """Handles extracted around landmarks (output of :func:`landmark_handles`).

    Attributes
    ----------
    handles : (h,) int64 unique vertex indices, ``h <= L * n_per_landmark``.
    targets : (h, 3) float64 target positions (mesh units): rest position for a handle
        of a static group, target-pose position for a dynamic one.
    group : (h,) int64 index into ``landmarks`` of the group each handle belongs to.
    static : (h,) bool, the handle's group is static.
    landmarks : (L,) int64 landmark vertex indices, as given.
    delta : (L,) float64 ``Delta_l``, summed displacement of the group's
        ``n_per_landmark`` sampled vertices between rest and target pose (mesh units),
        computed before de-duplication.
    group_static : (L,) bool, ``delta / n_per_landmark < static_threshold``.
    """

    handles: np.ndarray
    targets: np.ndarray
    group: np.ndarray
    static: np.ndarray
    landmarks: np.ndarray
    delta: np.ndarray
    group_static: np.ndarray

    @property
    def n_static(self) -> int:
        """Number of handles in static groups."""
        return int(self.static.sum())

    @property
    def n_dynamic(self) -> int:
        """Number of handles in dynamic groups."""
        return int((~self.static).sum())


def landmark_handles(V_rest, F, V_target, landmarks, *, n_per_landmark: int = 30,
                     neighbourhood: int = 90, static_threshold: float = 0.02,
                     seed: int = 0) -> LandmarkHandles:
    """Static and dynamic handle groups around landmarks (DeFAUST protocol).

    Parameters
    ----------
    V_rest : (n, 3) float rest-pose positions (mesh units; metres for FAUST).
    F : (m, 3) int faces shared by both poses.
    V_target : (n, 3) float target-pose positions, in vertex-to-vertex correspondence
        with ``V_rest`` (row ``i`` is ``pi(V_rest[i])``).
    landmarks : (L,) int landmark vertex indices, unique.
    n_per_landmark : int, vertices drawn per landmark (paper: 30).
    neighbourhood : int, size of the geodesic neighbourhood they are drawn from
        (``>= n_per_landmark``).
    static_threshold : float, mesh units: a group whose mean displacement
        ``Delta_l / n_per_landmark`` is below it is static. Default 0.02 (2 cm on FAUST).
    seed : int, seed of ``numpy.random.default_rng`` for the draws.

    Returns
    -------
    LandmarkHandles

    Raises
    ------
    SShaDeError
        Shape mismatch, NaN/inf positions, landmark indices out of range or repeated,
        ``n_per_landmark`` not in ``[1, neighbourhood]``, ``neighbourhood > n``,
        negative threshold.

    Examples
    --------
    >>> H = landmark_handles(V0, F, V1, [414, 2445], seed=0)  # doctest: +SKIP
    >>> H.handles.shape, H.targets.shape  # doctest: +SKIP
    ((60,), (60, 3))
    """
    V = np.asarray(V_rest, np.float64)
    W = np.asarray(V_target, np.float64)
    F = np.asarray(F)
    if V.ndim != 2 or V.shape[1] != 3:
        raise SShaDeError(f"V_rest must have shape (n, 3), got {V.shape}")
    if W.shape != V.shape:
        raise SShaDeError(f"V_target must match V_rest in shape: {W.shape} vs {V.shape} "
                          "(the poses must be in vertex-to-vertex correspondence)")
    if not (np.isfinite(V).all() and np.isfinite(W).all()):
        raise SShaDeError("V_rest or V_target contains NaN/inf")
    if F.ndim != 2 or F.shape[1] != 3 or not np.issubdtype(F.dtype, np.integer):
        raise SShaDeError(f"F must be an (m, 3) integer array, got {F.shape} {F.dtype}")
    F = F.astype(np.int64)
    n = len(V)
    if F.size and (F.min() < 0 or F.max() >= n):
        raise SShaDeError(f"F has vertex indices outside [0, {n})")
    L = np.asarray(landmarks)
    if L.ndim != 1 or L.size == 0 or not np.issubdtype(L.dtype, np.integer):
        raise SShaDeError(f"landmarks must be a non-empty 1-D integer array, got {np.shape(landmarks)}")
    L = L.astype(np.int64)
    if (L < 0).any() or (L >= n).any():
        raise SShaDeError(f"landmark index {int(L[(L < 0) | (L >= n)][0])} is out of range [0, {n})")
    if len(np.unique(L)) != len(L):
        raise SShaDeError("landmarks contain duplicate vertex indices")
    n_per_landmark, neighbourhood = int(n_per_landmark), int(neighbourhood)
    if not 1 <= n_per_landmark <= neighbourhood:
        raise SShaDeError(f"n_per_landmark must be in [1, neighbourhood={neighbourhood}], got {n_per_landmark}")
    if neighbourhood > n:
        raise SShaDeError(f"neighbourhood={neighbourhood} exceeds the vertex count {n}")
    if not np.isfinite(static_threshold) or static_threshold < 0:
        raise SShaDeError(f"static_threshold must be a finite number >= 0, got {static_threshold}")

    nbhd = geodesic_neighbourhood(V, F, L, neighbourhood)
    rng = np.random.default_rng(seed)
    disp = np.linalg.norm(W - V, axis=1)
    groups, delta = [], np.empty(len(L))
    for i in range(len(L)):
        pick = np.sort(rng.choice(nbhd[i], size=n_per_landmark, replace=False))
        groups.append(pick)
        delta[i] = disp[pick].sum()
    group_static = delta / n_per_landmark < static_threshold

    allv = np.concatenate(groups)
    allg = np.repeat(np.arange(len(L), dtype=np.int64), n_per_landmark)
    _, first = np.unique(allv, return_index=True)
    keep = np.sort(first)  # first occurrence, in landmark order
    h, g = allv[keep].astype(np.int64), allg[keep]
    st = group_static[g]
    T = np.where(st[:, None], V[h], W[h])
    return LandmarkHandles(handles=h, targets=np.ascontiguousarray(T), group=g, static=st,
                           landmarks=L, delta=delta, group_static=group_static)

"""The low-res faces of a Voronoi decomposition and the repair of flipped ones (paper §3.1).

:func:`nerve_faces` (one low-res face per label triple carried by a high-res face),
:func:`flipped_faces` (normal opposing the surface they stand for),
:func:`degenerate_faces` (almost no area for their size) and :func:`voronoi_vertex_seeds`
(a seed at each bad face's Voronoi vertex, after Delaunay refinement: Chew 1989; Ruppert
1995). Repairing flipped faces is a departure from the paper; why and how: docs/implementation.md
("Implementation notes: sshade/remesh_repair.py").
"""
from __future__ import annotations

import numpy as np

from .unique import unique_int

__all__ = ["nerve_faces", "flipped_faces", "degenerate_faces", "faces_to_repair", "fixed_faces", "voronoi_vertex_seeds",
           "MIN_FACE_QUALITY"]

#: A low-res face is *degenerate* when twice its area is at most this fraction of its
#: longest edge squared (its height over that edge, relative to the edge): its cotangent
#: weights then exceed about ``1 / MIN_FACE_QUALITY`` in magnitude, or are not finite
#: (libigl's Heron formula gives a zero area well before the cross product does).
MIN_FACE_QUALITY = 1e-4


def nerve_faces(Fc: np.ndarray, lab: np.ndarray, f3: np.ndarray, nseeds: int,
                unique_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Low-res faces: the label triples of the three-label high-res faces.

    Parameters
    ----------
    Fc : (m + b, 3) int64 high-res faces, boundary loops coned to virtual vertices
        (:class:`sshade.remesh.MeshTopology`).
    lab : (n + loops,) int labels, cone vertex ``n + i`` labelled ``nseeds + i``.
    f3 : (t3,) int64 the faces of ``Fc`` that carry three labels, in face order.
    nseeds : int, number of seeds (labels ``>= nseeds`` are cone vertices).
    unique_only : bool, keep only the triples carried by exactly one face (the faces
        of the nerve that are already valid while the closed-ball property fails; when
        it holds every triple is on one face).

    Returns
    -------
    keepf : (t,) int64, the high-res face (a Voronoi vertex) of each low-res face.
    FN : (t, 3) int64, low-res faces (labels, orientation of the high-res face), those
        touching a cone vertex dropped.
    """
    L3 = lab[Fc[f3]].astype(np.int64)
    keep = (L3 < nseeds).all(axis=1)
    if unique_only and len(f3):
        S = np.sort(L3, axis=1)
        nl = int(lab.max()) + 1
        _, inv, cnt = unique_int((S[:, 0] * nl + S[:, 1]) * nl + S[:, 2], return_inverse=True,
                                 return_counts=True)
        keep &= cnt[inv] == 1
    return f3[keep], L3[keep]


def flipped_faces(V: np.ndarray, vnormals: np.ndarray, seeds: np.ndarray, FN: np.ndarray) -> np.ndarray:
    """(t,) bool, low-res faces whose normal opposes the high-res surface.

    Parameters
    ----------
    V : (n, 3) float64 high-res vertices; vnormals : (n, 3) float64 their normals.
    seeds : (k,) int64 high-res index of each low-res vertex; FN : (t, 3) int64 low-res
        faces. A face is flipped when its normal has a non-positive dot product with
        the sum of the high-res normals at its three seeds."""
    return _flipped(_edges_normal(V[seeds], FN)[0], vnormals, seeds, FN)


def _flipped(n: np.ndarray, vnormals: np.ndarray, seeds: np.ndarray, FN: np.ndarray) -> np.ndarray:
    """(t,) bool, the faces whose normal ``n`` (t, 3) has a non-positive dot product with
    the sum of the high-res normals at their three seeds."""
    return np.einsum("ij,ij->i", n, vnormals[seeds[FN]].sum(axis=1)) <= 0


def _degenerate(n: np.ndarray, longest: np.ndarray, min_quality: float) -> np.ndarray:
    """(t,) bool, ``|n| <= min_quality * longest`` (NaN included), from :func:`_edges_normal`."""
    return ~(np.sqrt(np.einsum("ij,ij->i", n, n)) > min_quality * longest)


def _edges_normal(P: np.ndarray, FN: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face's unnormalised normal (t, 3) and longest squared edge length (t,)."""
    A, B, C = P[FN[:, 0]], P[FN[:, 1]], P[FN[:, 2]]
    a, b, c = B - A, C - A, C - B
    n = np.empty_like(a)
    n[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    n[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    n[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    sq = np.stack([np.einsum("ij,ij->i", e, e) for e in (a, b, c)])
    return n, sq.max(axis=0)


def degenerate_faces(P: np.ndarray, FN: np.ndarray, min_quality: float = MIN_FACE_QUALITY) -> np.ndarray:
    """(t,) bool, low-res faces with (almost) no area for their size (:data:`MIN_FACE_QUALITY`).

    Parameters
    ----------
    P : (k, 3) float64 low-res vertex positions; FN : (t, 3) int64 low-res faces.
    min_quality : float, the bound on ``|cross| / longest_edge**2`` (a NaN counts as degenerate).
    """
    return _degenerate(*_edges_normal(P, FN), min_quality)


def faces_to_repair(V: np.ndarray, vnormals: np.ndarray, seeds: np.ndarray, FN: np.ndarray,
                    fixed: np.ndarray | None = None) -> np.ndarray:
    """(t,) bool, low-res faces the remesher repairs: flipped (:func:`flipped_faces`) or
    degenerate (:func:`degenerate_faces`, which the low-res ARAP could hardly weigh), except
    degenerate faces whose three corners are ``fixed`` (:func:`fixed_faces`: no seed added
    removes them). Arguments as :func:`flipped_faces`, ``fixed`` (n,) bool or None; one
    pass over the faces for both."""
    n, longest = _edges_normal(V[seeds], FN)
    deg = _degenerate(n, longest, MIN_FACE_QUALITY)
    if fixed is not None and deg.any():
        deg &= ~fixed_faces(fixed, seeds, FN)
    return _flipped(n, vnormals, seeds, FN) | deg


def fixed_faces(fixed: np.ndarray, seeds: np.ndarray, FN: np.ndarray) -> np.ndarray:
    """(t,) bool, low-res faces whose three corners are ``fixed`` high-res vertices ((n,)
    bool; the required seeds, i.e. the handles): e.g. an input sliver triangle whose
    corners are all handles stays a low-res face whatever seeds are added, so the remesher
    neither repairs nor redraws for it; its cotangent weights are finite (an input face has
    area, :func:`sshade.mesh.validate.validate_mesh`) and join only handle vertices."""
    return fixed[seeds[FN]].all(axis=1)


def voronoi_vertex_seeds(Fc: np.ndarray, faces: np.ndarray, FN: np.ndarray, label: np.ndarray,
                         dist: np.ndarray) -> np.ndarray:
    """Repair seeds for flipped low-res faces: the Voronoi vertex of each (see module).

    Parameters
    ----------
    Fc : (m + b, 3) int64 coned high-res faces; faces : (f,) int64 the three-label
        high-res face of each flipped low-res face (``keepf[flipped]`` of
        :func:`nerve_faces`; no cone vertex on them); FN : (f, 3) int64 the flipped
        low-res faces (labels).
    label : (n,) int Voronoi region and dist : (n,) float64 distance to its seed of
        every high-res vertex.

    Returns
    -------
    (s,) int64 sorted unique high-res vertices, s <= f: on each face the vertex farthest
    from its seed (the first on ties); where all three are seeds already (distance 0),
    the farthest vertex of the union of the three regions instead.
    """
    T = Fc[faces]
    v = T[np.arange(len(T)), dist[T].argmax(axis=1)]
    dead = dist[v] == 0
    if dead.any():
        v[dead] = _farthest_in_regions(FN[dead], label, dist)
    return unique_int(v[dist[v] > 0])


def _farthest_in_regions(FN: np.ndarray, label: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(f,) int64, for each low-res face of FN (f, 3), the vertex of largest ``dist`` in
    the union of its three regions (the first on ties)."""
    vv = np.flatnonzero(np.isin(label, FN.ravel()))
    best = np.full(int(FN.max()) + 1, -1, np.int64)
    order = np.lexsort((vv, -dist[vv], label[vv]))  # per region: farthest, then smallest index
    reg = label[vv[order]]
    first = np.r_[True, reg[1:] != reg[:-1]]
    best[reg[first]] = vv[order][first]
    per_face = best[FN]
    return per_face[np.arange(len(FN)), dist[per_face].argmax(axis=1)]

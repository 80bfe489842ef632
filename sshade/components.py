"""Meshes with several connected components (scans, characters with eyes and teeth):
each component holding handles is deformed by the chosen method, each one without follows
its nearest deformed component rigidly (:func:`deform_components`, :func:`rigid_follow`;
:class:`ComponentWise` wraps any :class:`sshade.method_interface.Deformer`).

Used by :func:`sshade.deform`, the evaluator and ``python -m sshade deform``. The rule of
the rigid following: docs/implementation.md ("Implementation notes: sshade/components.py").
"""
from __future__ import annotations

import time

import numpy as np

from .arap import rigid_fit
from .errors import SShaDeError
from .mesh.validate import validate_handles, validate_mesh

__all__ = ["component_labels", "n_components", "drop_unreferenced", "rigid_follow", "deform_components",
           "ComponentWise", "MIN_PATCH_FACES"]

#: Fewest triangles of the nearest deformed component a handle-less component's rigid
#: motion is fitted to.
MIN_PATCH_FACES = 16


def component_labels(F, n: int) -> tuple[int, np.ndarray]:
    """Connected components of a triangle mesh (vertices linked by face edges).

    Parameters
    ----------
    F : (m, 3) int faces, indices in ``[0, n)``. n : int, vertex count.

    Returns
    -------
    ncomp : int; labels : (n,) int64 component of each vertex (an unreferenced vertex
    is a component of its own), numbered by first vertex.

    Raises
    ------
    SShaDeError if ``F`` is not (m, 3) with indices in ``[0, n)``.

    Examples
    --------
    >>> component_labels(np.array([[0, 1, 2], [3, 4, 5]]), 6)[0]
    2
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    F = np.asarray(F)
    if F.ndim != 2 or F.shape[1] != 3 or (F.size and (F.min() < 0 or F.max() >= n)):
        raise SShaDeError(f"faces must be an (m, 3) array of indices in [0, {n}), got shape {F.shape}")
    F = F.astype(np.int64)
    r = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    c = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    A = sp.coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(n, n))
    ncomp, lab = connected_components(A, directed=False)
    return int(ncomp), lab.astype(np.int64)


def n_components(F, n: int) -> int:
    """Number of connected components of a mesh of ``n`` vertices (see
    :func:`component_labels`), or 1 when ``F`` is malformed, so that the method's own
    validation names that problem. (m, 3) int faces; returns int."""
    try:
        return component_labels(F, n)[0]
    except (SShaDeError, TypeError, ValueError):
        return 1


def drop_unreferenced(V, F) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Remove the vertices no face uses.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int, indices in ``[0, n)``.

    Returns
    -------
    V2 : (n2, 3) float64 the referenced vertices, in their order; F2 : (m, 3) int64
    re-indexed; kept : (n2,) int64 the old index of each kept vertex (``V2 = V[kept]``).

    Raises
    ------
    SShaDeError if ``F`` has indices out of range.

    Examples
    --------
    >>> V2, F2, kept = drop_unreferenced(np.eye(4, 3), np.array([[0, 2, 3]]))
    >>> kept.tolist(), F2.tolist()
    ([0, 2, 3], [[0, 1, 2]])
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise SShaDeError(f"faces have vertex indices out of range [0, {len(V)})")
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    kept = np.flatnonzero(used).astype(np.int64)
    new = np.full(len(V), -1, np.int64)
    new[kept] = np.arange(len(kept))
    return V[kept], new[F], kept


def _submesh(F: np.ndarray, idx: np.ndarray, n: int) -> np.ndarray:
    """Faces of the component whose vertices are ``idx`` (sorted), re-indexed to it."""
    new = np.full(n, -1, np.int64)
    new[idx] = np.arange(len(idx))
    Fc = new[F]
    return Fc[(Fc >= 0).all(axis=1)]


def rigid_follow(V, Vd, F, labels, comp: int, near: int, *, min_faces: int = MIN_PATCH_FACES):
    """Rigid motion of the handle-less component ``comp`` from the deformation of
    component ``near`` (the patch rule: docs/implementation.md, "Implementation notes: sshade/components.py").

    Parameters
    ----------
    V : (n, 3) float64 rest positions; Vd : (n, 3) float64 deformed positions (those of
    ``near`` are used); F : (m, 3) int64 faces; labels : (n,) int64 component labels
    (:func:`component_labels`); comp, near : component numbers; min_faces : int >= 1.

    Returns
    -------
    R : (3, 3) float64 rotation; t : (3,) float64 translation (mesh units): the moved
    component is ``V[labels == comp] @ R.T + t``.
    """
    from scipy.spatial import cKDTree

    C = V[labels == comp]
    Hidx = np.flatnonzero(labels == near)
    d, j = cKDTree(V[Hidx]).query(C)
    p = V[Hidx[j[np.argmin(d)]]]
    FH = F[labels[F[:, 0]] == near]
    cent = V[FH].mean(axis=1)
    dist = np.linalg.norm(cent - p, axis=1)
    r = float(np.linalg.norm(C - C.mean(0), axis=1).max())
    k = min(len(FH), max(int(min_faces), int((dist <= r).sum())))
    patch = np.unique(FH[np.argsort(dist, kind="stable")[:k]])
    return rigid_fit(V[patch], Vd[patch])


def _merge_infos(infos: list[dict], sizes: list[int]) -> dict:
    """One info dict for several component runs: that of the largest component, with
    every per-stage time (keys ending in ``_s``) and ``iterations`` summed."""
    out = dict(infos[int(np.argmax(sizes))])
    for k in out:
        vals = [d.get(k) for d in infos]
        if (k.endswith("_s") or k == "iterations") and all(
                isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) for v in vals):
            out[k] = type(out[k])(np.sum(vals)) if isinstance(out[k], int) else float(np.sum(vals))
    return out


def deform_components(method, V, F, handles, targets, *, return_info: bool = False):
    """Deform a mesh with one or several connected components with ``method``.

    A single-component mesh goes straight to ``method.deform`` (same result, same
    ``info``). Otherwise each component holding handles is deformed on its own by
    ``method.deform`` (its vertices, faces, handles and targets), and each component
    without handles moves rigidly with its nearest deformed component
    (:func:`rigid_follow`).

    Parameters
    ----------
    method : a :class:`sshade.method_interface.Deformer` (``deform(V, F, handles, targets)``,
        optional ``info`` dict).
    V : (n, 3) float64 rest positions (mesh units); F : (m, 3) int faces, every component
        a 2-manifold (boundary allowed); handles : (h,) int vertex indices; targets :
        (h, 3) float positions.
    return_info : also return the info dict.

    Returns
    -------
    Vd : (n, 3) float64; with ``return_info`` ``(Vd, info)``: the method's info (one
    component), else that of its largest handled component with the ``*_s`` times and
    ``iterations`` summed over the components, plus ``n_components``,
    ``n_deformed_components``, ``n_rigid_components``, ``rigid_s`` and ``components``
    (per component: vertex count, ``deformed`` or ``rigid``, the method's info or the
    component it followed).

    Raises
    ------
    SShaDeError on an invalid mesh (every check of :func:`sshade.mesh.validate.validate_mesh`
    but the component count: unreferenced vertices, non-manifold edges, ...) or invalid
    handles, before any work; whatever ``method.deform`` raises on a component.

    Examples
    --------
    Example::

        from sshade import SShaDe
        Vd = deform_components(SShaDe(), V, F, handles, targets)
    """
    V, F = validate_mesh(V, F, allow_components=True)
    handles, targets = validate_handles(V, handles, targets)
    n = len(V)
    ncomp, lab = component_labels(F, n)
    if ncomp == 1:
        Vd = np.asarray(method.deform(V, F, handles, targets), np.float64)
        return (Vd, dict(getattr(method, "info", None) or {})) if return_info else Vd
    Vd = V.copy()
    hl = lab[handles]
    held = np.unique(hl)
    per: list[dict] = [{} for _ in range(ncomp)]
    infos, sizes = [], []
    for c in held:
        idx = np.flatnonzero(lab == c)
        new = np.full(n, -1, np.int64)
        new[idx] = np.arange(len(idx))
        sel = hl == c
        Vc = method.deform(V[idx], _submesh(F, idx, n), new[handles[sel]], targets[sel])
        Vd[idx] = np.asarray(Vc, np.float64)
        info = dict(getattr(method, "info", None) or {})
        infos.append(info)
        sizes.append(len(idx))
        per[c] = {"n_vertices": int(len(idx)), "mode": "deformed", "info": info}
    t0 = time.perf_counter()
    free = np.setdiff1d(np.arange(ncomp), held)
    if len(free):
        from scipy.spatial import cKDTree
        hv = np.flatnonzero(np.isin(lab, held))
        tree = cKDTree(V[hv])
        for c in free:
            idx = np.flatnonzero(lab == c)
            d, j = tree.query(V[idx])
            near = int(lab[hv[j[np.argmin(d)]]])
            R, t = rigid_follow(V, Vd, F, lab, int(c), near)
            Vd[idx] = V[idx] @ R.T + t
            per[c] = {"n_vertices": int(len(idx)), "mode": "rigid", "follows": near}
    Vd[handles] = targets
    if not return_info:
        return Vd
    info = _merge_infos(infos, sizes)
    info.update(n_components=int(ncomp), n_deformed_components=int(len(held)), n_rigid_components=int(len(free)),
                rigid_s=time.perf_counter() - t0, components=per)
    return Vd, info


class ComponentWise:
    """Any :class:`sshade.method_interface.Deformer` made to accept meshes with several connected
    components (:func:`deform_components`); same ``name``, ``info`` of the last call.

    Examples
    --------
    Example::

        from sshade import SShaDe
        Vd = ComponentWise(SShaDe()).deform(V, F, handles, targets)
    """

    def __init__(self, method):
        self.method = method
        self.name = method.name
        self.info: dict = {}

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """See :func:`deform_components`; returns (n, 3) float64."""
        Vd, self.info = deform_components(self.method, V, F, handles, targets, return_info=True)
        return Vd

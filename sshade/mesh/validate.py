"""Input validation for meshes and handles (paper §2, "Manifoldness"): the one validator
of every layer (the method, the baselines, the builder, the evaluator, the command line).

:func:`validate_mesh` (a single-component 2-manifold, boundary allowed: compiled
O(n + m) checks, then the reference checks to name the first problem; on a small mesh
while the kernels are deferred, :func:`sshade.mesh.halfedge.defer_kernels`, the reference
checks alone),
:func:`validate_handles`, :func:`validate_targets`, :func:`validate_deformed` (a method's
output); :func:`check_arrays` (:func:`check_points`, :func:`check_faces`): shapes, dtypes,
finite values and index range only. Errors: :class:`SShaDeError` naming what and where.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit
from scipy.sparse.csgraph import connected_components

from ..errors import SShaDeError
from .bounds import bbox_diagonal, bounding_box
from .checked import trusted_mesh
from .halfedge import count_components, count_pinched_vertices, halfedges, takes_kernels, tetrahedron, vertex_fan_count

__all__ = ["validate_mesh", "validate_handles", "validate_targets", "validate_handle_indices", "validate_deformed",
           "check_arrays", "check_points", "check_faces", "MAX_DIAGONALS", "COORD_MAX", "DIAG_MIN",
           "AREA_TOL", "zero_area_faces", "warm_kernels"]

#: Largest coordinate magnitude accepted. The methods form products of up to about
#: eight lengths (squared areas, circumradii, energies): beyond ~1e38 they overflow
#: float64 (max 1.8e308; SShaDe's remesh fails at 1e40, the area test at 1e77).
COORD_MAX = 1e30
#: Smallest bounding-box diagonal accepted: the same products underflow below ~1e-45.
DIAG_MIN = 1e-30
#: Targets (validate_handles) and deformed vertices (validate_deformed) farther than
#: this many bounding-box diagonals from the mesh are refused as out of scale (a units
#: mix-up, an overflow); no real edit moves a handle a million diagonals.
MAX_DIAGONALS = 1e6
#: A face whose area is at most ``AREA_TOL * bbox_diag**2`` is degenerate (zero-area):
#: :func:`validate_mesh` refuses it and :func:`sshade.mesh.repair.repair_mesh` removes it.
AREA_TOL = 1e-14


def _real_array(A, what: str) -> np.ndarray:
    """``A`` as a numpy array of real numbers (bool, integer or float dtype), else
    SShaDeError naming ``what`` and the dtype: complex numbers (whose imaginary part a
    float64 conversion drops with a warning) and strings (which it would parse) are refused."""
    try:
        a = np.asarray(A)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"{what} is not a numeric array ({' '.join(str(e).split())})") from None
    if a.dtype.kind not in "biuf":
        kind = "complex numbers" if a.dtype.kind == "c" else f"not real numbers (dtype {a.dtype})"
        raise SShaDeError(f"{what} holds {kind}; give real (k, 3) coordinates")
    return a


def check_points(P, name: str = "V", *, min_rows: int = 1) -> np.ndarray:
    """Check an array of 3-D points (vertex positions) and return it as float64.

    Parameters
    ----------
    P : (k, 3) array_like of real numbers (any length unit).
    name : str, first word of the error messages.
    min_rows : int, the fewest rows accepted.

    Returns
    -------
    (k, 3) float64, C-contiguous (a copy only if the input was not already).

    Raises
    ------
    SShaDeError: not numeric, a shape other than (k, 3), fewer than ``min_rows`` rows,
    NaN/inf coordinates (naming the first such row).

    Examples
    --------
    >>> check_points([[0, 0, 1]]).dtype
    dtype('float64')
    """
    P = np.ascontiguousarray(_real_array(P, name), dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise SShaDeError(f"{name}: must have shape (n, 3), got {P.shape}")
    if len(P) < min_rows:
        raise SShaDeError(f"{name}: is empty" if len(P) == 0 and min_rows <= 1 else
                          f"{name}: needs at least {min_rows} points, got {len(P)}")
    bad = ~np.isfinite(P).all(axis=1)
    if bad.any():
        raise SShaDeError(f"{name}: {int(bad.sum())} rows have NaN/inf coordinates "
                          f"(first: row {int(np.flatnonzero(bad)[0])})")
    return P


def check_faces(F, n: int, name: str = "F") -> np.ndarray:
    """Check triangle indices into ``n`` vertices and return them as int64.

    Parameters
    ----------
    F : (m, 3) array_like of integers (or of integral floats), m >= 1.
    n : int, the vertex count the indices refer to.
    name : str, first word of the error messages.

    Returns
    -------
    (m, 3) int64, C-contiguous.

    Raises
    ------
    SShaDeError: not numeric, a shape other than (m, 3), no face, non-integer values, an
    index outside ``[0, n)`` (naming the first such face).

    Examples
    --------
    >>> check_faces([[0, 1, 2]], 3).tolist()
    [[0, 1, 2]]
    """
    try:
        F = np.asarray(F)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"{name}: face array is ragged or not numeric ({e}); triangles only") from None
    if F.dtype.kind not in "iuf":
        raise SShaDeError(f"{name}: face indices must be integers, got dtype {F.dtype}")
    if F.ndim != 2 or F.shape[1] != 3:
        raise SShaDeError(f"{name}: must have shape (m, 3) (triangles only), got {F.shape}")
    if len(F) == 0:
        raise SShaDeError(f"{name}: has no faces")
    if not np.issubdtype(F.dtype, np.integer):
        if not np.isfinite(F).all() or np.any(F != np.round(F)):
            raise SShaDeError(f"{name}: face indices are not integers")
    F = np.ascontiguousarray(F, dtype=np.int64)
    out = (F < 0) | (F >= n)
    if out.any():
        f = int(np.flatnonzero(out.any(axis=1))[0])
        raise SShaDeError(f"{name}: face {f} has vertex index out of range [0, {n}): {F[f].tolist()}")
    return F


def check_arrays(V, F, *, name: str | None = None, min_vertices: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The array checks of a triangle mesh, without the manifold checks of
    :func:`validate_mesh`: :func:`check_points` on ``V``, :func:`check_faces` on ``F``.

    Parameters
    ----------
    V : (n, 3) array_like of float, vertex positions (any length unit).
    F : (m, 3) array_like of int, triangles (0-based indices into V).
    name : str or None, prefixes the messages (``"render"`` -> ``render: V: ...``).
    min_vertices : int, the fewest vertices accepted.

    Returns
    -------
    V : (n, 3) float64; F : (m, 3) int64 (both C-contiguous).

    Raises
    ------
    SShaDeError as :func:`check_points` and :func:`check_faces` (NaN/inf, shapes,
    non-integer or out-of-range indices, no vertex or face).

    Examples
    --------
    >>> V, F = check_arrays(np.eye(3), [[0, 1, 2]])
    """
    pre = f"{name}: " if name else ""
    V = check_points(V, f"{pre}V", min_rows=min_vertices)
    return V, check_faces(F, len(V), f"{pre}F")


def zero_area_faces(V: np.ndarray, F: np.ndarray, area_tol: float = AREA_TOL) -> np.ndarray:
    """The degenerate (zero-area) faces: area at most ``area_tol * bbox_diag**2``.

    Parameters
    ----------
    V : (n, 3) float64 finite positions (mesh units); F : (m, 3) int64 faces, indices in
    range. area_tol : float >= 0 (dimensionless, default :data:`AREA_TOL`).

    Returns
    -------
    (m,) bool, True where twice the face's area is at most ``2 * area_tol * diag**2``:
    what :func:`validate_mesh` refuses and :func:`sshade.mesh.repair.repair_mesh` removes.
    """
    if not len(F):
        return np.zeros(0, bool)
    diag = bbox_diagonal(V)
    dbl = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    return dbl <= 2 * area_tol * diag * diag


def validate_mesh(V, F, *, name: str = "mesh", allow_boundary: bool = True,
                  area_tol: float = AREA_TOL, return_halfedges: bool = False, allow_components: bool = False):
    """Check that ``(V, F)`` is a single-component 2-manifold triangle mesh.

    Parameters
    ----------
    V : (n, 3) array_like of float, vertex positions (any length unit).
    F : (m, 3) array_like of int, triangle faces (0-based vertex indices).
    name : str, used in error messages.
    allow_boundary : bool, if False a mesh with boundary edges is rejected.
    area_tol : float, a face with area at most ``area_tol * bbox_diag**2`` is degenerate
        (default :data:`AREA_TOL`).

    return_halfedges : bool, also return the :class:`sshade.mesh.halfedge.HalfEdges` built
        for the checks (reused by :func:`sshade.remesh.mesh_topology`).
    allow_components : bool, accept several connected components (each still has to
        pass every other check); used by :func:`sshade.components.deform_components`,
        which deforms each component apart.

    Returns
    -------
    V : (n, 3) float64, C-contiguous (a copy only if the input was not already).
    F : (m, 3) int64, C-contiguous.
    he : HalfEdges, only with ``return_halfedges``.

    Raises
    ------
    SShaDeError
        Wrong shapes, non-triangle faces, NaN/inf coordinates, out-of-range or repeated
        indices in a face, degenerate faces, duplicate faces, non-manifold edges
        (>2 faces or inconsistent orientation), non-manifold vertices, unreferenced
        vertices, several connected components (unless ``allow_components``).

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> V2, F2 = validate_mesh(V, F)

    Arrays a caller already checked (:func:`sshade.mesh.checked.checked_mesh`: the guard's,
    inside a method's call) are not checked again: copies of them come back at once.
    """
    hit = trusted_mesh(V, F, allow_components=allow_components,
                       default_checks=allow_boundary is True and area_tol == AREA_TOL)
    if hit is not None:
        return hit if return_halfedges else hit[:2]
    V = np.ascontiguousarray(_real_array(V, f"{name}: vertex array"), dtype=np.float64)
    if not V.flags.writeable:  # a read-only array (sshade.guard) would make numba compile a second signature
        V = V.copy()
    try:
        F = np.asarray(F)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"{name}: face array is ragged or not numeric ({e}); triangles only") from None
    if F.dtype.kind not in "iuf":
        raise SShaDeError(f"{name}: face indices must be integers, got dtype {F.dtype}")
    if V.ndim != 2 or V.shape[1] != 3:
        raise SShaDeError(f"{name}: V must have shape (n, 3), got {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3:
        raise SShaDeError(f"{name}: F must have shape (m, 3) (triangles only), got {F.shape}")
    if len(V) < 3 or len(F) < 1:
        raise SShaDeError(f"{name}: needs at least 3 vertices and 1 face, got {len(V)} and {len(F)}")
    if not np.issubdtype(F.dtype, np.integer):
        if not np.all(np.isfinite(F)) or np.any(F != np.round(F)):
            raise SShaDeError(f"{name}: face indices are not integers")
    F = np.ascontiguousarray(F, dtype=np.int64)
    if not F.flags.writeable:
        F = F.copy()
    # a small mesh while the kernels are deferred: the reference checks alone (the same verdict
    # and half-edges, nothing compiled)
    he = _fast_checks(V, F, allow_boundary, area_tol, allow_components) if takes_kernels(F) else None
    if he is None:  # something looks wrong: the reference checks name it (or pass a borderline case)
        he = _reference_checks(V, F, name, allow_boundary, area_tol, allow_components)
    if return_halfedges:
        return V, F, he
    return V, F


@njit(cache=True)
def _vertex_pass(V):
    """(all coordinates finite, bbox min (3,), bbox max (3,)) in one pass."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for i in range(V.shape[0]):
        for k in range(3):
            x = V[i, k]
            if not np.isfinite(x):
                return False, lo, hi
            lo[k] = min(lo[k], x)
            hi[k] = max(hi[k], x)
    return True, lo, hi


@njit(cache=True)
def _face_pass(V, F):
    """(indices in range, no repeated vertex in a face, every vertex referenced,
    smallest doubled face area) in one pass over the faces."""
    n = V.shape[0]
    used = np.zeros(n, np.bool_)
    mindbl = np.inf
    for f in range(F.shape[0]):
        a, b, c = F[f, 0], F[f, 1], F[f, 2]
        if a < 0 or a >= n or b < 0 or b >= n or c < 0 or c >= n:
            return False, False, False, 0.0
        if a == b or b == c or a == c:
            return True, False, False, 0.0
        used[a] = True
        used[b] = True
        used[c] = True
        e10, e11, e12 = V[b, 0] - V[a, 0], V[b, 1] - V[a, 1], V[b, 2] - V[a, 2]
        e20, e21, e22 = V[c, 0] - V[a, 0], V[c, 1] - V[a, 1], V[c, 2] - V[a, 2]
        n0 = e11 * e22 - e12 * e21
        n1 = e12 * e20 - e10 * e22
        n2 = e10 * e21 - e11 * e20
        mindbl = min(mindbl, np.sqrt(n0 * n0 + n1 * n1 + n2 * n2))
    for i in range(n):
        if not used[i]:
            return True, True, False, mindbl
    return True, True, True, mindbl


@njit(cache=True)
def _twin_faces(twin):
    """True if some face has all three twins in one other face (a duplicate face of
    opposite orientation)."""
    for f in range(twin.shape[0] // 3):
        t0, t1, t2 = twin[3 * f], twin[3 * f + 1], twin[3 * f + 2]
        if t0 >= 0 and t1 >= 0 and t2 >= 0 and t0 // 3 == t1 // 3 and t1 // 3 == t2 // 3:
            return True
    return False


def _fast_checks(V, F, allow_boundary, area_tol, allow_components=False):
    """The checks of :func:`validate_mesh`, compiled; the mesh's HalfEdges if it passes,
    None if any check fails (then :func:`_reference_checks` names the problem)."""
    n = len(V)
    finite, lo, hi = _vertex_pass(V)
    if not finite:
        return None
    in_range, no_repeat, all_used, mindbl = _face_pass(V, F)
    if not (in_range and no_repeat and all_used):
        return None
    if max(np.abs(lo).max(), np.abs(hi).max()) > COORD_MAX:
        return None
    diag = float(np.linalg.norm(hi - lo))
    if diag < DIAG_MIN:
        return None
    # the reference rejects dbl <= 2 tol diag^2; anything within round-off of it goes there
    if diag == 0 or mindbl <= 2 * area_tol * diag * diag * (1 + 1e-9):
        return None
    he = halfedges(F, n)
    # a duplicate face shares its three edges with its copy: a third face on an edge, two
    # half-edges running the same way, or three twins in one face
    if (he.count > 2).any() or he.misoriented or _twin_faces(he.twin):
        return None
    if not allow_boundary and (he.count == 1).any():
        return None
    if (not allow_components and count_components(he.E, n) != 1) or count_pinched_vertices(F, he, n):
        return None
    return he


def warm_kernels() -> None:
    """Compile (or load from numba's cache) the kernels of the compiled checks
    (:func:`sshade.mesh.halfedge.takes_kernels`), on :func:`sshade.mesh.halfedge.tetrahedron`."""
    V, F = tetrahedron()
    _fast_checks(V, F, True, AREA_TOL)


def _reference_checks(V, F, name, allow_boundary, area_tol, allow_components=False):
    """The checks of :func:`validate_mesh` in numpy/scipy, in order; raise SShaDeError
    naming the first problem. ``V`` (n, 3) float64, ``F`` (m, 3) int64 (contiguous).
    Returns the HalfEdges of a mesh that passes."""
    bad = ~np.isfinite(V).all(axis=1)
    if bad.any():
        raise SShaDeError(f"{name}: {bad.sum()} vertices have NaN/inf coordinates "
                          f"(first: vertex {np.flatnonzero(bad)[0]})")
    n = len(V)
    out = (F < 0) | (F >= n)
    if out.any():
        f = np.flatnonzero(out.any(axis=1))[0]
        raise SShaDeError(f"{name}: face {f} has vertex index out of range [0, {n}): {F[f].tolist()}")
    rep = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    if rep.any():
        f = np.flatnonzero(rep)[0]
        raise SShaDeError(f"{name}: face {f} repeats a vertex: {F[f].tolist()}")
    used = np.zeros(n, bool)
    used[F.ravel()] = True
    if not used.all():
        raise SShaDeError(f"{name}: {int((~used).sum())} unreferenced vertices "
                          f"(first: vertex {np.flatnonzero(~used)[0]}); "
                          "remove them before deforming (sshade.components.drop_unreferenced(V, F) returns the "
                          "mesh without them and the old index of each kept vertex; `python -m sshade deform` "
                          "drops them itself)")
    _check_scale(V, F, name)
    deg = zero_area_faces(V, F, area_tol)
    if deg.any():
        f = np.flatnonzero(deg)[0]
        raise SShaDeError(f"{name}: {int(deg.sum())} degenerate (zero-area) faces (first: face {f} = {F[f].tolist()})")
    sf = np.sort(F, axis=1)
    order = np.lexsort((sf[:, 2], sf[:, 1], sf[:, 0]))  # no int64 overflow at any size
    same = (sf[order[1:]] == sf[order[:-1]]).all(axis=1)
    if same.any():
        f = int(order[1:][same][0])
        raise SShaDeError(f"{name}: duplicate faces (first: face {f} = {F[f].tolist()})")
    he = halfedges(F, n)
    if (he.count > 2).any():
        e = np.flatnonzero(he.count > 2)[0]
        raise SShaDeError(f"{name}: {int((he.count > 2).sum())} non-manifold edges shared by 3+ faces "
                          f"(first: edge {he.E[e].tolist()})")
    if he.misoriented:
        raise SShaDeError(f"{name}: inconsistently oriented faces ({he.misoriented} edges whose two faces run "
                          "the same way); the mesh is non-orientable or needs its faces re-wound")
    if not allow_boundary and (he.count == 1).any():
        raise SShaDeError(f"{name}: has {int((he.count == 1).sum())} boundary edges but a closed mesh is required")
    # components
    E = he.E
    A = sp.coo_matrix((np.ones(len(E), np.int8), (E[:, 0], E[:, 1])), shape=(n, n))
    ncomp, _ = connected_components(A, directed=False)
    if ncomp != 1 and not allow_components:
        raise SShaDeError(f"{name}: has {ncomp} connected components; this solver needs a single component "
                          "(paper §2): sshade.deform, sshade.components.deform_components(method, V, F, handles, "
                          "targets), the evaluator and `python -m sshade deform` deform each component apart")
    # vertex manifoldness: the faces around each vertex form a single fan (corners linked
    # across interior edges at both ends; a pinch vertex has several groups of corners)
    fans = vertex_fan_count(F, he, n)
    bad = fans > 1
    if bad.any():
        v = np.flatnonzero(bad)[0]
        raise SShaDeError(f"{name}: {int(bad.sum())} non-manifold vertices (several fans of faces meet there; "
                          f"first: vertex {v})")
    return he


def _check_scale(V, F, name) -> None:
    """Coordinates whose squares overflow or underflow float64 (:data:`COORD_MAX`,
    :data:`DIAG_MIN`): say so rather than report the faces as degenerate."""
    big = float(np.abs(V).max())
    if big > COORD_MAX:
        raise SShaDeError(f"{name}: coordinates overflow in float64 (largest |x| = {big:.3g}, above {COORD_MAX:g}: "
                          "products of lengths in the methods would overflow; rescale the mesh)")
    diag = bbox_diagonal(V)
    if diag == 0:
        raise SShaDeError(f"{name}: all vertices coincide")
    if diag < DIAG_MIN:
        raise SShaDeError(f"{name}: coordinates underflow in float64 (bounding-box diagonal {diag:.3g}, below "
                          f"{DIAG_MIN:g}: products of lengths in the methods would underflow to zero; "
                          "rescale the mesh)")


def validate_handle_indices(V: np.ndarray, handles) -> np.ndarray:
    """Check handle indices against a mesh (the index part of :func:`validate_handles`).

    Parameters
    ----------
    V : (n, 3) float64 vertex positions. handles : (h,) array_like of int (an (h, 1) or
        (1, h) array is flattened).

    Returns
    -------
    (h,) int64, in the given order.

    Raises
    ------
    SShaDeError
        Empty handle set, non-integer, out-of-range or duplicate indices.

    Examples
    --------
    >>> validate_handle_indices(np.zeros((4, 3)), [[2], [0]]).tolist()
    [2, 0]
    """
    h = np.asarray(handles)
    if h.ndim == 2 and 1 in h.shape:
        h = h.ravel()
    if h.ndim != 1 or h.size == 0:
        raise SShaDeError(f"handles must be a non-empty 1-D index array, got shape {np.shape(handles)}")
    if not np.issubdtype(h.dtype, np.integer):
        raise SShaDeError(f"handles must be integer vertex indices, got dtype {h.dtype}")
    n = len(V)
    if h.dtype.kind == "u" and h.dtype.itemsize >= 8 and int(h.max()) >= n:  # int64 would wrap it negative
        raise SShaDeError(f"handle index {int(h[h >= n][0])} is out of range [0, {n}) (handle off the surface)")
    h = h.astype(np.int64)
    oob = (h < 0) | (h >= n)
    if oob.any():
        raise SShaDeError(f"handle index {int(h[oob][0])} is out of range [0, {n}) (handle off the surface)")
    if len(np.unique(h)) != len(h):
        raise SShaDeError("handles contain duplicate vertex indices")
    return h


def validate_handles(V: np.ndarray, handles, targets) -> tuple[np.ndarray, np.ndarray]:
    """Check handle indices and target positions against a mesh.

    Parameters
    ----------
    V : (n, 3) float64 vertex positions.
    handles : (h,) array_like of int, vertex indices, unique, in ``[0, n)``.
    targets : (h, 3) array_like of float, target positions of the handles.

    Returns
    -------
    handles : (h,) int64; targets : (h, 3) float64.

    Raises
    ------
    SShaDeError
        Empty handle set, non-integer, out-of-range or duplicate indices, length
        mismatch, NaN/inf targets, targets out of scale: farther than
        :data:`MAX_DIAGONALS` (1e6) bounding-box diagonals from the mesh (checked when ``V``
        spans a positive, finite box; a units mix-up, not an edit).

    Examples
    --------
    >>> V = np.zeros((4, 3)); h, t = validate_handles(V, [0, 2], np.zeros((2, 3)))
    """
    h = validate_handle_indices(V, handles)
    return h, validate_targets(V, len(h), targets)


def validate_targets(V: np.ndarray, n_handles: int, targets) -> np.ndarray:
    """The target-position checks of :func:`validate_handles`, for handles already checked.

    Parameters
    ----------
    V : (n, 3) float64 vertex positions, or any points with the same bounding box (its two
        corners: a solve per frame need not scan the mesh again).
    n_handles : int, the number of handles. targets : (h, 3) array_like of float.

    Returns
    -------
    targets : (h, 3) float64.

    Raises
    ------
    SShaDeError
        Not real numbers (complex, strings), shape or length mismatch, NaN/inf targets,
        targets out of scale (as :func:`validate_handles`).

    Examples
    --------
    >>> V = np.zeros((4, 3)); T = validate_targets(V, 2, np.zeros((2, 3)))
    """
    T = np.ascontiguousarray(_real_array(targets, "targets"), dtype=np.float64)
    if not T.flags.writeable:  # see validate_mesh
        T = T.copy()
    if T.ndim != 2 or T.shape[1] != 3:
        raise SShaDeError(f"targets must have shape (h, 3), got {T.shape}")
    if len(T) != n_handles:
        raise SShaDeError(f"handles and targets differ in length: {n_handles} handles, {len(T)} targets")
    if not np.isfinite(T).all():
        raise SShaDeError("targets contain NaN/inf")
    _check_target_scale(V, T)
    return T


def validate_deformed(U, n_vertices: int, *, V=None, name: str = "method") -> np.ndarray:
    """Check a deformation method's output before anything measures or writes it.

    The one check of every method's result (the evaluator and ``python -m sshade
    deform`` both call it through :func:`sshade.guard.run_method`).

    Parameters
    ----------
    U : (n, 3) array_like of real numbers, the deformed vertex positions (mesh units).
    n_vertices : int, the rest mesh's vertex count ``n``.
    V : optional (n, 3) float rest positions; with it, a vertex farther than
        :data:`MAX_DIAGONALS` (1e6) rest bounding-box diagonals from the rest
        bounding-box centre is refused (an absurd result, e.g. an overflow).
    name : str, the method's name, first word of every message.

    Returns
    -------
    (n, 3) float64, C-contiguous, writeable: always a new array (the method keeps no
    reference to what is measured or written).

    Raises
    ------
    SShaDeError
        ``name returned ...``: not an array of real numbers (None, ragged lists,
        strings, objects, booleans, complex numbers even with a zero imaginary part),
        a shape other than ``(n_vertices, 3)``, NaN/inf coordinates (also after the
        conversion to float64), or an absurd magnitude (with ``V``).

    Examples
    --------
    >>> V = np.zeros((4, 3)); V[1:, :] = np.eye(3)
    >>> validate_deformed(V.astype(np.float32), 4, V=V).dtype
    dtype('float64')
    """
    try:
        A = np.asarray(U)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"{name} returned something that is not numeric ({' '.join(str(e).split())})") from None
    if A.dtype.kind == "c":
        raise SShaDeError(f"{name} returned complex numbers (dtype {A.dtype}); return real (n, 3) coordinates")
    if A.dtype.kind not in "iuf":
        raise SShaDeError(f"{name} returned something that is not numeric ({type(U).__name__} of dtype {A.dtype}); "
                          "return an (n, 3) float array")
    if A.shape != (int(n_vertices), 3):
        raise SShaDeError(f"{name} returned an array of shape {A.shape} for a mesh of {int(n_vertices)} vertices; "
                          f"expected ({int(n_vertices)}, 3)")
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.array(A, dtype=np.float64, order="C", copy=True)
    bad = None if np.isfinite(out).all() else ~np.isfinite(out).all(axis=1)  # a row-wise pass only to name one
    if bad is not None:
        raise SShaDeError(f"{name} returned {int(bad.sum())} vertices with NaN/inf coordinates "
                          f"(first: vertex {int(np.flatnonzero(bad)[0])})")
    if V is not None:
        _check_magnitude(out, V, name)
    return out


def _check_magnitude(U: np.ndarray, V, name: str) -> None:
    """SShaDeError if a row of ``U`` is farther than :data:`MAX_DIAGONALS` bounding-box
    diagonals of ``V`` from ``V``'s bounding-box centre."""
    V = np.asarray(V, dtype=np.float64)
    lo, hi = bounding_box(V)
    diag = float(np.linalg.norm(hi - lo))
    if not np.isfinite(diag) or diag <= 0:
        return
    ulo, uhi = bounding_box(U)  # every row within this box: none is far when its corners are not
    if np.linalg.norm(np.maximum(np.abs(ulo - (lo + hi) / 2), np.abs(uhi - (lo + hi) / 2))) * (1 + 1e-12) \
            <= MAX_DIAGONALS * diag:
        return
    dist = np.linalg.norm(U - (lo + hi) / 2, axis=1)
    far = dist > MAX_DIAGONALS * diag
    if far.any():
        i = int(np.argmax(dist))
        raise SShaDeError(f"{name} returned {int(far.sum())} vertices farther than {MAX_DIAGONALS:g} bounding-box "
                          f"diagonals from the mesh (vertex {i} at {dist[i] / diag:.3g} diagonals)")


def _check_target_scale(V, T) -> None:
    """Refuse targets more than :data:`MAX_DIAGONALS` bounding-box diagonals away from
    the mesh (max-norm distances: no overflow at any finite scale)."""
    V = np.asarray(V, np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or not len(V) or not np.isfinite(V).all():
        return
    lo, hi = bounding_box(V)
    ext = float((hi - lo).max())
    if not ext > 0 or not np.isfinite(ext):
        return
    diag = ext * float(np.linalg.norm((hi - lo) / ext))
    away = float(np.abs(T - np.clip(T, lo, hi)).max(1).max()) / diag
    if away > MAX_DIAGONALS:
        raise SShaDeError(f"targets are out of scale: they lie {away:.3g} x the mesh's bounding-box diagonal "
                          f"({diag:.3g}) away (at most {MAX_DIAGONALS:g}); are the mesh and the targets in the "
                          "same units?")

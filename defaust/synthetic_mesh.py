"""The synthetic bodies' surface (:mod:`defaust.synthetic`): the implicit body, a polynomial
smooth minimum of round-cone SDFs after Quilez, compiled with numba (:func:`body_sdf`,
:func:`primitive_sdfs`); its mesh, by marching cubes (``igl.marching_cubes``), the largest
component and pymeshlab's isotropic remesh to about ``n_vertices``, checked to be a closed
single-component 2-manifold (:func:`mesh_body`); and the landmark vertices, nearest to
where each landmark ray leaves the body (:func:`body_landmarks`). Pure functions over
arrays; no file I/O.
"""
from __future__ import annotations

import warnings

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh

from .highres import isotropic_remesh
from .synthetic_body import LANDMARK_NAMES, Body, Primitive

__all__ = ["primitive_sdfs", "body_sdf", "mesh_body", "body_landmarks"]


def _round_cone_sdf(P: np.ndarray, pr: Primitive) -> np.ndarray:
    """Exact SDF of a round cone (Quilez), with the primitive's squash, at points (n, 3)."""
    a, b, r1, r2 = pr.a, pr.b, pr.ra, pr.rb
    X = (P - a) @ pr.Q.T  # Q symmetric; squashed coordinates relative to a
    ba = b - a
    l2 = float(ba @ ba)
    rr = r1 - r2
    a2 = l2 - rr * rr
    il2 = 1.0 / l2
    yv = X @ ba
    zv = yv - l2
    x2 = np.einsum("ij,ij->i", X * l2 - yv[:, None] * ba, X * l2 - yv[:, None] * ba)
    y2 = yv * yv * l2
    z2 = zv * zv * l2
    k = np.sign(rr) * rr * rr * x2
    d_mid = (np.sqrt(np.maximum(x2 * a2 * il2, 0.0)) + yv * rr) * il2 - r1
    d_b = np.sqrt(x2 + z2) * il2 - r2
    d_a = np.sqrt(x2 + y2) * il2 - r1
    d = np.where(np.sign(zv) * a2 * z2 > k, d_b, np.where(np.sign(yv) * a2 * y2 < k, d_a, d_mid))
    return d * pr.c


def primitive_sdfs(body: Body, P) -> np.ndarray:
    """Signed distance (lower bound, metres) of points to every primitive.

    Parameters
    ----------
    body : Body; P : (n, 3) points.

    Returns
    -------
    (n, len(body.primitives)) float64, negative inside.

    Examples
    --------
    >>> from defaust.synthetic_body import BodyParams, body_model
    >>> body = body_model(BodyParams()); primitive_sdfs(body, body.joints).shape[0]
    19
    """
    P = np.asarray(P, np.float64)
    return np.stack([_round_cone_sdf(P, pr) for pr in body.primitives], axis=1)


def body_sdf(body: Body, P) -> np.ndarray:
    """Implicit body: polynomial smooth union of the primitives (negative inside).

    The primitives are joined in order, each with its own radius ``k``
    (``d = mix(e, d, h) - k h (1 - h)``, ``h = clamp(0.5 + 0.5 (e - d) / k, 0, 1)``).

    Parameters
    ----------
    body : Body; P : (n, 3) points (metres).

    Returns
    -------
    (n,) float64, metres (a lower bound of the distance near the surface).

    Examples
    --------
    >>> from defaust.synthetic_body import BodyParams, body_model
    >>> body = body_model(BodyParams()); float(body_sdf(body, body.joints[:1])[0]) < 0
    True
    """
    P = np.ascontiguousarray(P, np.float64).reshape(-1, 3)
    pr = body.primitives
    A = np.array([p.a for p in pr], np.float64)
    B = np.array([p.b for p in pr], np.float64)
    R = np.array([[p.ra, p.rb, p.k, p.c] for p in pr], np.float64)
    Q = np.ascontiguousarray(np.array([p.Q for p in pr], np.float64))
    with warnings.catch_warnings():  # numba's notice that an old TBB is not used (it falls back to OpenMP)
        warnings.filterwarnings("ignore", message=".*TBB.*")
        return _smooth_union_sdf(P, A, B, R, Q)


def _round_cone_point(x, y, z, a, b, r1, r2, Q, c):
    """Scalar version of :func:`_round_cone_sdf` (compiled by numba below)."""
    px, py, pz = x - a[0], y - a[1], z - a[2]
    X0 = Q[0, 0] * px + Q[0, 1] * py + Q[0, 2] * pz
    X1 = Q[1, 0] * px + Q[1, 1] * py + Q[1, 2] * pz
    X2 = Q[2, 0] * px + Q[2, 1] * py + Q[2, 2] * pz
    b0, b1, b2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    l2 = b0 * b0 + b1 * b1 + b2 * b2
    rr = r1 - r2
    a2 = l2 - rr * rr
    il2 = 1.0 / l2
    yv = X0 * b0 + X1 * b1 + X2 * b2
    zv = yv - l2
    q0, q1, q2 = X0 * l2 - b0 * yv, X1 * l2 - b1 * yv, X2 * l2 - b2 * yv
    x2 = q0 * q0 + q1 * q1 + q2 * q2
    y2 = yv * yv * l2
    z2 = zv * zv * l2
    k = np.sign(rr) * rr * rr * x2
    if np.sign(zv) * a2 * z2 > k:
        d = np.sqrt(x2 + z2) * il2 - r2
    elif np.sign(yv) * a2 * y2 < k:
        d = np.sqrt(x2 + y2) * il2 - r1
    else:
        d = (np.sqrt(max(x2 * a2 * il2, 0.0)) + yv * rr) * il2 - r1
    return d * c


def _smooth_union_sdf_py(P, A, B, R, Q):
    out = np.empty(len(P))
    for i in _prange(len(P)):
        x, y, z = P[i, 0], P[i, 1], P[i, 2]
        d = _rc(x, y, z, A[0], B[0], R[0, 0], R[0, 1], Q[0], R[0, 3])
        for j in range(1, len(A)):
            e = _rc(x, y, z, A[j], B[j], R[j, 0], R[j, 1], Q[j], R[j, 3])
            k = R[j, 2]
            if k > 0:
                h = min(max(0.5 + 0.5 * (e - d) / k, 0.0), 1.0)
                d = e * (1 - h) + d * h - k * h * (1 - h)
            else:
                d = min(d, e)
        out[i] = d
    return out


try:  # compiled (numba, parallel): the marching-cubes grid has ~1M points
    import numba as _nb

    _prange = _nb.prange
    _rc = _nb.njit(cache=True, fastmath=False)(_round_cone_point)
    _smooth_union_sdf = _nb.njit(cache=True, parallel=True, fastmath=False)(_smooth_union_sdf_py)
except ImportError:  # pragma: no cover - numba is a dependency
    _prange = range
    _rc = _round_cone_point
    _smooth_union_sdf = _smooth_union_sdf_py


def mesh_body(body: Body, *, voxel_size: float = 0.01, n_vertices: int = 7000,
              remesh_iterations: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Mesh the implicit body: marching cubes, largest component, isotropic remesh.

    Parameters
    ----------
    body : Body.
    voxel_size : float, grid spacing of marching cubes (metres).
    n_vertices : int, approximate vertex count of the result (the isotropic remesh's
        target edge length is ``sqrt(2 A / (sqrt(3) n_vertices))`` for surface area A).
    remesh_iterations : int, pymeshlab isotropic remeshing iterations.

    Returns
    -------
    V : (n, 3) float64 (metres); F : (m, 3) int64, outward oriented; a single-component
    closed 2-manifold.

    Raises
    ------
    SShaDeError if the result is not a closed single-component manifold (should not
    happen for the built-in proportions; report it with the subject's parameters).

    Examples
    --------
    Example::

        V, F = mesh_body(body_model(BodyParams()), voxel_size=0.02, n_vertices=1500)
    """
    import pymeshlab  # heavy: only when meshing

    J = body.joints
    r = max(max(p.ra, p.rb) for p in body.primitives)
    ends = np.concatenate([[p.a for p in body.primitives], [p.b for p in body.primitives], J])
    lo = ends.min(0) - r - 3 * voxel_size
    hi = ends.max(0) + r + 3 * voxel_size
    n = np.ceil((hi - lo) / voxel_size).astype(int) + 1
    xs, ys, zs = (lo[i] + voxel_size * np.arange(n[i]) for i in range(3))
    Z, Y, X = np.meshgrid(zs, ys, xs, indexing="ij")  # x fastest, as igl wants
    GV = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    S = body_sdf(body, GV)
    V, F, _ = igl.marching_cubes(S, GV, int(n[0]), int(n[1]), int(n[2]), 0.0)
    if len(F) == 0:
        raise SShaDeError("synthetic body: marching cubes produced no surface")
    V, F = _largest_component(np.asarray(V, np.float64), np.asarray(F, np.int64))
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(V, F.astype(np.int32)))
    ms.meshing_remove_duplicate_vertices()
    ms.meshing_remove_duplicate_faces()
    ms.meshing_remove_null_faces()
    ms.meshing_remove_unreferenced_vertices()
    area = ms.get_geometric_measures()["surface_area"]
    target = float(np.sqrt(2.0 * area / (np.sqrt(3.0) * int(n_vertices))))
    isotropic_remesh(ms, target, remesh_iterations, check_distance=True)  # every parameter given
    m = ms.current_mesh()
    V, F = _largest_component(np.asarray(m.vertex_matrix(), np.float64), np.asarray(m.face_matrix(), np.int64))
    if _signed_volume(V, F) < 0:
        F = F[:, ::-1].copy()
    V, F = validate_mesh(V, F, name="synthetic body", allow_boundary=False)
    return V, F


def _largest_component(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep the connected component (through shared vertices) with most faces, drop
    unreferenced vertices; vertex order is kept."""
    n = len(V)
    i = np.repeat(np.arange(len(F)), 3)
    A = sp.coo_matrix((np.ones(3 * len(F)), (F.ravel(), i)), shape=(n, len(F))).tocsr()
    G = A @ A.T
    _, comp = connected_components(G, directed=False)
    fc = comp[F[:, 0]]
    best = np.argmax(np.bincount(fc))
    F = F[fc == best]
    used = np.zeros(n, bool)
    used[F.ravel()] = True
    remap = np.cumsum(used) - 1
    return np.ascontiguousarray(V[used]), np.ascontiguousarray(remap[F])


def _signed_volume(V: np.ndarray, F: np.ndarray) -> float:
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def body_landmarks(body: Body, V) -> dict[str, int]:
    """Landmark vertices of a rest mesh of the body (see :data:`LANDMARK_NAMES`).

    Each landmark is the vertex nearest to where a ray leaves the implicit body: from
    the head centre up (head top), from the hand centre along the arm (finger tips),
    from the elbow joint backwards, from the knee joint forwards, from inside the front
    of the foot forwards (toe tip), from the sternum height on the spine axis forwards
    (chest), from the pelvis down between the legs (crotch).

    Parameters
    ----------
    body : Body; V : (n, 3) rest mesh vertices (metres).

    Returns
    -------
    dict name -> vertex index, in :data:`LANDMARK_NAMES` order.

    Examples
    --------
    Example::

        lm = body_landmarks(body, V)
        V[lm["head_top"], 1] == V[:, 1].max()
        # -> True
    """
    tree = cKDTree(np.asarray(V, np.float64))
    out = {}
    for name in LANDMARK_NAMES:
        o, d = body.rays[name]
        p = _ray_exit(body, o, d)
        out[name] = int(tree.query(p)[1])
    return out


def _ray_exit(body: Body, o: np.ndarray, d: np.ndarray, step: float = 2e-4, max_len: float = 0.6) -> np.ndarray:
    """First point where the ray ``o + t d`` (``o`` inside) leaves the body, to ~0.01 mm."""
    ts = np.arange(0.0, max_len, step)
    s = body_sdf(body, o[None] + ts[:, None] * d[None])
    if s[0] >= 0:
        raise SShaDeError(f"landmark ray origin {o.round(3).tolist()} is outside the body")
    out = np.flatnonzero(s > 0)
    if not len(out):
        raise SShaDeError("landmark ray never leaves the body")
    i = out[0]
    t = ts[i - 1] + step * s[i - 1] / (s[i - 1] - s[i])  # linear interpolation of the crossing
    return o + t * d

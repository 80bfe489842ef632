"""Landmark handle groups of DeFAUST (paper appendix A, eq. for Delta_l), stored as positions.

Around each landmark ``l``, ``n_per_landmark`` (paper: 30) vertices ``H_l`` are drawn among
its ``neighbourhood`` geodesically nearest (:func:`landmark_handles`). With the
correspondence ``pi`` of a target pose, ``Delta_l = sum_{v in H_l} || v - pi(v) ||``; the
group is static (targets = rest positions) when ``Delta_l / n_per_landmark`` is below
``static_threshold`` (mesh units), else dynamic (the target pose's positions). Handles are
stored as positions ("so that they can be used with remeshed and subdivided shapes") and
snapped to the mesh they are used with (:func:`snap_handles`). docs/defaust.md §2,
"Handles", and "Implementation notes: defaust/handles.py".
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from sshade.errors import SShaDeError

__all__ = ["BASE_LANDMARKS", "HandleSet", "Snap", "edge_length_matrix", "geodesic_neighbourhood",
           "landmark_handles", "classify_groups", "snap_handles", "handles_to_arrays",
           "handles_from_arrays", "landmarks_for_target", "HANDLE_ARRAYS", "HANDLE_OPTIONAL_ARRAYS",
           "HANDLE_ARRAY_MAX_BYTES", "handle_array_bytes"]

log = logging.getLogger(__name__)

#: Landmarks used for every target pose but the last (which uses all of its source's
#: landmarks, paper appendix). Names as in :data:`defaust.faust_source.FAUST_LANDMARKS`,
#: :data:`defaust.anny_source.LANDMARK_NAMES` and :data:`defaust.synthetic.LANDMARK_NAMES`.
BASE_LANDMARKS: tuple[str, ...] = ("head_top", "left_hand", "right_hand", "crotch", "left_foot", "right_foot")


def landmarks_for_target(all_landmarks: dict[str, int], target_index: int, n_targets: int) -> dict[str, int]:
    """The landmarks used for the ``target_index``-th of ``n_targets`` target poses.

    The last target (``target_index == n_targets - 1``) uses every landmark, the others
    :data:`BASE_LANDMARKS` (in that order).

    Parameters
    ----------
    all_landmarks : dict name -> vertex index (the source's full list, in order).
    target_index, n_targets : int, 0-based position of the target among the subject's.

    Returns
    -------
    dict name -> vertex index.

    Raises
    ------
    SShaDeError if a base landmark is missing from ``all_landmarks``.

    Examples
    --------
    >>> lm = {n: i for i, n in enumerate(BASE_LANDMARKS + ("chest",))}
    >>> list(landmarks_for_target(lm, 0, 4)) == list(BASE_LANDMARKS)
    True
    >>> len(landmarks_for_target(lm, 3, 4))
    7
    """
    if target_index == n_targets - 1:
        return dict(all_landmarks)
    missing = [n for n in BASE_LANDMARKS if n not in all_landmarks]
    if missing:
        raise SShaDeError(f"landmark list lacks base landmarks {missing}")
    return {n: all_landmarks[n] for n in BASE_LANDMARKS}


@dataclass(frozen=True)
class HandleSet:
    """Handles of one deformation case, as positions (units of the source mesh).

    Attributes
    ----------
    rest : (h, 3) float64 rest-pose positions of the handle vertices (exact low-res
        vertex positions).
    target : (h, 3) float64 target positions: ``rest`` for static handles, the target
        pose's positions for dynamic ones.
    static : (h,) bool, the handle's group is static.
    group : (h,) int64 index into ``landmark_names``.
    landmark_names : tuple of str, (L,).
    landmark_rest : (L, 3) float64 rest positions of the landmark vertices.
    delta : (L,) float64 ``Delta_l`` (sum over the group's ``n_per_landmark`` draws,
        before de-duplication; mesh units).
    group_static : (L,) bool.
    index : (h,) int64 the handle vertices on the mesh they were drawn from.
    n_per_landmark : int; neighbourhood : int; static_threshold : float; seed : int.
    """

    rest: np.ndarray
    target: np.ndarray
    static: np.ndarray
    group: np.ndarray
    landmark_names: tuple
    landmark_rest: np.ndarray
    delta: np.ndarray
    group_static: np.ndarray
    index: np.ndarray
    n_per_landmark: int
    neighbourhood: int
    static_threshold: float
    seed: int

    def __len__(self) -> int:
        return len(self.rest)


def edge_length_matrix(V: np.ndarray, F: np.ndarray) -> sp.csr_matrix:
    """Symmetric sparse adjacency of the mesh edges weighted by Euclidean length.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64.

    Returns
    -------
    (n, n) CSR matrix, entry ``(i, j) = ||V[i] - V[j]||`` for every edge.

    Examples
    --------
    >>> G = edge_length_matrix(np.eye(3), np.array([[0, 1, 2]])); G.nnz
    6
    """
    F = np.asarray(F, np.int64)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    E = np.unique(np.sort(E, axis=1), axis=0)
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    n = len(V)
    i = np.concatenate([E[:, 0], E[:, 1]])
    j = np.concatenate([E[:, 1], E[:, 0]])
    return sp.coo_matrix((np.concatenate([w, w]), (i, j)), shape=(n, n)).tocsr()


def geodesic_neighbourhood(V, F, landmarks, k: int, *, graph: sp.csr_matrix | None = None) -> np.ndarray:
    """The ``k`` vertices geodesically nearest to each landmark (the landmark included).

    Distances are shortest paths over :func:`edge_length_matrix` (Dijkstra); ties are broken by
    vertex index, so the result is deterministic.

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int64; landmarks : (L,) int vertex indices;
    k : int, ``1 <= k <= n``; graph : optional precomputed :func:`edge_length_matrix`.

    Returns
    -------
    (L, k) int64, row ``i`` sorted by distance from ``landmarks[i]`` (``[i, 0]`` is the
    landmark).

    Raises
    ------
    SShaDeError if ``k`` is out of range or fewer than ``k`` vertices are connected to a
    landmark.

    Examples
    --------
    Example::

        nb = geodesic_neighbourhood(V, F, [414], 90)
    """
    V = np.asarray(V, np.float64)
    n = len(V)
    k = int(k)
    if not 1 <= k <= n:
        raise SShaDeError(f"neighbourhood size must be in [1, {n}], got {k}")
    L = np.asarray(landmarks, np.int64).ravel()
    G = edge_length_matrix(V, F) if graph is None else graph
    mean_edge = float(G.data.mean()) if G.nnz else 1.0
    limit = 3.0 * mean_edge * np.sqrt(k)  # a disc of k vertices has radius ~ sqrt(k) edges
    out = np.empty((len(L), k), np.int64)
    todo = np.arange(len(L))
    while len(todo):
        D = np.atleast_2d(dijkstra(G, directed=False, indices=L[todo], limit=limit))
        left = []
        for row, i in zip(D, todo):
            reach = np.flatnonzero(np.isfinite(row))
            if len(reach) < k:
                left.append(i)
                continue
            order = np.lexsort((reach, row[reach]))
            out[i] = reach[order[:k]]
        if left and not np.isfinite(limit):
            raise SShaDeError(f"fewer than {k} vertices are connected to landmark vertex {int(L[left[0]])}")
        todo = np.asarray(left, np.int64)
        limit = np.inf if limit > 1e6 * mean_edge else 2.0 * limit
    return out


def classify_groups(delta, n_per_landmark: int, static_threshold: float) -> np.ndarray:
    """Static groups: mean displacement ``Delta_l / n_per_landmark < static_threshold``.

    Parameters
    ----------
    delta : (L,) float, ``Delta_l`` in mesh units; n_per_landmark : int;
    static_threshold : float, mesh units (metres for FAUST / synthetic).

    Returns
    -------
    (L,) bool.

    Examples
    --------
    >>> classify_groups([0.3, 0.9], 30, 0.02)
    array([ True, False])
    """
    return np.asarray(delta, np.float64) / float(n_per_landmark) < float(static_threshold)


def landmark_handles(V_rest, F, V_target, landmarks: dict[str, int], *, n_per_landmark: int = 30,
                     neighbourhood: int = 90, static_threshold: float = 0.02, seed: int = 0) -> HandleSet:
    """Static and dynamic handle groups around landmarks (paper appendix).

    Parameters
    ----------
    V_rest : (n, 3) float rest-pose positions (metres for FAUST / synthetic).
    F : (m, 3) int faces shared by both poses.
    V_target : (n, 3) float target-pose positions, row ``i`` = ``pi(V_rest[i])``.
    landmarks : dict name -> vertex index (unique), in group order.
    n_per_landmark : int, vertices drawn per landmark (paper: 30).
    neighbourhood : int, geodesic neighbourhood they are drawn from (>= n_per_landmark).
    static_threshold : float, mesh units, on the mean displacement of a group.
    seed : int, seed of ``numpy.random.default_rng`` for the draws.

    Returns
    -------
    HandleSet with ``rest = V_rest[index]``.

    Raises
    ------
    SShaDeError
        Shape mismatch, NaN/inf, landmark indices out of range or repeated,
        ``n_per_landmark`` not in ``[1, neighbourhood]``, ``neighbourhood > n``,
        negative threshold.

    Examples
    --------
    Example::

        H = landmark_handles(V0, F, V1, {"head_top": 414, "left_hand": 2445})
        H.rest.shape
        # -> (60, 3)
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
    names = tuple(landmarks)
    L = np.array([int(landmarks[k]) for k in names], np.int64)
    if L.size == 0:
        raise SShaDeError("no landmarks given")
    if (L < 0).any() or (L >= n).any():
        raise SShaDeError(f"landmark index {int(L[(L < 0) | (L >= n)][0])} is out of range [0, {n})")
    if len(np.unique(L)) != len(L):
        raise SShaDeError(f"landmarks share vertices: {dict(zip(names, L.tolist()))}")
    n_per_landmark, neighbourhood = int(n_per_landmark), int(neighbourhood)
    if not 1 <= n_per_landmark <= neighbourhood:
        raise SShaDeError(f"n_per_landmark must be in [1, neighbourhood={neighbourhood}], got {n_per_landmark}")
    if neighbourhood > n:
        raise SShaDeError(f"neighbourhood={neighbourhood} exceeds the vertex count {n}")
    if not np.isfinite(static_threshold) or static_threshold < 0:
        raise SShaDeError(f"static_threshold must be a finite number >= 0, got {static_threshold}")

    nbhd = geodesic_neighbourhood(V, F, L, neighbourhood)
    rng = np.random.default_rng(int(seed))
    disp = np.linalg.norm(W - V, axis=1)
    groups, delta = [], np.empty(len(L))
    for i in range(len(L)):
        pick = np.sort(rng.choice(nbhd[i], size=n_per_landmark, replace=False))
        groups.append(pick)
        delta[i] = disp[pick].sum()
    group_static = classify_groups(delta, n_per_landmark, static_threshold)
    allv = np.concatenate(groups)
    allg = np.repeat(np.arange(len(L), dtype=np.int64), n_per_landmark)
    _, first = np.unique(allv, return_index=True)
    keep = np.sort(first)
    idx, g = allv[keep].astype(np.int64), allg[keep]
    st = group_static[g]
    T = np.where(st[:, None], V[idx], W[idx])
    return HandleSet(rest=np.ascontiguousarray(V[idx]), target=np.ascontiguousarray(T), static=st, group=g,
                     landmark_names=names, landmark_rest=np.ascontiguousarray(V[L]), delta=delta,
                     group_static=group_static, index=idx, n_per_landmark=n_per_landmark,
                     neighbourhood=neighbourhood, static_threshold=float(static_threshold), seed=int(seed))


def handles_to_arrays(H: HandleSet) -> dict[str, np.ndarray]:
    """Arrays for :func:`defaust.store.write_npz` (fixed-width types, no pickles).

    Keys: ``rest_positions``, ``target_positions`` (h, 3) float64; ``static`` (h,) bool;
    ``group`` (h,) int64; ``low_index`` (h,) int64; ``landmark_names`` (L,) unicode;
    ``landmark_positions`` (L, 3); ``delta`` (L,); ``group_static`` (L,) bool;
    ``n_per_landmark``, ``neighbourhood``, ``seed`` int64 scalars; ``static_threshold``
    float64 scalar.

    Examples
    --------
    Example::

        from defaust.store import write_npz
        write_npz("/tmp/h.npz", handles_to_arrays(H))
    """
    return {
        "rest_positions": H.rest, "target_positions": H.target, "static": H.static.astype(bool),
        "group": H.group.astype(np.int64), "low_index": H.index.astype(np.int64),
        "landmark_names": np.array(H.landmark_names, dtype="<U32"),
        "landmark_positions": H.landmark_rest, "delta": H.delta, "group_static": H.group_static.astype(bool),
        "n_per_landmark": np.int64(H.n_per_landmark), "neighbourhood": np.int64(H.neighbourhood),
        "static_threshold": np.float64(H.static_threshold), "seed": np.int64(H.seed),
    }


#: Arrays of a handles file (:func:`handles_to_arrays`) that :func:`handles_from_arrays`
#: needs, and those it may hold besides (the builder also stores ``subject`` and ``pose``).
HANDLE_ARRAYS = ("rest_positions", "target_positions", "static", "group", "landmark_names", "delta", "group_static")
HANDLE_OPTIONAL_ARRAYS = ("landmark_positions", "low_index", "n_per_landmark", "neighbourhood",
                          "static_threshold", "seed", "subject", "pose")
#: Largest accepted array of a handles file when its handle count is not known (bytes).
HANDLE_ARRAY_MAX_BYTES = 64 << 20
# bytes per handle and per landmark of each array (a landmark name: up to 64 characters)
_PER_HANDLE = {"rest_positions": 24, "target_positions": 24, "static": 1, "group": 8, "low_index": 8}
_PER_LANDMARK = {"landmark_names": 256, "landmark_positions": 24, "delta": 8, "group_static": 1}


def handle_array_bytes(n_handles: int | None = None, n_landmarks: int | None = None) -> dict[str, int]:
    """Upper bound on the uncompressed size of each array of a handles file with
    ``n_handles`` handles in ``n_landmarks`` groups (``.npy`` header included, with a
    few KB of slack), at most :data:`HANDLE_ARRAY_MAX_BYTES` (also the bound of a count
    given as None); for :func:`defaust.store.read_npz`'s ``max_bytes``.

    Examples
    --------
    >>> handle_array_bytes(180, 6)["rest_positions"]
    8416
    """
    out = {}
    for k in HANDLE_ARRAYS + HANDLE_OPTIONAL_ARRAYS:
        n, per = ((n_handles, _PER_HANDLE[k]) if k in _PER_HANDLE else
                  (n_landmarks, _PER_LANDMARK[k]) if k in _PER_LANDMARK else (1, 8))
        out[k] = HANDLE_ARRAY_MAX_BYTES if n is None else min(HANDLE_ARRAY_MAX_BYTES, 4096 + per * int(n))
    return out


_KINDS = {"fiu": "real numbers", "biu": "booleans", "iu": "integers", "U": "strings"}


def _field(d: dict, key: str, name: str, kinds: str, *, finite: bool = False, shape=None) -> np.ndarray:
    """``d[key]`` checked: dtype kind in ``kinds`` (flags: 0 or 1), finite, of ``shape``."""
    a = np.asarray(d[key])
    if a.dtype.kind not in kinds:
        raise SShaDeError(f"{name}: array {key!r} has dtype {a.dtype}; expected {_KINDS[kinds]}")
    if kinds == "biu" and a.dtype.kind != "b" and not np.isin(a, (0, 1)).all():
        raise SShaDeError(f"{name}: array {key!r} holds values other than 0 and 1")
    if finite and not np.isfinite(a).all():
        raise SShaDeError(f"{name}: array {key!r} holds {int((~np.isfinite(a)).sum())} NaN or infinite value(s)")
    if shape is not None and a.shape != shape:
        raise SShaDeError(f"{name}: array {key!r} has shape {a.shape}, expected {shape}")
    return a


def handles_from_arrays(d: dict, *, name: str = "handles") -> HandleSet:
    """Inverse of :func:`handles_to_arrays`, as untrusted input: every array of
    :data:`HANDLE_ARRAYS` present, positions, targets and ``delta`` finite real numbers,
    flags booleans (or 0/1), groups integers in ``[0, L)``, shapes consistent.

    Raises
    ------
    SShaDeError naming ``name`` and the array: a key missing, a non-real dtype (complex,
    string, object), NaN or inf, or shapes that disagree.

    Examples
    --------
    Example::

        from defaust.store import read_npz
        H = handles_from_arrays(read_npz("subject_00/pose_01_handles.npz"))
    """
    miss = [k for k in HANDLE_ARRAYS if k not in d]
    if miss:
        raise SShaDeError(f"{name}: missing arrays {miss}")
    R = _field(d, "rest_positions", name, "fiu", finite=True).astype(np.float64)
    h = len(R) if R.ndim == 2 and R.shape[1] == 3 else -1
    if h < 0:
        raise SShaDeError(f"{name}: array 'rest_positions' has shape {R.shape}, expected (h, 3)")
    T = _field(d, "target_positions", name, "fiu", finite=True, shape=R.shape).astype(np.float64)
    st = _field(d, "static", name, "biu", shape=(h,)).astype(bool)
    g = _field(d, "group", name, "iu", shape=(h,)).astype(np.int64)
    names = _field(d, "landmark_names", name, "U")
    if names.ndim != 1:
        raise SShaDeError(f"{name}: array 'landmark_names' has shape {names.shape}, expected (L,)")
    L = len(names)
    if h and (g.min() < 0 or g.max() >= L):
        raise SShaDeError(f"{name}: array 'group' holds values outside [0, {L}) (the landmark groups)")
    opt = {k: d[k] for k in HANDLE_OPTIONAL_ARRAYS if k in d}
    scalar = {k: _field(opt, k, name, "fiu" if k == "static_threshold" else "iu", shape=()).item()
              for k in ("n_per_landmark", "neighbourhood", "static_threshold", "seed") if k in opt}
    return HandleSet(
        rest=R, target=T, static=st, group=g, landmark_names=tuple(str(x) for x in names.tolist()),
        landmark_rest=(_field(opt, "landmark_positions", name, "fiu", finite=True, shape=(L, 3)).astype(np.float64)
                       if "landmark_positions" in opt else np.zeros((L, 3))),
        delta=_field(d, "delta", name, "fiu", finite=True, shape=(L,)).astype(np.float64),
        group_static=_field(d, "group_static", name, "biu", shape=(L,)).astype(bool),
        index=(_field(opt, "low_index", name, "iu", shape=(h,)).astype(np.int64) if "low_index" in opt
               else np.full(h, -1, np.int64)),
        n_per_landmark=int(scalar.get("n_per_landmark", 0)), neighbourhood=int(scalar.get("neighbourhood", 0)),
        static_threshold=float(scalar.get("static_threshold", np.nan)), seed=int(scalar.get("seed", 0)))


@dataclass(frozen=True)
class Snap:
    """Result of :func:`snap_handles`.

    Attributes
    ----------
    index : (k,) int64 unique vertex indices, one per kept handle, in handle order.
    keep : (h,) bool, which input positions were kept (``k = keep.sum()``); filter the
        targets / static flags / groups with it.
    distance : (h,) float64 distance from each position to its nearest vertex.
    n_dropped : int, handles dropped because another handle took the same vertex.
    """

    index: np.ndarray
    keep: np.ndarray
    distance: np.ndarray
    n_dropped: int


def snap_handles(V, rest_positions, *, tol: float | None = None, name: str = "handles") -> Snap:
    """Snap stored handle positions to the nearest vertices of a mesh.

    Parameters
    ----------
    V : (n, 3) float64 vertices of the mesh the handles are used with (any resolution of
        the rest pose the handles were drawn on; same units).
    rest_positions : (h, 3) float64 stored rest positions of the handles.
    tol : float or None, largest accepted distance to the nearest vertex (mesh units);
        default ``0.01 * bbox diagonal of V`` (why that bound: docs/defaust.md,
        "Implementation notes: defaust/handles.py").
    name : str, used in messages.

    Returns
    -------
    Snap. When several handles snap to one vertex the one nearest to it is kept (ties:
    the first in order) and the others are dropped, logged at DEBUG level (the
    evaluator says it once per run, :func:`eval.datasets.defaust_dataset.summarise_dropped`);
    ``keep`` says which and ``n_dropped`` how many.

    Raises
    ------
    SShaDeError on bad shapes, NaN/inf, or a handle farther than ``tol`` from every
    vertex (a handle off the surface: the mesh is not the pose the handles belong to).

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> s = snap_handles(V, [[0.9, 0, 0], [0.1, 0, 0]], tol=0.5)
    >>> s.index.tolist(), s.keep.tolist()
    ([1, 0], [True, True])
    """
    from scipy.spatial import cKDTree

    V = np.asarray(V, np.float64)
    P = np.asarray(rest_positions, np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) == 0:
        raise SShaDeError(f"{name}: V must have shape (n, 3), got {V.shape}")
    if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
        raise SShaDeError(f"{name}: rest positions must have shape (h, 3) with h >= 1, got {P.shape}")
    if not np.isfinite(P).all():
        raise SShaDeError(f"{name}: rest positions contain NaN/inf")
    if tol is None:
        tol = 0.01 * float(np.linalg.norm(V.max(0) - V.min(0)))
    dist, idx = cKDTree(V).query(P)
    far = dist > tol
    if far.any():
        i = int(np.flatnonzero(far)[0])
        raise SShaDeError(f"{name}: {int(far.sum())} handle(s) off the surface: handle {i} at "
                          f"{P[i].round(4).tolist()} is {dist[i]:.4g} from the nearest vertex (tolerance {tol:.4g}); "
                          "is this the rest pose the handles were made for?")
    idx = idx.astype(np.int64)
    order = np.lexsort((np.arange(len(P)), dist, idx))  # by vertex, then distance, then order
    first = np.ones(len(P), bool)
    first[1:] = idx[order][1:] != idx[order][:-1]
    keep = np.zeros(len(P), bool)
    keep[order[first]] = True
    n_drop = int((~keep).sum())
    if n_drop:  # two stored positions (low-res vertices) closer than the mesh's spacing share a nearest vertex
        # DEBUG: by design of the dataset; the evaluator says it once per run (eval.datasets.defaust_dataset)
        log.debug("%s: %d of %d handles share their nearest vertex with a nearer handle; dropped (their "
                  "low-res vertices are closer together than this mesh's vertex spacing; counted per case as "
                  "n_handles_dropped, docs/differences.md)", name, n_drop, len(P))
    return Snap(index=idx[keep], keep=keep, distance=dist, n_dropped=n_drop)

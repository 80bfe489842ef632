"""Synthetic human-like subjects for DeFAUST: a parametric implicit body posed by linear
blend skinning (LBS).

This is the builder's embedded default source: no download and no FAUST file. Like
FAUST's registrations, all poses of one subject share one face array and correspond
vertex to vertex (the rest mesh is meshed once and every pose is the same vertices
moved by LBS).

Model (units: metres; axes: +x = subject's left, +y = up, +z = forward; feet near y=0):

- **Skeleton**: 19 joints (:data:`JOINTS`, tree :data:`PARENT`) placed from the subject's
  stature ``H`` with anthropometric fractions (Drillis & Contini 1966: knee 0.285 H,
  hip 0.53 H, shoulder 0.818 H, chin 0.87 H), in an A-pose (arms ~40 degrees from the
  body, feet slightly apart) so that no two limbs touch.
- **Shape**: each body part is one or more *round cones* (capsules whose radius varies
  linearly along the axis, exact SDF after Quilez) optionally squashed across their axis
  (elliptic torso, flat hands and feet), combined by a polynomial smooth minimum.
  Per-subject proportions (:class:`BodyParams`: stature, girth, shoulder and hip
  breadth, head size, belly, limb lengths, arm angle) are drawn from a seeded RNG.
- **Mesh**: the SDF is sampled on a grid and meshed by marching cubes
  (``igl.marching_cubes``), the largest component is kept and it is isotropically
  remeshed with pymeshlab to about ``n_vertices`` vertices; the result is checked to be
  a single-component closed 2-manifold (:func:`sshade.mesh.validate.validate_mesh`).
- **Skinning weights**: each vertex is first given to one part (:func:`part_labels`:
  the part of the nearest primitive, limbs not claiming points behind their proximal
  joint, the torso split by height at the spine and chest joints), then the one-hot
  labels are diffused on the surface
  by one implicit heat step ``(M - t L) W = M W0`` (cotangent Laplacian ``L``, mass
  matrix ``M``, ``t = s^2 / 2`` for a blend width ``s``), which blends neighbouring parts
  across joints but never leaks between parts that are close in space and far on the
  surface (hand and thigh). Weights of another mesh of the same body (the high-res
  remesh) are interpolated barycentrically at its closest points on the low-res rest
  mesh (:func:`transfer_weights`), so "the same skinning" applies at any resolution.
- **Poses** (:data:`POSE_NAMES`): rest (pose 0), then FAUST-like targets: arms raised,
  knees bent, twisted torso, (arms forward, side bend,) and last a step with a turn of
  the whole body (not aligned with the rest pose, like the paper's last target). The
  standing foot stays in place (the root is translated to keep it there), as in FAUST
  where the subjects stand on the floor. Joint angles are moderate (LBS self-intersects
  in extreme poses; with the default blend width no self-intersecting face was found in
  any pose of subjects 0-9, pymeshlab ``compute_selection_by_self_intersections_per_face``)
  and jittered per subject by +-20 % with a seeded RNG.

Pure functions over arrays plus small dataclasses; no file I/O.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from sshade.errors import SShaDeError

# moved to the generic defaust.skinning (also used by defaust.anny_source); re-exported
# here so that existing imports keep working
from .skinning import barycentric as _barycentric  # noqa: F401
from .skinning import lbs, transfer_weights  # noqa: F401

__all__ = [
    "JOINTS", "PARENT", "POSE_NAMES", "LANDMARK_NAMES", "BodyParams", "Primitive", "Body",
    "SyntheticSubject", "sample_body_params", "body_model", "primitive_sdfs", "body_sdf",
    "mesh_body", "part_labels", "skinning_weights", "transfer_weights", "pose_rotations",
    "pose_transforms", "lbs", "body_landmarks", "synthetic_subject", "pose_names",
]

#: Skeleton joints; each joint is also a skinning *part* (the bones it moves).
JOINTS: tuple[str, ...] = (
    "pelvis", "spine", "chest", "neck", "head",
    "l_clavicle", "l_shoulder", "l_elbow", "l_wrist", "r_clavicle", "r_shoulder", "r_elbow", "r_wrist",
    "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle",
)
#: Parent of each joint (``None`` for the root).
PARENT: dict[str, str | None] = {
    "pelvis": None, "spine": "pelvis", "chest": "spine", "neck": "chest", "head": "neck",
    "l_clavicle": "chest", "l_shoulder": "l_clavicle", "l_elbow": "l_shoulder", "l_wrist": "l_elbow",
    "r_clavicle": "chest", "r_shoulder": "r_clavicle", "r_elbow": "r_shoulder", "r_wrist": "r_elbow",
    "l_hip": "pelvis", "l_knee": "l_hip", "l_ankle": "l_knee",
    "r_hip": "pelvis", "r_knee": "r_hip", "r_ankle": "r_knee",
}
_JI = {n: i for i, n in enumerate(JOINTS)}

#: Pose library: index 0 is the rest pose; targets are the aligned poses in this order,
#: then always ``step_turn`` (the whole body turned and moved) as the last target.
POSE_NAMES: tuple[str, ...] = ("rest", "arms_raised", "knees_bent", "twisted_torso",
                               "arms_forward", "side_bend", "step_turn")

#: Landmarks, as on FAUST (:data:`defaust.faust_source.FAUST_LANDMARKS`), each the mesh
#: vertex nearest to where a ray from a joint leaves the body (:func:`body_landmarks`).
LANDMARK_NAMES: tuple[str, ...] = (
    "head_top", "left_hand", "right_hand", "left_elbow", "right_elbow", "chest", "crotch",
    "left_knee", "right_knee", "left_foot", "right_foot",
)


def pose_names(n_poses: int) -> list[str]:
    """Names of poses ``0 .. n_poses - 1``: rest, aligned targets, ``step_turn`` last.

    Raises
    ------
    SShaDeError unless ``2 <= n_poses <= len(POSE_NAMES)``.

    Examples
    --------
    >>> pose_names(5)
    ['rest', 'arms_raised', 'knees_bent', 'twisted_torso', 'step_turn']
    """
    n_poses = int(n_poses)
    if not 2 <= n_poses <= len(POSE_NAMES):
        raise SShaDeError(f"n_poses must be in [2, {len(POSE_NAMES)}] for the synthetic source, got {n_poses}")
    return ["rest"] + list(POSE_NAMES[1:-1][: n_poses - 2]) + ["step_turn"]


# ----------------------------------------------------------------------------- body


@dataclass(frozen=True)
class BodyParams:
    """Proportions of one synthetic subject (dimensionless factors unless stated).

    Attributes
    ----------
    height : float, stature in metres.
    girth : float, scales every limb and torso radius.
    shoulders, hips : float, shoulder and hip breadth factors.
    head : float, head size factor.
    belly : float, torso depth factor.
    arms, legs : float, limb length factors.
    arm_angle : float, degrees between each arm and the vertical in the rest pose.
    """

    height: float = 1.75
    girth: float = 1.0
    shoulders: float = 1.0
    hips: float = 1.0
    head: float = 1.0
    belly: float = 1.0
    arms: float = 1.0
    legs: float = 1.0
    arm_angle: float = 40.0


def sample_body_params(rng: np.random.Generator) -> BodyParams:
    """Draw varied but plausible proportions.

    Parameters
    ----------
    rng : numpy Generator (seeded by the caller).

    Returns
    -------
    BodyParams (stature 1.55-1.95 m, girth 0.85-1.2, ...).

    Examples
    --------
    >>> p = sample_body_params(np.random.default_rng(0)); 1.55 <= p.height <= 1.95
    True
    """
    u = rng.uniform
    sex = u(0.0, 1.0)  # 0: broad hips, 1: broad shoulders
    return BodyParams(
        height=float(u(1.55, 1.95)), girth=float(u(0.85, 1.2)),
        shoulders=float(0.92 + 0.16 * sex + u(-0.04, 0.04)), hips=float(1.08 - 0.16 * sex + u(-0.04, 0.04)),
        head=float(u(0.92, 1.08)), belly=float(u(0.9, 1.3)), arms=float(u(0.95, 1.05)),
        legs=float(u(0.95, 1.05)), arm_angle=float(u(36.0, 44.0)))


@dataclass(frozen=True)
class Primitive:
    """A round cone from ``a`` (radius ``ra``) to ``b`` (radius ``rb``), metres.

    ``Q`` (3, 3) maps ``p`` to ``a + Q (p - a)`` before the exact round-cone SDF is
    evaluated and ``c`` rescales the result (``c = 1 / ||Q||_2``, so the value is a lower
    bound of the true distance). ``part`` is the index into :data:`JOINTS` of the joint
    that moves it; ``k`` the smooth-union radius with which it joins the body.
    """

    name: str
    a: np.ndarray
    b: np.ndarray
    ra: float
    rb: float
    part: int
    k: float
    Q: np.ndarray = field(default_factory=lambda: np.eye(3))
    c: float = 1.0
    kind: str = "other"


@dataclass(frozen=True)
class Body:
    """A parametric body: proportions, rest skeleton and the primitives of its shape.

    Attributes
    ----------
    params : BodyParams.
    joints : (19, 3) float64 rest joint positions (metres), rows in :data:`JOINTS` order.
    parents : (19,) int64 parent index (-1 for the root).
    primitives : tuple of :class:`Primitive`.
    rays : dict landmark name -> (origin (3,), direction (3,)) used by
        :func:`body_landmarks`.
    """

    params: BodyParams
    joints: np.ndarray
    parents: np.ndarray
    primitives: tuple
    rays: dict


def _squash(axes_scales) -> tuple[np.ndarray, float]:
    """Q and c for shrinking the shape by ``scale`` along each unit ``axis``."""
    Q = np.eye(3)
    smin = 1.0
    for axis, s in axes_scales:
        e = np.asarray(axis, float)
        e = e / np.linalg.norm(e)
        Q = Q + (1.0 / s - 1.0) * np.outer(e, e)
        smin = min(smin, s)
    return Q, float(smin)


def body_model(params: BodyParams) -> Body:
    """Skeleton and primitives of a body with the given proportions (rest A-pose).

    Parameters
    ----------
    params : BodyParams.

    Returns
    -------
    Body, metres, +y up, +z forward, +x the subject's left.

    Examples
    --------
    >>> body = body_model(BodyParams()); body.joints.shape
    (19, 3)
    """
    p = params
    H = p.height
    g = p.girth
    J = {}
    J["pelvis"] = np.array([0.0, 0.54, 0.0]) * H
    J["spine"] = np.array([0.0, 0.62, 0.0]) * H
    J["chest"] = np.array([0.0, 0.71, 0.0]) * H
    J["neck"] = np.array([0.0, 0.815, -0.005]) * H
    J["head"] = np.array([0.0, 0.875, 0.0]) * H
    hip_w = 0.052 * H * p.hips
    sh_w = 0.105 * H * p.shoulders
    leg_top = 0.51 * H
    knee_y = leg_top - (leg_top - 0.285 * H) * p.legs
    ankle_y = 0.045 * H
    a = np.radians(p.arm_angle)
    for side, s in (("l", 1.0), ("r", -1.0)):
        J[f"{side}_hip"] = np.array([s * hip_w, leg_top, 0.0])
        J[f"{side}_knee"] = np.array([s * hip_w * 0.97, knee_y, 0.005 * H])
        J[f"{side}_ankle"] = np.array([s * hip_w * 1.02, ankle_y, -0.005 * H])
        J[f"{side}_clavicle"] = np.array([s * 0.025 * H, 0.8 * H, -0.005 * H])
        J[f"{side}_shoulder"] = np.array([s * sh_w, 0.812 * H, -0.01 * H])
        d = np.array([s * np.sin(a), -np.cos(a), 0.0])
        J[f"{side}_elbow"] = J[f"{side}_shoulder"] + 0.17 * H * p.arms * d
        J[f"{side}_wrist"] = J[f"{side}_elbow"] + 0.145 * H * p.arms * d
    joints = np.stack([J[n] for n in JOINTS])
    parents = np.array([-1 if PARENT[n] is None else _JI[PARENT[n]] for n in JOINTS], np.int64)

    prims: list[Primitive] = []

    def add(name, a_, b_, ra, rb, part, k, squash=(), kind="other"):
        Q, c = _squash(squash)
        prims.append(Primitive(name, np.asarray(a_, float), np.asarray(b_, float), float(ra), float(rb),
                               _JI[part], float(k), Q, c, kind))

    z, y = (0, 0, 1), (0, 1, 0)
    depth = 0.62 * p.belly
    # torso: pelvis, abdomen, chest (elliptic cross-sections), shoulder girdle, neck, head
    add("pelvis", [0, 0.545 * H, -0.005 * H], [0, 0.6 * H, 0], 0.095 * H * p.hips * g, 0.088 * H * g,
        "pelvis", 0.0, [(z, 0.66), (y, 0.75)], kind="torso")
    add("abdomen", [0, 0.6 * H, 0.005 * H], [0, 0.7 * H, 0], 0.087 * H * g, 0.092 * H * g * p.shoulders,
        "spine", 0.03 * H, [(z, depth)], kind="torso")
    add("chest", [0, 0.7 * H, 0], [0, 0.78 * H, -0.005 * H], 0.094 * H * g * p.shoulders,
        0.096 * H * g * p.shoulders, "chest", 0.03 * H, [(z, 0.6), (y, 0.8)], kind="torso")
    for side in ("l", "r"):
        add(f"{side}_trapezius", J[f"{side}_clavicle"], J[f"{side}_shoulder"], 0.045 * H * g,
            0.036 * H * g, f"{side}_clavicle", 0.025 * H, [(z, 0.8)], kind="limb")
    add("neck", J["neck"] + [0, -0.02 * H, 0], J["head"] + [0, 0.01 * H, 0.005 * H], 0.033 * H * g,
        0.03 * H * g, "neck", 0.02 * H)
    hc = np.array([0.0, 0.935 * H, 0.01 * H])
    add("head", hc + [0, -0.02 * H * p.head, 0.005 * H], hc + [0, 0.018 * H * p.head, -0.004 * H],
        0.056 * H * p.head, 0.052 * H * p.head, "head", 0.02 * H, [((1, 0, 0), 0.84)])
    add("nose", hc + [0, -0.005 * H, 0.04 * H * p.head], hc + [0, -0.015 * H, 0.052 * H * p.head],
        0.008 * H, 0.007 * H, "head", 0.01 * H)
    for side, s in (("l", 1.0), ("r", -1.0)):
        sh, el, wr = J[f"{side}_shoulder"], J[f"{side}_elbow"], J[f"{side}_wrist"]
        d = (wr - el) / np.linalg.norm(wr - el)
        palm = np.array([s * np.cos(a), np.sin(a), 0.0])  # palms face the thighs
        add(f"{side}_upper_arm", sh, el, 0.032 * H * g, 0.022 * H * g, f"{side}_shoulder", 0.02 * H, kind="limb")
        add(f"{side}_forearm", el, wr, 0.022 * H * g, 0.0155 * H * g, f"{side}_elbow", 0.01 * H, kind="limb")
        add(f"{side}_hand", wr + 0.01 * H * d, wr + 0.085 * H * d, 0.02 * H, 0.016 * H, f"{side}_wrist",
            0.012 * H, [(palm, 0.5)], kind="limb")
        add(f"{side}_thumb", wr + 0.02 * H * d + 0.012 * H * np.array([0, 0, 1.0]),
            wr + 0.055 * H * d + 0.025 * H * np.array([0, 0, 1.0]), 0.008 * H, 0.007 * H,
            f"{side}_wrist", 0.008 * H)
        hp, kn, an = J[f"{side}_hip"], J[f"{side}_knee"], J[f"{side}_ankle"]
        add(f"{side}_thigh", hp, kn, 0.05 * H * g * p.hips ** 0.5, 0.031 * H * g, f"{side}_hip", 0.03 * H, kind="limb")
        add(f"{side}_shin", kn, an + [0, 0.01 * H, 0], 0.032 * H * g, 0.02 * H * g, f"{side}_knee", 0.012 * H,
            kind="limb")
        add(f"{side}_foot", [an[0], 0.028 * H, -0.03 * H], [an[0] * 1.06, 0.018 * H, 0.115 * H],
            0.025 * H, 0.02 * H, f"{side}_ankle", 0.015 * H, [(y, 0.7)], kind="limb")

    head_top = hc + [0, 0.0, 0.0]
    rays = {"head_top": (head_top, (0, 1.0, 0)), "chest": (J["chest"] + [0, 0.04 * H, 0], (0, 0, 1.0)),
            "crotch": (np.array([0.0, 0.56 * H, 0.0]), (0, -1.0, 0))}
    for side, word in (("l", "left"), ("r", "right")):
        el, wr = J[f"{side}_elbow"], J[f"{side}_wrist"]
        d = (wr - el) / np.linalg.norm(wr - el)
        rays[f"{word}_hand"] = (wr + 0.05 * H * d, d)
        rays[f"{word}_elbow"] = (el, (0, 0, -1.0))
        rays[f"{word}_knee"] = (J[f"{side}_knee"], (0, 0, 1.0))
        an = J[f"{side}_ankle"]
        rays[f"{word}_foot"] = (np.array([an[0] * 1.05, 0.02 * H, 0.08 * H]), (0, 0, 1.0))
    rays = {k: (np.asarray(o, float), np.asarray(d, float) / np.linalg.norm(d)) for k, (o, d) in rays.items()}
    return Body(params=params, joints=joints, parents=parents, primitives=tuple(prims), rays=rays)


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


try:  # compiled: ~100x faster than numpy on a 1M-point grid
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
    >>> V, F = mesh_body(body_model(BodyParams()), voxel_size=0.02, n_vertices=1500)  # doctest: +SKIP
    """
    import igl
    import pymeshlab

    from sshade.mesh.validate import validate_mesh

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
    ms.meshing_isotropic_explicit_remeshing(targetlen=pymeshlab.PureValue(target),
                                            iterations=int(remesh_iterations))
    m = ms.current_mesh()
    V, F = _largest_component(np.asarray(m.vertex_matrix(), np.float64), np.asarray(m.face_matrix(), np.int64))
    if _signed_volume(V, F) < 0:
        F = F[:, ::-1].copy()
    V, F = validate_mesh(V, F, name="synthetic body", allow_boundary=False)
    return V, F


def _largest_component(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep the connected component (through shared vertices) with most faces, drop
    unreferenced vertices; vertex order is kept."""
    from scipy.sparse.csgraph import connected_components

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


# ----------------------------------------------------------------------------- skinning


def part_labels(body: Body, V) -> np.ndarray:
    """Rigid segmentation of points into parts (index into :data:`JOINTS`).

    A point goes to the part of its nearest primitive (smallest primitive SDF), except
    that a limb primitive (bone from joint ``a`` to ``b``) does not claim points behind
    ``a`` (projection on the bone axis < 0: the hip or the top of the shoulder stay with
    the torso), and the torso primitives are split by height at the spine and chest
    joints (the joints they bend at).

    Parameters
    ----------
    body : Body; V : (n, 3) points (metres, rest pose).

    Returns
    -------
    (n,) int64.

    Examples
    --------
    >>> body = body_model(BodyParams())
    >>> JOINTS[part_labels(body, body.joints[[14]])[0]]  # a point at the left knee
    'l_knee'
    """
    V = np.asarray(V, np.float64)
    D = primitive_sdfs(body, V)
    for j, pr in enumerate(body.primitives):
        if pr.kind == "limb":
            behind = (V - pr.a) @ (pr.b - pr.a) < 0
            D[behind, j] = np.inf
    parts = np.array([p.part for p in body.primitives], np.int64)
    lab = parts[np.argmin(D, axis=1)]
    torso_prim = np.array([p.kind == "torso" for p in body.primitives])
    is_torso = torso_prim[np.argmin(D, axis=1)]
    y = V[:, 1]
    ys, yc = body.joints[_JI["spine"], 1], body.joints[_JI["chest"], 1]
    tl = np.where(y < ys, _JI["pelvis"], np.where(y < yc, _JI["spine"], _JI["chest"]))
    return np.where(is_torso, tl, lab).astype(np.int64)


def skinning_weights(body: Body, V, F, *, blend: float = 0.07) -> np.ndarray:
    """Smooth LBS weights on a rest mesh of the body (heat diffusion of part labels).

    Parameters
    ----------
    body : Body.
    V : (n, 3) float64 rest positions (metres); F : (m, 3) int64 faces (closed manifold).
    blend : float, metres: width ``s`` of the blend across joints; the implicit heat
        step uses ``t = s**2 / 2`` (the heat kernel's standard deviation is ``s``).

    Returns
    -------
    W : (n, 19) float64, rows non-negative and summing to 1, columns in :data:`JOINTS`
    order.

    Raises
    ------
    SShaDeError if ``blend`` is negative.

    Examples
    --------
    >>> W = skinning_weights(body, V, F)  # doctest: +SKIP
    """
    import igl
    from scipy.sparse.linalg import splu

    if not blend >= 0:
        raise SShaDeError(f"skinning blend width must be >= 0, got {blend}")
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    lab = part_labels(body, V)
    W0 = np.zeros((len(V), len(JOINTS)))
    W0[np.arange(len(V)), lab] = 1.0
    if blend == 0:
        return W0
    L = igl.cotmatrix(V, F)
    M = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI)
    t = 0.5 * blend * blend
    A = sp.csc_matrix(M - t * L)
    W = splu(A).solve(np.asarray(M @ W0))
    W = np.maximum(W, 0.0)
    W /= W.sum(axis=1, keepdims=True)
    return np.ascontiguousarray(W)


# ----------------------------------------------------------------------------- posing


def _rotvec(axis, deg) -> np.ndarray:
    a = np.asarray(axis, float)
    return a / np.linalg.norm(a) * np.radians(deg)


def _bend(d, u, deg) -> np.ndarray:
    """Rotation vector turning direction ``d`` towards ``u`` by ``deg`` degrees."""
    axis = np.cross(d, u)
    return _rotvec(axis, deg)


def pose_rotations(body: Body, name: str, rng: np.random.Generator | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Local joint rotations and root translation of a named pose.

    Rotations are axis-angle vectors in the rest frame (applied after the parent's
    rotation: ``R_j = R_parent @ R_local_j``).

    Parameters
    ----------
    body : Body.
    name : str, one of :data:`POSE_NAMES`.
    rng : seeded Generator for the per-subject jitter (every angle times U(0.8, 1.2),
        sides swapped at random for the asymmetric poses); ``None`` = no jitter.

    Returns
    -------
    rotvecs : (19, 3) float64 radians; root_translation : (3,) float64 metres, chosen
    so that the standing foot (both feet, or the one that does not move) stays where
    it is in the rest pose; ``step_turn`` then also moves the whole body
    (0.08 H sideways, 0.1 H forward) so that it is not aligned with the rest pose.

    Raises
    ------
    SShaDeError on an unknown pose name.

    Examples
    --------
    >>> R, t = pose_rotations(body_model(BodyParams()), "arms_raised"); R.shape
    (19, 3)
    """
    J = body.joints
    H = body.params.height
    rot = np.zeros((len(JOINTS), 3))
    jit = (lambda: float(rng.uniform(0.8, 1.2))) if rng is not None else (lambda: 1.0)
    swap = bool(rng.integers(2)) if rng is not None else False
    S = ("r", "l") if swap else ("l", "r")  # S[0]: the side that does the asymmetric move
    sgn = {"l": 1.0, "r": -1.0}
    fwd, back, up = np.array([0, 0, 1.0]), np.array([0, 0, -1.0]), np.array([0, 1.0, 0])
    down = -up

    def arm_dir(side):
        return (J[_JI[f"{side}_elbow"]] - J[_JI[f"{side}_shoulder"]]) / np.linalg.norm(
            J[_JI[f"{side}_elbow"]] - J[_JI[f"{side}_shoulder"]])

    def set_(joint, v):
        rot[_JI[joint]] = v

    planted = ("l_ankle", "r_ankle")  # feet kept in place (FAUST poses stand on the floor)
    extra = np.zeros(3)
    if name == "rest":
        pass
    elif name == "arms_raised":
        for s in ("l", "r"):
            set_(f"{s}_clavicle", _rotvec((0, 0, sgn[s]), 15 * jit()))
            set_(f"{s}_shoulder", _rotvec((0, 0, sgn[s]), 60 * jit()))
            set_(f"{s}_elbow", _rotvec((0, 0, sgn[s]), 25 * jit()))
        set_("neck", _rotvec((1, 0, 0), -8 * jit()))
    elif name == "knees_bent":
        hip, knee = 45 * jit(), 60 * jit()  # the same for both legs: both feet stay planted
        for s in ("l", "r"):
            set_(f"{s}_hip", _bend(down, fwd, hip))
            set_(f"{s}_knee", _bend(down, back, knee))
            set_(f"{s}_ankle", _bend(fwd, up, knee - hip))  # foot flat on the floor
            set_(f"{s}_shoulder", _bend(arm_dir(s), fwd, 40 * jit()))
        set_("spine", _rotvec((1, 0, 0), 12 * jit()))
    elif name == "twisted_torso":
        set_("spine", _rotvec((0, 1, 0), sgn[S[0]] * 20 * jit()))
        set_("chest", _rotvec((0, 1, 0), sgn[S[0]] * 18 * jit()))
        set_("neck", _rotvec((0, 1, 0), -sgn[S[0]] * 15 * jit()))
        set_(f"{S[0]}_shoulder", _bend(arm_dir(S[0]), fwd, 45 * jit()))
        set_(f"{S[1]}_shoulder", _bend(arm_dir(S[1]), back, 25 * jit()))
        set_(f"{S[0]}_knee", _bend(down, back, 15 * jit()))
        planted = (f"{S[1]}_ankle",)
    elif name == "arms_forward":
        for s in ("l", "r"):
            set_(f"{s}_shoulder", _bend(arm_dir(s), fwd, 70 * jit()))
            set_(f"{s}_elbow", _bend(arm_dir(s), fwd, 30 * jit()))
        set_("neck", _rotvec((1, 0, 0), 10 * jit()))
    elif name == "side_bend":
        set_("spine", _rotvec((0, 0, 1), sgn[S[0]] * 12 * jit()))
        set_("chest", _rotvec((0, 0, 1), sgn[S[0]] * 10 * jit()))
        set_(f"{S[1]}_clavicle", _rotvec((0, 0, sgn[S[1]]), 10 * jit()))
        set_(f"{S[1]}_shoulder", _rotvec((0, 0, sgn[S[1]]), 55 * jit()))
        set_(f"{S[0]}_elbow", _bend(arm_dir(S[0]), fwd, 40 * jit()))
    elif name == "step_turn":
        set_("pelvis", _rotvec((0, 1, 0), sgn[S[0]] * 35 * jit()))
        planted = (f"{S[1]}_ankle",)
        extra = np.array([0.08 * sgn[S[0]], 0.0, 0.1]) * H * jit()  # and moved: not aligned
        set_(f"{S[0]}_hip", _bend(down, fwd, 45 * jit()))
        set_(f"{S[0]}_knee", _bend(down, back, 60 * jit()))
        set_(f"{S[1]}_hip", _bend(down, back, 10 * jit()))
        set_(f"{S[1]}_shoulder", _bend(arm_dir(S[1]), fwd, 35 * jit()))
        set_(f"{S[0]}_clavicle", _rotvec((0, 0, sgn[S[0]]), 10 * jit()))
        set_(f"{S[0]}_shoulder", _rotvec((0, 0, sgn[S[0]]), 50 * jit()))
        set_(f"{S[0]}_elbow", _bend(arm_dir(S[0]), fwd, 45 * jit()))
        set_("head", _rotvec((0, 1, 0), -sgn[S[0]] * 15 * jit()))
    else:
        raise SShaDeError(f"unknown synthetic pose {name!r}; known: {list(POSE_NAMES)}")
    trans = np.zeros(3)
    if name != "rest":
        R, t = pose_transforms(body, rot)
        ids = [_JI[j] for j in planted]
        posed = np.einsum("jab,jb->ja", R[ids], J[ids]) + t[ids]
        trans = J[ids].mean(0) - posed.mean(0) + extra
    return rot, trans


def pose_transforms(body: Body, rotvecs, root_translation=None) -> tuple[np.ndarray, np.ndarray]:
    """Forward kinematics: per-part affine maps ``x -> R[j] @ x + t[j]`` of the rest pose.

    Parameters
    ----------
    body : Body; rotvecs : (19, 3) local axis-angle rotations (radians, rest frame);
    root_translation : (3,) metres or None.

    Returns
    -------
    R : (19, 3, 3) float64; t : (19, 3) float64.

    Examples
    --------
    >>> body = body_model(BodyParams())
    >>> R, t = pose_transforms(body, *pose_rotations(body, "knees_bent")); R.shape
    (19, 3, 3)
    """
    from scipy.spatial.transform import Rotation

    Rl = Rotation.from_rotvec(np.asarray(rotvecs, np.float64)).as_matrix()
    J = body.joints
    nj = len(JOINTS)
    Rg = np.zeros((nj, 3, 3))
    Pg = np.zeros((nj, 3))
    for j in range(nj):  # JOINTS lists every parent before its children
        p = body.parents[j]
        if p < 0:
            Rg[j] = Rl[j]
            Pg[j] = J[j] + (0 if root_translation is None else np.asarray(root_translation, float))
        else:
            Rg[j] = Rg[p] @ Rl[j]
            Pg[j] = Pg[p] + Rg[p] @ (J[j] - J[p])
    t = Pg - np.einsum("jab,jb->ja", Rg, J)
    return Rg, t


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
    >>> lm = body_landmarks(body, V)  # doctest: +SKIP
    >>> V[lm["head_top"], 1] == V[:, 1].max()  # doctest: +SKIP
    True
    """
    from scipy.spatial import cKDTree

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


# ----------------------------------------------------------------------------- subject


@dataclass
class SyntheticSubject:
    """One synthetic subject at low resolution, with its rig and poses.

    Attributes
    ----------
    subject : int; body : Body.
    V : (n, 3) float64 rest mesh (pose 0, metres); F : (m, 3) int64, shared by all poses.
    W : (n, 19) float64 skinning weights.
    landmarks : dict name -> vertex index of V.
    pose_names : list of str, pose ``i`` is ``pose_names[i]``.
    rotvecs : (P, 19, 3) local rotations; translations : (P, 3) root translations.
    """

    subject: int
    body: Body
    V: np.ndarray
    F: np.ndarray
    W: np.ndarray
    landmarks: dict
    pose_names: list
    rotvecs: np.ndarray
    translations: np.ndarray

    def transforms(self, pose: int) -> tuple[np.ndarray, np.ndarray]:
        """Per-part (R, t) of pose ``pose``."""
        return pose_transforms(self.body, self.rotvecs[pose], self.translations[pose])

    def posed(self, pose: int, V=None, W=None) -> np.ndarray:
        """Vertices of pose ``pose``: the low-res mesh, or ``V`` with weights ``W``.

        Returns
        -------
        (n, 3) float64 metres.
        """
        V = self.V if V is None else V
        if not self.rotvecs[pose].any() and not self.translations[pose].any():
            return np.array(V, np.float64)  # the rest pose, exactly
        R, t = self.transforms(pose)
        return lbs(V, self.W if W is None else W, R, t)


def synthetic_subject(seed: int, subject: int, *, n_poses: int = 5, voxel_size: float = 0.01,
                      n_vertices: int = 7000, blend: float = 0.07,
                      remesh_iterations: int = 10) -> SyntheticSubject:
    """Build synthetic subject ``subject`` of a dataset with seed ``seed``.

    Deterministic: the same ``(seed, subject)`` and parameters give the same arrays,
    independently of the other subjects. Proportions come from
    ``SeedSequence([seed, 0xB0D1, subject])``, the jitter of pose ``name`` from
    ``SeedSequence([seed, 0x905E, subject, POSE_NAMES.index(name)])``.

    Parameters
    ----------
    seed, subject : int.
    n_poses : int, rest + targets, see :func:`pose_names`.
    voxel_size, n_vertices : see :func:`mesh_body`.
    blend : float, see :func:`skinning_weights`.
    remesh_iterations : int, see :func:`mesh_body`.

    Returns
    -------
    SyntheticSubject.

    Raises
    ------
    SShaDeError on a bad ``n_poses`` or a failed meshing.

    Examples
    --------
    >>> sub = synthetic_subject(0, 3, voxel_size=0.02, n_vertices=2000)  # doctest: +SKIP
    >>> sub.posed(1).shape == sub.V.shape  # doctest: +SKIP
    True
    """
    names = pose_names(n_poses)
    body_rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xB0D1, int(subject)]))
    body = body_model(sample_body_params(body_rng))
    V, F = mesh_body(body, voxel_size=voxel_size, n_vertices=n_vertices, remesh_iterations=remesh_iterations)
    W = skinning_weights(body, V, F, blend=blend)
    lm = body_landmarks(body, V)
    rv, tr = [], []
    for name in names:
        # one child generator per pose name: a pose does not depend on n_poses
        r = np.random.default_rng(np.random.SeedSequence(
            [int(seed), 0x905E, int(subject), POSE_NAMES.index(name)]))
        R, t = pose_rotations(body, name, None if name == "rest" else r)
        rv.append(R)
        tr.append(t)
    return SyntheticSubject(subject=int(subject), body=body, V=V, F=F, W=W, landmarks=lm,
                            pose_names=names, rotvecs=np.stack(rv), translations=np.stack(tr))

"""The synthetic bodies' shape (the ``synthetic`` source, :mod:`defaust.synthetic`):
skeleton, proportions and round-cone primitives, in metres (+x the subject's left, +y up,
+z forward; feet near y = 0). The skeleton has 19 joints (:data:`JOINTS`, tree
:data:`PARENT`) placed from the stature with anthropometric fractions (Drillis & Contini
1966); each body part is one or more round cones (:class:`Primitive`); the per-subject
proportions (:class:`BodyParams`) are drawn from a seeded RNG
(:func:`sample_body_params`); the landmarks are found along rays (:attr:`Body.rays`). Pure
functions over arrays plus small dataclasses. Details: docs/defaust.md, "Implementation
notes: defaust/synthetic_body.py".
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["JOINTS", "PARENT", "JOINT_INDEX", "LANDMARK_NAMES", "BodyParams", "Primitive", "Body",
           "sample_body_params", "body_model"]

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
#: Joint name -> its index in :data:`JOINTS` (and row of :attr:`Body.joints`).
JOINT_INDEX: dict[str, int] = {n: i for i, n in enumerate(JOINTS)}

#: Landmarks, as on FAUST (:data:`defaust.faust_source.FAUST_LANDMARKS`), each the mesh
#: vertex nearest to where a ray from a joint leaves the body
#: (:func:`defaust.synthetic_mesh.body_landmarks`).
LANDMARK_NAMES: tuple[str, ...] = (
    "head_top", "left_hand", "right_hand", "left_elbow", "right_elbow", "chest", "crotch",
    "left_knee", "right_knee", "left_foot", "right_foot",
)


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
        :func:`defaust.synthetic_mesh.body_landmarks`.
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
    joints = _skeleton(params)
    J = {n: np.array(v) for n, v in zip(JOINTS, joints)}
    parents = np.array([-1 if PARENT[n] is None else JOINT_INDEX[PARENT[n]] for n in JOINTS], np.int64)
    return Body(params=params, joints=joints, parents=parents, primitives=tuple(_primitives(params, J)),
                rays=_landmark_rays(params, J))


def _head_centre(H: float) -> np.ndarray:
    return np.array([0.0, 0.935 * H, 0.01 * H])


def _skeleton(p: BodyParams) -> np.ndarray:
    """(19, 3) rest joint positions (rows in :data:`JOINTS` order), A-pose."""
    H = p.height
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
    return np.stack([J[n] for n in JOINTS])


def _primitives(p: BodyParams, J: dict) -> list[Primitive]:
    """The round cones of the body's shape, in smooth-union order (``J``: joint name ->
    rest position)."""
    H = p.height
    g = p.girth
    a = np.radians(p.arm_angle)
    prims: list[Primitive] = []

    def add(name, a_, b_, ra, rb, part, k, squash=(), kind="other"):
        Q, c = _squash(squash)
        prims.append(Primitive(name, np.asarray(a_, float), np.asarray(b_, float), float(ra), float(rb),
                               JOINT_INDEX[part], float(k), Q, c, kind))

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
    hc = _head_centre(H)
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
    return prims


def _landmark_rays(p: BodyParams, J: dict) -> dict:
    """Landmark name -> (origin (3,), unit direction (3,)) of the ray that finds it
    (:func:`defaust.synthetic_mesh.body_landmarks`)."""
    H = p.height
    hc = _head_centre(H)
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
    return rays

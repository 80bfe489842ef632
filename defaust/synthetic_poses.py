"""The synthetic bodies' poses: a small named pose library and forward kinematics.

:data:`POSE_NAMES`: rest (pose 0), then FAUST-like targets (arms raised, knees bent,
twisted torso, then arms forward and side bend when more poses are asked for,
:func:`pose_names`) and last a step with a turn of the whole body (not aligned with the
rest pose, like the paper's last target). The standing foot stays in place, as in FAUST;
joint angles are moderate (linear blend skinning self-intersects in extreme poses) and
jittered per subject by +-20 % with a seeded RNG (:func:`pose_rotations`).
:func:`pose_transforms` turns local joint rotations into the per-part rigid maps that
:func:`defaust.skinning.lbs` blends. Pure functions over arrays; no file I/O.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from sshade.errors import SShaDeError

from .synthetic_body import JOINT_INDEX, JOINTS, Body

__all__ = ["POSE_NAMES", "pose_names", "pose_rotations", "pose_transforms"]

#: Pose library: index 0 is the rest pose; targets are the aligned poses in this order,
#: then always ``step_turn`` (the whole body turned and moved) as the last target.
POSE_NAMES: tuple[str, ...] = ("rest", "arms_raised", "knees_bent", "twisted_torso",
                               "arms_forward", "side_bend", "step_turn")

#: Landmarks, as on FAUST (:data:`defaust.faust_source.FAUST_LANDMARKS`), each the mesh


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
    >>> from defaust.synthetic_body import BodyParams, body_model
    >>> R, t = pose_rotations(body_model(BodyParams()), "arms_raised"); R.shape
    (19, 3)
    """
    if name not in _POSES:
        raise SShaDeError(f"unknown synthetic pose {name!r}; known: {list(POSE_NAMES)}")
    q = _Poser(body, rng)
    planted, extra = _POSES[name](q)
    trans = np.zeros(3)
    if name != "rest":
        J = body.joints
        R, t = pose_transforms(body, q.rot)
        ids = [JOINT_INDEX[j] for j in planted]
        posed = np.einsum("jab,jb->ja", R[ids], J[ids]) + t[ids]
        trans = J[ids].mean(0) - posed.mean(0) + extra
    return q.rot, trans


_SGN = {"l": 1.0, "r": -1.0}
_FWD, _BACK, _UP = np.array([0, 0, 1.0]), np.array([0, 0, -1.0]), np.array([0, 1.0, 0])
_DOWN = -_UP
_FEET = ("l_ankle", "r_ankle")  # feet kept in place (FAUST poses stand on the floor)


class _Poser:
    """The local rotations of one pose being set, with the per-subject jitter: ``jit()``
    is U(0.8, 1.2) (1 without ``rng``); ``S[0]`` is the side that does the asymmetric
    move (swapped at random, drawn first)."""

    def __init__(self, body: Body, rng: np.random.Generator | None):
        self.J = body.joints
        self.H = body.params.height
        self.rng = rng
        self.rot = np.zeros((len(JOINTS), 3))
        swap = bool(rng.integers(2)) if rng is not None else False
        self.S = ("r", "l") if swap else ("l", "r")

    def jit(self) -> float:
        return float(self.rng.uniform(0.8, 1.2)) if self.rng is not None else 1.0

    def arm_dir(self, side: str) -> np.ndarray:
        J = self.J
        return (J[JOINT_INDEX[f"{side}_elbow"]] - J[JOINT_INDEX[f"{side}_shoulder"]]) / np.linalg.norm(
            J[JOINT_INDEX[f"{side}_elbow"]] - J[JOINT_INDEX[f"{side}_shoulder"]])

    def set(self, joint: str, v) -> None:
        self.rot[JOINT_INDEX[joint]] = v


# Each pose sets its rotations on a _Poser and returns (planted joints, extra root move).

def _rest(q: _Poser):
    return _FEET, np.zeros(3)


def _arms_raised(q: _Poser):
    jit, set_ = q.jit, q.set
    for s in ("l", "r"):
        set_(f"{s}_clavicle", _rotvec((0, 0, _SGN[s]), 15 * jit()))
        set_(f"{s}_shoulder", _rotvec((0, 0, _SGN[s]), 60 * jit()))
        set_(f"{s}_elbow", _rotvec((0, 0, _SGN[s]), 25 * jit()))
    set_("neck", _rotvec((1, 0, 0), -8 * jit()))
    return _FEET, np.zeros(3)


def _knees_bent(q: _Poser):
    jit, set_ = q.jit, q.set
    hip, knee = 45 * jit(), 60 * jit()  # the same for both legs: both feet stay planted
    for s in ("l", "r"):
        set_(f"{s}_hip", _bend(_DOWN, _FWD, hip))
        set_(f"{s}_knee", _bend(_DOWN, _BACK, knee))
        set_(f"{s}_ankle", _bend(_FWD, _UP, knee - hip))  # foot flat on the floor
        set_(f"{s}_shoulder", _bend(q.arm_dir(s), _FWD, 40 * jit()))
    set_("spine", _rotvec((1, 0, 0), 12 * jit()))
    return _FEET, np.zeros(3)


def _twisted_torso(q: _Poser):
    jit, set_, S = q.jit, q.set, q.S
    set_("spine", _rotvec((0, 1, 0), _SGN[S[0]] * 20 * jit()))
    set_("chest", _rotvec((0, 1, 0), _SGN[S[0]] * 18 * jit()))
    set_("neck", _rotvec((0, 1, 0), -_SGN[S[0]] * 15 * jit()))
    set_(f"{S[0]}_shoulder", _bend(q.arm_dir(S[0]), _FWD, 45 * jit()))
    set_(f"{S[1]}_shoulder", _bend(q.arm_dir(S[1]), _BACK, 25 * jit()))
    set_(f"{S[0]}_knee", _bend(_DOWN, _BACK, 15 * jit()))
    return (f"{S[1]}_ankle",), np.zeros(3)


def _arms_forward(q: _Poser):
    jit, set_ = q.jit, q.set
    for s in ("l", "r"):
        set_(f"{s}_shoulder", _bend(q.arm_dir(s), _FWD, 70 * jit()))
        set_(f"{s}_elbow", _bend(q.arm_dir(s), _FWD, 30 * jit()))
    set_("neck", _rotvec((1, 0, 0), 10 * jit()))
    return _FEET, np.zeros(3)


def _side_bend(q: _Poser):
    jit, set_, S = q.jit, q.set, q.S
    set_("spine", _rotvec((0, 0, 1), _SGN[S[0]] * 12 * jit()))
    set_("chest", _rotvec((0, 0, 1), _SGN[S[0]] * 10 * jit()))
    set_(f"{S[1]}_clavicle", _rotvec((0, 0, _SGN[S[1]]), 10 * jit()))
    set_(f"{S[1]}_shoulder", _rotvec((0, 0, _SGN[S[1]]), 55 * jit()))
    set_(f"{S[0]}_elbow", _bend(q.arm_dir(S[0]), _FWD, 40 * jit()))
    return _FEET, np.zeros(3)


def _step_turn(q: _Poser):
    jit, set_, S = q.jit, q.set, q.S
    set_("pelvis", _rotvec((0, 1, 0), _SGN[S[0]] * 35 * jit()))
    extra = np.array([0.08 * _SGN[S[0]], 0.0, 0.1]) * q.H * jit()  # and moved: not aligned
    set_(f"{S[0]}_hip", _bend(_DOWN, _FWD, 45 * jit()))
    set_(f"{S[0]}_knee", _bend(_DOWN, _BACK, 60 * jit()))
    set_(f"{S[1]}_hip", _bend(_DOWN, _BACK, 10 * jit()))
    set_(f"{S[1]}_shoulder", _bend(q.arm_dir(S[1]), _FWD, 35 * jit()))
    set_(f"{S[0]}_clavicle", _rotvec((0, 0, _SGN[S[0]]), 10 * jit()))
    set_(f"{S[0]}_shoulder", _rotvec((0, 0, _SGN[S[0]]), 50 * jit()))
    set_(f"{S[0]}_elbow", _bend(q.arm_dir(S[0]), _FWD, 45 * jit()))
    set_("head", _rotvec((0, 1, 0), -_SGN[S[0]] * 15 * jit()))
    return (f"{S[1]}_ankle",), extra


_POSES = {"rest": _rest, "arms_raised": _arms_raised, "knees_bent": _knees_bent, "twisted_torso": _twisted_torso,
          "arms_forward": _arms_forward, "side_bend": _side_bend, "step_turn": _step_turn}


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
    >>> from defaust.synthetic_body import BodyParams, body_model
    >>> body = body_model(BodyParams())
    >>> R, t = pose_transforms(body, *pose_rotations(body, "knees_bent")); R.shape
    (19, 3, 3)
    """
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

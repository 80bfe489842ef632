"""The pose library of the ANNY DeFAUST source (paper appendix A: 4 target poses per
subject): FAUST-like poses as joint rotations of ANNY's rig (MakeHuman's "default"
skeleton, 163 joints), in the body frame of the rest pose (degrees; +x the subject's left,
+y up, +z forward). :func:`turn` rotates a joint (and the rig below it) about an axis
through its rest position, :func:`bend` turns its bone towards a direction, :func:`sym`
mirrors left to right. :data:`REST` is ANNY's A-pose with :data:`REST_CORRECTIONS`,
:data:`POSES` the library, :data:`DEFAULT_TARGETS` the four targets (the last one turned
and shifted). Pure data and small helpers; no model access (:mod:`defaust.anny_source`);
the arithmetic in a fixed order (:mod:`defaust.fixed_order`: the same bytes on every machine).
The pose language, the joint names and the poses: docs/defaust.md, "Implementation notes:
defaust/anny_poses.py".
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from sshade.errors import SShaDeError

from . import fixed_order as fo

__all__ = ["JointRotation", "AnnyPose", "turn", "bend", "sym", "REST_CORRECTIONS", "REST", "POSES",
           "DEFAULT_TARGETS", "LAST_TARGET_TURN_DEG", "LAST_TARGET_SHIFT", "FORWARD", "BACK", "UP", "DOWN",
           "LEFT", "RIGHT", "get_pose", "pose_from_spec", "pose_to_spec", "resolve_poses", "local_rotations"]

FORWARD, BACK, UP, DOWN, LEFT, RIGHT = (0, 0, 1.0), (0, 0, -1.0), (0, 1.0, 0), (0, -1.0, 0), (1.0, 0, 0), (-1.0, 0, 0)

#: The last target of a subject is turned by this angle (degrees) about the vertical axis
#: through the rest pose's root ...
LAST_TARGET_TURN_DEG: float = 30.0
#: ... and then moved by this vector (metres, body frame: left, up, forward).
LAST_TARGET_SHIFT: tuple[float, float, float] = (0.15, 0.0, 0.20)


@dataclass(frozen=True)
class JointRotation:
    """One rotation of a pose (:func:`turn`, :func:`bend`; docs/defaust.md,
    "Implementation notes: defaust/anny_poses.py").

    Attributes
    ----------
    joint : str, a joint of ANNY's rig (e.g. ``"upperarm01.L"``).
    kind : ``"turn"`` (about ``vector``) or ``"bend"`` (the bone towards ``vector``).
    vector : (3,) tuple of float, body frame (+x left, +y up, +z forward); any length > 0.
    degrees : float.
    """

    joint: str
    kind: str
    vector: tuple
    degrees: float

    def __post_init__(self):
        if self.kind not in ("turn", "bend"):
            raise SShaDeError(f"joint rotation of {self.joint!r}: kind must be 'turn' or 'bend', got {self.kind!r}")
        v = np.asarray(self.vector, np.float64)
        if v.shape != (3,) or not np.isfinite(v).all() or fo.norm3(v) == 0:
            raise SShaDeError(f"joint rotation of {self.joint!r}: vector must be 3 finite numbers, not all zero, "
                              f"got {self.vector!r}")
        if not np.isfinite(float(self.degrees)):
            raise SShaDeError(f"joint rotation of {self.joint!r}: degrees must be finite, got {self.degrees!r}")
        object.__setattr__(self, "vector", tuple(float(x) + 0.0 for x in v))  # + 0.0: no -0.0
        object.__setattr__(self, "degrees", float(self.degrees))

    def rotation_vector(self, bone_direction=None) -> np.ndarray:
        """Axis-angle vector (radians, body frame).

        Parameters
        ----------
        bone_direction : (3,) unit vector of the joint's bone in the rest pose (body
            frame); needed for ``"bend"``.

        Returns
        -------
        (3,) float64.

        Raises
        ------
        SShaDeError for a bend towards the bone's own direction (no rotation axis).
        """
        v = np.asarray(self.vector, np.float64)
        v = v / fo.norm3(v)
        rad = np.radians(self.degrees)
        if self.kind == "turn":
            return v * rad
        d = np.asarray(bone_direction, np.float64)
        axis = np.cross(d / fo.norm3(d), v)
        n = fo.norm3(axis)
        if n < 1e-6:
            raise SShaDeError(f"bend of {self.joint!r} towards {self.vector}: the bone already points that way")
        return axis / n * rad


def turn(joint: str, axis, degrees: float) -> JointRotation:
    """Rotate ``joint`` about ``axis`` (body frame) by ``degrees``, right-handed.

    Examples
    --------
    >>> turn("spine02", UP, 20).kind
    'turn'
    """
    return JointRotation(joint, "turn", tuple(axis), degrees)


def bend(joint: str, toward, degrees: float) -> JointRotation:
    """Rotate the bone of ``joint`` towards the body-frame direction ``toward``.

    Examples
    --------
    >>> bend("upperleg01.L", FORWARD, 80).vector
    (0.0, 0.0, 1.0)
    """
    return JointRotation(joint, "bend", tuple(toward), degrees)


def _mirror(r: JointRotation) -> JointRotation:
    if r.joint.endswith(".L"):
        j = r.joint[:-2] + ".R"
    elif r.joint.endswith(".R"):
        j = r.joint[:-2] + ".L"
    else:
        j = r.joint
    x, y, z = r.vector
    # a direction mirrors as (-x, y, z); an axis (pseudo-vector) as (x, -y, -z)
    v = (-x, y, z) if r.kind == "bend" else (x, -y, -z)
    return JointRotation(j, r.kind, v, r.degrees)


def sym(*rotations: JointRotation) -> tuple[JointRotation, ...]:
    """The given (left-side) rotations followed by their mirror images (``x -> -x``).

    Examples
    --------
    >>> [r.joint for r in sym(turn("upperarm01.L", FORWARD, 30))]
    ['upperarm01.L', 'upperarm01.R']
    >>> sym(turn("upperarm01.L", FORWARD, 30))[1].vector
    (0.0, 0.0, -1.0)
    """
    return tuple(rotations) + tuple(_mirror(r) for r in rotations)


@dataclass(frozen=True)
class AnnyPose:
    """A named pose: joint rotations from the rest pose and the joints kept in place.

    Attributes
    ----------
    name : str (file records and figure titles).
    description : str.
    rotations : tuple of :class:`JointRotation`, applied in order (two rotations of one
        joint compose: the later one after the earlier).
    planted : tuple of joint names kept at their rest positions (default: both ankles).
    level : tuple of joint names that keep their rest orientation (default: none).
    """

    name: str
    description: str
    rotations: tuple = ()
    planted: tuple = ("foot.L", "foot.R")
    level: tuple = ()

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise SShaDeError(f"a pose needs a non-empty name, got {self.name!r}")
        if not self.planted:
            raise SShaDeError(f"pose {self.name!r}: planted must name at least one joint")
        object.__setattr__(self, "rotations", tuple(self.rotations))
        object.__setattr__(self, "planted", tuple(str(j) for j in self.planted))
        object.__setattr__(self, "level", tuple(str(j) for j in self.level))


#: Applied to every pose (the rest pose included); why: docs/defaust.md, "Implementation notes:
#: defaust/anny_poses.py".
REST_CORRECTIONS: tuple[JointRotation, ...] = (
    *sym(turn("upperarm01.L", FORWARD, -15)),            # arms 15 deg closer to the body
    *sym(bend("lowerarm01.L", BACK, 20)),                 # elbows straighter
    *sym(turn("toe5-1.L", UP, 8)),                        # little toes spread outwards
)

REST = AnnyPose("rest", "ANNY's A-pose with the rest corrections (arms slightly spread)")

POSES: dict[str, AnnyPose] = {p.name: p for p in (
    AnnyPose("arms_raised", "both arms raised above the head in a V, elbows slightly bent", (
        *sym(turn("clavicle.L", FORWARD, 15), turn("upperarm01.L", FORWARD, 105),
             bend("lowerarm01.L", FORWARD, 10)),
        turn("neck01", LEFT, -8),
    )),
    AnnyPose("arms_forward", "both arms stretched forwards at shoulder height", (
        *sym(bend("upperarm01.L", FORWARD, 70), turn("upperarm01.L", UP, 18), bend("lowerarm01.L", FORWARD, 10)),
    )),
    AnnyPose("knee_lift", "left thigh lifted forwards and out, knee bent, standing on the right foot", (
        bend("upperleg01.L", FORWARD, 60), turn("upperleg01.L", UP, 25), bend("lowerleg01.L", BACK, 50),
        bend("foot.L", DOWN, 10), *sym(turn("upperarm01.L", FORWARD, 20)),
        turn("spine05", LEFT, -6), turn("spine04", LEFT, -6),
    ), planted=("foot.R",)),
    AnnyPose("squat", "half squat: hips and knees bent, feet flat, torso leaning forwards, arms forwards", (
        *sym(bend("upperleg01.L", FORWARD, 30), bend("lowerleg01.L", BACK, 45), bend("upperarm01.L", FORWARD, 60),
             turn("upperarm01.L", UP, 10)),
        turn("spine04", LEFT, 6), turn("spine03", LEFT, 6), turn("neck01", LEFT, -10),
    ), level=("foot.L", "foot.R")),
    AnnyPose("bend_twist", "torso bent forwards (~36 deg) and twisted to the subject's left (~24 deg)", (
        turn("spine05", LEFT, 12), turn("spine04", LEFT, 12), turn("spine03", LEFT, 12),
        turn("spine02", UP, 12), turn("spine01", UP, 12),
        turn("neck01", LEFT, -15), *sym(turn("upperarm01.L", FORWARD, 30)),
    )),
    AnnyPose("side_bend", "torso bent to the subject's right, left arm raised over the head", (
        turn("spine04", FORWARD, 8), turn("spine03", FORWARD, 8), turn("spine02", FORWARD, 8),
        turn("clavicle.L", FORWARD, 15), turn("upperarm01.L", FORWARD, 100), bend("lowerarm01.L", UP, 20),
        turn("upperarm01.R", FORWARD, -20),
    )),
    AnnyPose("step", "a walking step: left leg forwards, right leg back, arms swinging", (
        bend("upperleg01.L", FORWARD, 30), bend("lowerleg01.L", BACK, 25),
        bend("upperleg01.R", BACK, 12), bend("lowerleg01.R", BACK, 15), bend("foot.R", DOWN, 10),
        bend("upperarm01.L", BACK, 20), bend("upperarm01.R", FORWARD, 20), bend("lowerarm01.R", FORWARD, 20),
        *sym(turn("upperarm01.L", FORWARD, 10)),
        turn("spine03", UP, -6),
    ), planted=("foot.R",)),
)}

#: The four targets of every subject, in order (the last one is also turned and moved).
DEFAULT_TARGETS: tuple[str, ...] = ("arms_raised", "squat", "bend_twist", "step")


def get_pose(name: str) -> AnnyPose:
    """The library pose ``name``.

    Raises
    ------
    SShaDeError for an unknown name (the message lists the library).

    Examples
    --------
    >>> get_pose("squat").planted
    ('foot.L', 'foot.R')
    """
    if name == "rest":
        return REST
    if name not in POSES:
        raise SShaDeError(f"unknown ANNY pose {name!r}; the library has {sorted(POSES)} "
                          "(or give a mapping {name: ..., rotations: [[turn|bend, joint, [x, y, z], degrees], ...]})")
    return POSES[name]


def pose_from_spec(spec) -> AnnyPose:
    """A pose from a library name, an :class:`AnnyPose` or a mapping.

    Parameters
    ----------
    spec : str (library name), AnnyPose, or mapping with keys ``name`` (str),
        ``rotations`` (list of ``[kind, joint, [x, y, z], degrees]``, kind ``turn`` or
        ``bend``), optional ``description`` (str), ``planted`` and ``level`` (lists of
        joint names).

    Returns
    -------
    AnnyPose.

    Raises
    ------
    SShaDeError on an unknown name or a malformed mapping.

    Examples
    --------
    >>> p = pose_from_spec({"name": "lean", "rotations": [["turn", "spine05", [1, 0, 0], 15]]})
    >>> p.rotations[0].joint, p.planted
    ('spine05', ('foot.L', 'foot.R'))
    """
    if isinstance(spec, AnnyPose):
        return spec
    if isinstance(spec, str):
        return get_pose(spec)
    if isinstance(spec, Mapping):
        unknown = set(spec) - {"name", "description", "rotations", "planted", "level"}
        if unknown or "name" not in spec:
            raise SShaDeError(f"a pose mapping needs 'name' and 'rotations' (optional: description, planted, level), "
                              f"got keys {sorted(spec)}")
        rots = []
        for r in spec.get("rotations") or []:
            if not isinstance(r, Sequence) or isinstance(r, str) or len(r) != 4:
                raise SShaDeError(f"pose {spec['name']!r}: each rotation is [kind, joint, [x, y, z], degrees], "
                                  f"got {r!r}")
            kind, joint, vec, deg = r
            rots.append(JointRotation(str(joint), str(kind), tuple(vec), float(deg)))
        kw = {}
        for k in ("planted", "level"):
            if spec.get(k) is not None:
                kw[k] = tuple(spec[k])
        return AnnyPose(str(spec["name"]), str(spec.get("description", "")), tuple(rots), **kw)
    raise SShaDeError(f"a pose is a library name, an AnnyPose or a mapping, got {type(spec).__name__}")


def pose_to_spec(pose: AnnyPose) -> dict:
    """JSON-able mapping of a pose (the inverse of :func:`pose_from_spec`; for manifests
    and item keys).

    Examples
    --------
    >>> pose_to_spec(pose_from_spec("squat"))["planted"]
    ['foot.L', 'foot.R']
    """
    d = {"name": pose.name, "description": pose.description, "planted": list(pose.planted),
         "rotations": [[r.kind, r.joint, list(r.vector), r.degrees] for r in pose.rotations]}
    if pose.level:
        d["level"] = list(pose.level)
    return d


def resolve_poses(targets=None) -> list[AnnyPose]:
    """The rest pose followed by the target poses.

    Parameters
    ----------
    targets : sequence of pose specs (see :func:`pose_from_spec`) or None for
        :data:`DEFAULT_TARGETS`.

    Returns
    -------
    list of AnnyPose, ``[REST, target_1, ...]``.

    Raises
    ------
    SShaDeError if there is no target, a name repeats, a target is called ``rest``, or a
    spec is malformed.

    Examples
    --------
    >>> [p.name for p in resolve_poses(["squat", "step"])]
    ['rest', 'squat', 'step']
    """
    specs = list(DEFAULT_TARGETS if targets is None else targets)
    if isinstance(targets, (str, Mapping)):
        specs = [targets]
    if not specs:
        raise SShaDeError("no ANNY target pose given (anny.poses is empty)")
    poses = [pose_from_spec(s) for s in specs]
    names = [p.name for p in poses]
    if "rest" in names:
        raise SShaDeError("'rest' is pose 0 of every subject, not a target; remove it from anny.poses")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SShaDeError(f"ANNY target poses repeat: {dup}")
    return [REST] + poses


def local_rotations(pose: AnnyPose, bone_directions: Mapping[str, np.ndarray], *,
                    corrections: Sequence[JointRotation] = REST_CORRECTIONS,
                    parents: Mapping[str, str | None] | None = None) -> dict[str, np.ndarray]:
    """Rotation matrix of every joint a pose moves (rest corrections included).

    The rotations of ``corrections`` then of ``pose.rotations`` are accumulated per joint
    in order (``R_j <- R(r) @ R_j``); a bend uses the bone direction as already rotated
    by the joint's earlier rotations (``R_j @ d_j``). A joint of ``pose.level`` then gets
    the inverse of the product of its ancestors' rotations (its orientation stays).

    Parameters
    ----------
    pose : AnnyPose.
    bone_directions : mapping joint name -> (3,) rest bone direction (body frame, the
        rig's unposed skeleton), for every joint named by a rotation.
    corrections : rotations applied before the pose's (default :data:`REST_CORRECTIONS`).
    parents : mapping joint name -> parent name (None for the root); needed when the pose
        levels a joint.

    Returns
    -------
    dict joint name -> (3, 3) float64 rotation matrix in the body frame (about the
    joint's rest position), in first-use order.

    Raises
    ------
    SShaDeError if a rotation names a joint missing from ``bone_directions``.

    Examples
    --------
    >>> knee = AnnyPose("knee", "", (bend("lowerleg01.L", BACK, 90),))
    >>> R = local_rotations(knee, {"lowerleg01.L": (0, -1, 0)}, corrections=())
    >>> (R["lowerleg01.L"] @ [0, -1, 0]).round(6) + 0  # the shank now points backwards
    array([ 0.,  0., -1.])
    """
    out: dict[str, np.ndarray] = {}
    for r in (*corrections, *pose.rotations):
        if r.joint not in bone_directions:
            raise SShaDeError(f"pose {pose.name!r}: unknown joint {r.joint!r} (ANNY's rig has e.g. upperarm01.L, "
                              "lowerleg01.R, spine03, neck01, head; see defaust.anny_poses)")
        Rj = out.get(r.joint, np.eye(3))
        d = fo.matmul(Rj, np.asarray(bone_directions[r.joint], np.float64)[:, None])[:, 0]
        out[r.joint] = fo.matmul(fo.rotvec_to_matrix(r.rotation_vector(d)), Rj)
    for j in pose.level:
        if parents is None or j not in parents:
            raise SShaDeError(f"pose {pose.name!r}: cannot level joint {j!r} (unknown joint or no rig given)")
        net, a = np.eye(3), parents[j]
        while a is not None:
            net = fo.matmul(out.get(a, np.eye(3)), net)
            a = parents[a]
        out[j] = net.T
    return out

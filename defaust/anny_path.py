"""The way from the rest pose to a target pose of an ANNY subject, frame by frame: the
ground truth of an animated DeFAUST case (:func:`path_transforms`).

Frame ``a`` in [0, 1] turns every joint's rotation (ANNY's axis-angle pose arrays, rest
corrections included) along the geodesic ``R_j(a) = R_j^0 exp(a log(R_j^0^T R_j^p))``
(:func:`interpolate_pose_arrays`), poses the body by the builder's skinning, keeps the
planted joints (the feet) at their rest positions and grows the last target's turn and
shift in proportion to ``a``: frame 0 is the rest pose, frame 1 the target (to rounding).
Any mesh of the rest surface follows through
:meth:`defaust.anny_source.AnnySubject.posed_by`. The arithmetic is in a fixed order
(:mod:`defaust.fixed_order`, :mod:`defaust.anny_fixed`): the same bytes on every machine.
"""
from __future__ import annotations

import numpy as np

from sshade.errors import SShaDeError

from . import anny_fixed
from . import fixed_order as fo
from .anny_source import AnnySubject, body_transform, placement

__all__ = ["interpolate_pose_arrays", "path_transforms"]


def interpolate_pose_arrays(rest: dict, target: dict, a: float) -> dict:
    """ANNY's pose arrays a fraction ``a`` of the way from ``rest`` to ``target``: per
    joint the geodesic between the two rotations (module docstring), by rotation matrices
    (:func:`defaust.fixed_order.rotvec_to_matrix`, :func:`~defaust.fixed_order.matmul`,
    :func:`~defaust.fixed_order.matrix_to_rotvec`).

    Parameters
    ----------
    rest, target : dict group name -> (j, 3) axis-angle arrays (radians), the same keys and
        shapes. a : float in [0, 1].

    Returns
    -------
    dict of the same keys, (j, 3) float64 arrays (``rest``'s rotations at 0, ``target``'s
    at 1, up to rounding).

    Raises
    ------
    SShaDeError on different keys or shapes, or ``a`` outside [0, 1].
    """
    if not 0.0 <= float(a) <= 1.0:
        raise SShaDeError(f"interpolate_pose_arrays: a must be in [0, 1], got {a}")
    if set(rest) != set(target) or any(np.shape(rest[g]) != np.shape(target[g]) for g in rest):
        raise SShaDeError("interpolate_pose_arrays: the two poses' arrays differ in groups or shapes")
    out = {}
    for g in rest:
        R0 = fo.rotvec_to_matrix(np.asarray(rest[g], np.float64).reshape(-1, 3))
        R1 = fo.rotvec_to_matrix(np.asarray(target[g], np.float64).reshape(-1, 3))
        step = fo.matrix_to_rotvec(fo.matmul(np.swapaxes(R0, -1, -2), R1))  # log(R0^T R1)
        Ra = fo.matmul(R0, fo.rotvec_to_matrix(float(a) * step))
        out[g] = fo.matrix_to_rotvec(Ra).reshape(np.shape(rest[g]))
    return out


def path_transforms(sub: AnnySubject, model, pose: int, alphas) -> np.ndarray:
    """The joint maps of the frames ``alphas`` of the way from the rest pose to target
    ``pose`` (module docstring), in the shape of :attr:`AnnySubject.T`.

    Parameters
    ----------
    sub : :class:`defaust.anny_source.AnnySubject` (built by
        :func:`defaust.anny_source.anny_subject` with ``model``). model : ANNY's assets
        (:func:`defaust.anny_fixed.load_anny_fixed`). pose : int target index, 1 .. P-1.
        alphas : (f,) floats in [0, 1].

    Returns
    -------
    (f, k, 3, 4) float64, per frame and joint of ``sub.joint_names`` the map ``u -> T[:, :3]
    u + T[:, 3]`` from the unposed body to the frame (metres, body frame).

    Raises
    ------
    SShaDeError on a pose out of range or an alpha outside [0, 1].

    Example::

        model = load_anny_fixed()
        sub = anny_subject(0, model=model)
        T = path_transforms(sub, model, 2, np.linspace(0, 1, 31))   # (31, k, 3, 4)
        frames = [sub.posed_by(Ta, V=Vh, W=Wh) for Ta in T]         # high-res ground truth
    """
    if not 1 <= int(pose) < len(sub.T):
        raise SShaDeError(f"path_transforms: target pose {pose} out of range [1, {len(sub.T)})")
    names = list(model.joint_names)
    used = [names.index(n) for n in sub.joint_names]
    ident = anny_fixed.prepare_identity(model, np.asarray(sub.phenotype.shape, np.float64))
    A = body_transform(sub.offset)
    Ainv = fo.rigid_inverse(A)
    last = len(sub.T) - 1
    out = []
    for a in np.asarray(alphas, np.float64).ravel():
        arr = interpolate_pose_arrays(sub.pose_params[0], sub.pose_params[int(pose)], float(a))
        R = anny_fixed.pack_rotations(arr["body_pose"], arr["head_pose"], arr["hand_pose"])
        res = anny_fixed.prepare_pose(model, ident, R)
        S, K = res["skinning_transforms"], res["skeleton_transforms"]
        X = fo.matmul(fo.matmul(A, S[used]), Ainv)  # unposed -> frame, body frame
        G, _ = placement(int(pose), sub.poses[int(pose)], last, K, A, names, sub.joints, sub.offset, fraction=float(a))
        out.append((X if G is None else fo.matmul(G, X))[:, :3, :])
    return np.stack(out) if out else np.empty((0, len(used), 3, 4))

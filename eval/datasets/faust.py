"""FAUST registrations as handle-driven deformation cases (DeFAUST protocol).
Floor 2 of eval/ (eval/datasets/, tests/test_layering.py); notes: docs/implementation.md.

Source: SShaDe paper (Maggioli et al., Eurographics 2025), appendix "DeFAUST dataset";
data: MPI-FAUST training registrations (Bogo et al. 2014), files ``tr_reg_XYZ.ply``
with index ``i = XYZ = 10 * subject + pose`` (subject ``i // 10``, pose ``i % 10``),
6890 vertices each, all sharing ONE face array and in vertex-to-vertex correspondence
(the SMPL template topology). Units: metres."""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional  # OmegaConf 2.3 reads typing's generics

import numpy as np
from omegaconf import MISSING

from defaust.faust_source import FAUST_LANDMARKS as _FAUST_LANDMARKS
from defaust.faust_source import discover_faust, faust_subjects
from defaust.handles import landmark_handles, landmarks_for_target  # the DeFAUST builder's (one implementation)
from eval.datasets.dataset_options import DatasetOptions
from eval.datasets.dataset_registry import register_dataset
from eval.datasets.deformation_case import DeformationCase
from harness.checks import checked_field
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh

__all__ = ["FAUST_LANDMARKS", "PROTOCOLS", "FaustOptions", "Case", "discover_faust", "faust_cases", "case_seed",
           "faust_plan"]

log = logging.getLogger(__name__)

#: Landmark vertices on the FAUST/SMPL template (6890 vertices), in handle-group order.
#: Subject's left = +x, up = +y, forward = +z in ``tr_reg_000``.
#:
#: How they were chosen (geometry only, on ``tr_reg_000.ply``, then hard-coded):
#: geodesic distance = Dijkstra over the edge graph with Euclidean edge lengths.
#: The five extremities are the farthest-point picks of the geodesic distance from the
#: vertex nearest the centroid (suppressing 0.5 m around each pick); the one nearest the
#: centre is the head, the two nearest the head are the hands, the others the feet; left
#: vs right from a body frame (up = crotch -> head, left = right hand -> left hand,
#: forward = left x up, sign fixed so the face bulges forward). Stature ``S`` = head top
#: height above the toes (1.753 m for subject 0). Proportions from Drillis & Contini
#: (1966) anthropometric tables.
#:
#: - head_top 414: vertex near the head extremity (within 0.15 m) farthest from both
#:   feet (max of the summed geodesic distances to the two toe tips); highest vertex.
#: - left_hand 2445 / right_hand 5905: geodesic extremities = middle finger tips.
#: - left_foot 3295 / right_foot 6695: geodesic extremities = toe tips.
#: - crotch 1363: midpoint of the shortest edge path from toe tip to toe tip.
#: - left_elbow 1623 / right_elbow 5092: most posterior vertex at geodesic distance
#:   0.254 S (forearm + hand) from the finger tip.
#: - left_knee 1046 / right_knee 4530: most anterior vertex of the leg at height
#:   0.285 S above the floor (knee height).
#: - chest 3077: most anterior vertex of the mid-sagittal line (|lateral| < 1 cm) at
#:   height 0.72 S (sternum, between the breasts).
#:
#: Verification (on the 10 registrations in ``shared/data/faust_reg``): re-running the
#: same rule on subject 1's rest pose ``tr_reg_010`` gives the same vertex for hands,
#: feet, crotch and left knee and a vertex within 3.5-4.2 cm geodesic of the hard-coded
#: one for head top, elbows, right knee and chest (the 90-vertex geodesic neighbourhood
#: the handles are drawn from reaches 5-15 cm from its landmark). In every pose of
#: subjects 0 and 1 the hand and foot landmarks are within 0.6 cm of a geodesic
#: extremity wherever the extremity search finds that limb, and the intrinsic distances
#: hand->elbow (0.38-0.46 m), foot->knee (0.56-0.66 m), crotch->chest and head->chest
#: vary by a few percent across the poses of one subject, i.e. each index stays on the
#: same body part. The indices agree with the usual SMPL vertex
#: names (2445 = left middle finger tip, 5905 = right middle finger tip, head top next
#: to SMPL's 411).
FAUST_LANDMARKS = _FAUST_LANDMARKS  # one list, in defaust.faust_source

FAUST_N_VERTICES = 6890

#: ``dataset.protocol`` values, see the module docstring.
PROTOCOLS = ("paper", "all_landmarks")


@dataclass
class FaustOptions(DatasetOptions):
    """``conf/dataset/faust.yaml``: the keys of :class:`DatasetOptions` and FAUST's own,
    checked when made (SShaDeError naming ``dataset.<key>``).

    Attributes
    ----------
    protocol : ``"paper"`` or ``"all_landmarks"``, n_targets : int >= 1, targets per subject
        of ``paper``; subjects, poses : None or integers >= 0 (one integer or a list; a
        list once made): which cases, see :func:`faust_plan`.
    n_per_landmark, neighbourhood : int >= 1, static_threshold : metres >= 0, see
        :func:`defaust.handles.landmark_handles`.
    seed : int >= 0, the dataset seed; each case draws with :func:`case_seed`.
    """

    name: str = "faust"
    root: Optional[str] = MISSING  # the user's to set: composed, the section shows it missing (???)
    protocol: str = "paper"
    n_targets: int = checked_field(int, min=1, default=4)
    subjects: Any = checked_field(list[int], allow_none=True, default=None)
    poses: Any = checked_field(list[int], allow_none=True, default=None)
    n_per_landmark: int = checked_field(int, min=1, default=30)
    neighbourhood: int = checked_field(int, min=1, default=90)
    static_threshold: float = checked_field(float, min=0, default=0.02)
    seed: int = checked_field(int, min=0, default=0)

    def __post_init__(self):
        super().__post_init__()  # the declared fields (harness.checks.check_fields)
        if self.protocol not in PROTOCOLS:
            raise SShaDeError(f"dataset.protocol must be one of {list(PROTOCOLS)}, got {self.protocol!r}")


@dataclass
class Case(DeformationCase):
    """One FAUST deformation case: deform the rest pose with handles towards a target
    pose (fields of :class:`eval.datasets.deformation_case.DeformationCase`, plus the ones below).

    Attributes
    ----------
    name : ``"s{subject}_p{pose}"``; V in metres; V_gt : (n, 3) the target-pose
    registration (ground truth); group indexes ``landmark_names``.
    landmark_names : tuple of str, (L,) the landmarks of this case (6 or 11 names,
        :data:`FAUST_LANDMARKS` order).
    delta : (L,) float64 summed group displacement per landmark (metres).
    seed : int, seed of the handle draw (:func:`case_seed`).
    rest_path, target_path : Path, source files.
    """

    delta: np.ndarray = field(repr=False, default=None)
    landmark_names: tuple = ()
    seed: int = 0
    rest_path: Path | None = None
    target_path: Path | None = None


def case_seed(seed: int, subject: int, pose: int) -> int:
    """Deterministic per-case seed from the dataset seed, subject and pose.

    ``numpy.random.SeedSequence([seed, subject, pose])``, first 32-bit word: independent
    of which other cases are present or of the order they are processed in.
    """
    return int(np.random.SeedSequence([int(seed), int(subject), int(pose)]).generate_state(1)[0])


def faust_plan(files: dict, *, protocol: str = "paper", subjects=None, poses=None, n_targets: int = 4,
               landmarks: dict[str, int] | None = None) -> list[tuple[int, int, dict[str, int]]]:
    """The cases of a protocol: ``(subject, pose, landmarks)`` in (subject, pose) order.

    Parameters
    ----------
    files : output of :func:`discover_faust`.
    protocol : ``"paper"`` or ``"all_landmarks"`` (module docstring).
    subjects : iterable of int or None, subjects to use (default: all present).
    poses : iterable of int or None. ``all_landmarks``: the target poses kept (default:
        all present except 0). ``paper``: the explicit target list, as the builder's
        ``faust_target_poses`` (the last one listed that a subject has gets all landmarks);
        default: the first ``n_targets`` non-rest poses present.
    n_targets : int, targets per subject of the ``paper`` protocol (paper: 4).
    landmarks : dict name -> vertex index, default :data:`FAUST_LANDMARKS`.

    Returns
    -------
    list of ``(subject, pose, {name: vertex})``; subjects without a pose-0 file are
    skipped (with a warning under ``all_landmarks``).

    Raises
    ------
    SShaDeError on an unknown protocol, a bad ``n_targets`` or when no case is left
    ("no FAUST case ...").

    Examples
    --------
    >>> files = {(0, p): f"tr_reg_00{p}.ply" for p in range(6)}
    >>> [(s, p, len(lm)) for s, p, lm in faust_plan(files)]
    [(0, 1, 6), (0, 2, 6), (0, 3, 6), (0, 4, 11)]
    """
    lm = dict(FAUST_LANDMARKS if landmarks is None else landmarks)
    subj_sel = None if subjects is None else sorted({int(s) for s in _as_list(subjects)})
    pose_sel = None if poses is None else sorted({int(p) for p in _as_list(poses)})
    if protocol == "paper":
        if isinstance(n_targets, bool) or not isinstance(n_targets, (int, np.integer)) or n_targets < 1:
            raise SShaDeError(f"dataset.n_targets must be a positive integer, got {n_targets!r}")
        try:
            plan = faust_subjects(files, n_targets=int(n_targets), target_poses=pose_sel, subjects=subj_sel)
        except SShaDeError as e:
            raise SShaDeError(f"no FAUST case for the paper protocol: {e}") from None
        return [(s, p, landmarks_for_target(lm, ti, len(ps))) for s, ps in plan.items() for ti, p in enumerate(ps)]
    if protocol != "all_landmarks":
        raise SShaDeError(f"dataset.protocol must be one of {list(PROTOCOLS)}, got {protocol!r}")
    out = []
    for s in sorted({s for s, _ in files}):
        if subj_sel is not None and s not in subj_sel:
            continue
        targets = [p for (s2, p) in files if s2 == s and p != 0 and (pose_sel is None or p in pose_sel)]
        if targets and (s, 0) not in files:
            log.warning("FAUST subject %d has no rest pose (tr_reg_%d0.ply); skipped", s, s)
            continue
        out += [(s, p, dict(lm)) for p in targets]
    if not out:
        raise SShaDeError(f"no FAUST case for subjects={_fmt(subj_sel)} poses={_fmt(pose_sel)} "
                          f"(found subject/pose {sorted(files)}; rest pose 0 and at least one other pose are needed)")
    return out


def faust_cases(root, options: FaustOptions | None = None) -> list[Case]:
    """Build the deformation cases from a folder of FAUST registrations.

    Parameters
    ----------
    root : str or Path, see :func:`discover_faust`.
    options : :class:`FaustOptions` (None: its defaults): ``subjects``, ``poses``,
        ``protocol``, ``n_targets`` say which cases and which landmarks, see
        :func:`faust_plan` (``protocol`` ``"paper"`` by default: 4 targets per subject, 6
        landmarks for the first three, 11 for the last); ``n_per_landmark``,
        ``neighbourhood``, ``static_threshold``: see :func:`defaust.handles.landmark_handles`
        (threshold in metres); ``seed``: each case uses :func:`case_seed` ``(seed, subject,
        pose)``; ``limit``: only the first ``limit`` cases in (subject, pose) order.

    Returns
    -------
    list of :class:`Case`, sorted by (subject, pose).

    Raises
    ------
    SShaDeError
        No registrations found, unreadable/invalid mesh, a mesh whose faces differ from
        its rest pose's (not a FAUST registration), or no case left after filtering.
    """
    o = FaustOptions() if options is None else options
    files = discover_faust(root)
    try:
        plan = faust_plan(files, protocol=o.protocol, subjects=o.subjects, poses=o.poses, n_targets=o.n_targets)
    except SShaDeError as e:
        raise SShaDeError(f"{Path(root)}: {e}") from None
    if o.limit is not None:
        plan = plan[:o.limit]
    rest: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    cases: list[Case] = []
    for s, p, lm in plan:
        if s not in rest:
            rest[s] = _read_rest(files[(s, 0)])
        V0, F0 = rest[s]
        V1, F1 = read_mesh(files[(s, p)])
        if V1.shape != V0.shape or F1.shape != F0.shape or not np.array_equal(F1, F0):
            raise SShaDeError(f"{files[(s, p)]}: connectivity differs from the rest pose {files[(s, 0)]}; "
                              "FAUST registrations must share one face array")
        bad = [k for k, v in lm.items() if not 0 <= v < len(V0)]
        if bad:
            raise SShaDeError(f"{files[(s, 0)]}: landmark(s) {bad} out of range for {len(V0)} vertices")
        cs = case_seed(o.seed, s, p)
        H = landmark_handles(V0, F0, V1, lm, n_per_landmark=o.n_per_landmark,
                             neighbourhood=o.neighbourhood, static_threshold=o.static_threshold, seed=cs)
        cases.append(Case(name=f"s{s}_p{p}", subject=s, pose=p, V=V0, F=F0, handles=H.index,
                          targets=H.target, static=H.static, V_gt=V1, group=H.group, delta=H.delta,
                          landmark_names=H.landmark_names, seed=cs, rest_path=files[(s, 0)],
                          target_path=files[(s, p)]))
    return cases


def _read_rest(path) -> tuple[np.ndarray, np.ndarray]:
    """A subject's rest mesh, with a warning when it is not the 6890-vertex template."""
    V0, F0 = read_mesh(path)
    if len(V0) != FAUST_N_VERTICES:
        log.warning("%s has %d vertices, not the FAUST template's %d; landmark indices may be meaningless",
                    path, len(V0), FAUST_N_VERTICES)
    return V0, F0


def _as_list(x) -> list:
    if isinstance(x, (int, np.integer)):
        return [x]
    try:
        return list(x)
    except TypeError:
        raise SShaDeError(f"expected an int or a list of ints, got {x!r}") from None


def _fmt(sel) -> str:
    return "all" if sel is None else str(sorted(sel))


register_dataset("faust", faust_cases, options=FaustOptions)

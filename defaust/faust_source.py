"""The ``faust`` source: a user's MPI-FAUST training registrations.

Files ``tr_reg_XYZ.ply`` (index ``i = XYZ``: subject ``i // 10``, pose ``i % 10``), 6890
vertices each, all sharing one face array and in vertex-to-vertex correspondence, so
the correspondence ``pi`` of the paper's appendix is the identity on vertex indices.
Units: metres; +x = subject's left, +y = up, +z = forward (in ``tr_reg_000``).

Nothing of FAUST is distributed with the project: the user points the builder at a
folder (``faust.root=DIR``) holding ``training/registrations/`` (the layout of the
official archive) or the files themselves; any subset of the 100 files may be there.
"""
from __future__ import annotations

import re
from pathlib import Path

from sshade.errors import SShaDeError

__all__ = ["FAUST_LANDMARKS", "FAUST_N_VERTICES", "discover_faust", "faust_subjects"]

FAUST_N_VERTICES = 6890
_NAME = re.compile(r"^tr_reg_(\d{3})\.ply$")

#: Landmark vertices on the 6890-vertex FAUST/SMPL template, in handle-group order.
#: The same list as ``eval/datasets/faust.py`` (so the builder and the evaluator's
#: direct FAUST cases draw handles around the same points). Determined geometrically on
#: ``tr_reg_000.ply`` (geodesic distance = Dijkstra on the edge graph with Euclidean
#: edge lengths; stature S = head-top height above the toes) and hard-coded:
#:
#: - head_top 414: the highest vertex of ``tr_reg_000`` (checked: it is ``argmax y``).
#: - left_hand 2445 / right_hand 5905: geodesic extremities = middle finger tips
#:   (5.7 / 6.5 cm from the x-extreme vertices, which lie on the hands' outer edges).
#: - left_foot 3295 / right_foot 6695: geodesic extremities = toe tips (1.2 / 1.3 cm
#:   from the most anterior vertex of each foot).
#: - crotch 1363: midpoint of the shortest edge path from toe tip to toe tip.
#: - left_elbow 1623 / right_elbow 5092: most posterior vertex at geodesic distance
#:   0.254 S (forearm + hand) from the finger tip.
#: - left_knee 1046 / right_knee 4530: most anterior vertex of the leg at height
#:   0.285 S above the floor (knee height, Drillis & Contini 1966).
#: - chest 3077: most anterior vertex of the mid-sagittal line at height 0.72 S.
#:
#: Targets other than the last use :data:`defaust.handles.BASE_LANDMARKS` (head top,
#: hands, feet, crotch); the last target uses all eleven (paper appendix: "for the last
#: pose we use more landmarks").
FAUST_LANDMARKS: dict[str, int] = {
    "head_top": 414,
    "left_hand": 2445,
    "right_hand": 5905,
    "left_elbow": 1623,
    "right_elbow": 5092,
    "chest": 3077,
    "crotch": 1363,
    "left_knee": 1046,
    "right_knee": 4530,
    "left_foot": 3295,
    "right_foot": 6695,
}


def discover_faust(root) -> dict[tuple[int, int], Path]:
    """Find FAUST registration files ``tr_reg_XYZ.ply``.

    Looks in ``root`` and in ``root/training/registrations`` (a file directly in
    ``root`` wins over one with the same name in the archive layout).

    Parameters
    ----------
    root : str or Path, folder to search.

    Returns
    -------
    dict ``(subject, pose) -> Path``, sorted by key; subject = XYZ // 10,
    pose = XYZ % 10.

    Raises
    ------
    SShaDeError if ``root`` does not exist, is not a folder, or holds no
    ``tr_reg_XYZ.ply`` file (the message names the paths searched).

    Examples
    --------
    Example::

        files = discover_faust("../shared/data/faust_reg")
        sorted(files)[:2]
        # -> [(0, 0), (0, 1)]
    """
    if root is None or str(root) == "":
        raise SShaDeError("FAUST folder not given: pass faust.root=DIR (a folder with tr_reg_XYZ.ply files "
                          "or an MPI-FAUST folder with training/registrations/)")
    root = Path(root).expanduser()
    if not root.exists():
        raise SShaDeError(f"FAUST folder not found: {root}")
    if not root.is_dir():
        raise SShaDeError(f"FAUST root is not a folder: {root}")
    found: dict[tuple[int, int], Path] = {}
    for d in (root, root / "training" / "registrations"):
        if not d.is_dir():
            continue
        for p in sorted(d.iterdir()):
            m = _NAME.match(p.name)
            if m and p.is_file():
                i = int(m.group(1))
                found.setdefault((i // 10, i % 10), p)
    if not found:
        raise SShaDeError(f"no FAUST registrations (tr_reg_XYZ.ply) found in {root} "
                          f"or {root / 'training' / 'registrations'}")
    return dict(sorted(found.items()))


def faust_subjects(files: dict[tuple[int, int], Path], *, n_targets: int = 4, target_poses=None,
                   subjects=None) -> dict[int, list[int]]:
    """Target poses per subject: rest pose 0 plus up to ``n_targets`` others.

    Parameters
    ----------
    files : output of :func:`discover_faust`.
    n_targets : int, targets per subject when ``target_poses`` is None: the first
        ``n_targets`` non-zero poses present, in increasing order (the paper uses 4).
    target_poses : list of int or None, explicit target poses (those absent for a
        subject are skipped for it).
    subjects : list of int or None, keep only these subjects.

    Returns
    -------
    dict subject -> sorted list of target poses; subjects without a pose-0 file or
    without any target are left out.

    Raises
    ------
    SShaDeError if no subject is left (the message lists what was found), or a
    requested pose is 0 or outside 0..9.

    Examples
    --------
    >>> faust_subjects({(0, 0): "a", (0, 3): "b", (1, 2): "c"})
    {0: [3]}
    """
    if target_poses is not None:
        target_poses = sorted({int(p) for p in target_poses})
        bad = [p for p in target_poses if not 1 <= p <= 9]
        if bad:
            raise SShaDeError(f"faust target poses must be in 1..9 (pose 0 is the rest pose), got {bad}")
    keep = None if subjects is None else {int(s) for s in subjects}
    plan: dict[int, list[int]] = {}
    for s in sorted({s for s, _ in files}):
        if keep is not None and s not in keep:
            continue
        if (s, 0) not in files:
            continue
        present = sorted(p for (s2, p) in files if s2 == s and p != 0)
        poses = [p for p in present if p in target_poses] if target_poses is not None else present[:int(n_targets)]
        if poses:
            plan[s] = poses
    if not plan:
        raise SShaDeError(f"no FAUST subject with a rest pose (pose 0) and a target pose among {sorted(files)}"
                          f" (subjects={None if keep is None else sorted(keep)}, target_poses={target_poses})")
    return plan

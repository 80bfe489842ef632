"""Seconds per optimiser step of Implicit-ARAP (SDF fit and deformation) for a preset on
one device, and what a whole case at the preset's step counts would take.

One warm-up call (50 SDF steps, 2 deformation steps), then one timed call with
``--sdf-steps`` SDF steps and ``--deform-steps`` deformation steps on the mesh, with
``--handles`` random vertices moved by ``--move`` (units of the mesh) along x; the method's
own ``info["sdf_fit_s"]`` and ``info["deform_s"]`` divided by the step counts. With
``--both`` the timing is repeated with PyTorch's default (non-deterministic) kernels in
place of the method's deterministic ones.

    python benchmarks/implicit_arap_step_time.py MESH [--preset paper] [--device cuda] [--both]

Prints one JSON object. Needs PyTorch (extra [neural]); the paper preset needs a GPU to end
in minutes. Record: benchmarks/records/implicit_arap_paper_h200_attempt.md.
"""
import argparse
import contextlib
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

import baselines.implicit_arap.method as ia  # noqa: E402
from baselines.implicit_arap.backend import torch  # noqa: E402
from baselines.implicit_arap.params import ImplicitARAPParams  # noqa: E402
from sshade.mesh import read_mesh  # noqa: E402


def step_times(V, F, h, t, args) -> dict:
    """SDF-fit and deformation seconds per step of one timed call (after a warm-up call)."""
    kw = dict(preset=args.preset, device=args.device)
    m = ia.ImplicitARAP(sdf_steps=50, deform_steps=2, **kw)
    m.warmup()
    m.deform(V, F, h, t)
    m = ia.ImplicitARAP(sdf_steps=args.sdf_steps, deform_steps=args.deform_steps, **kw)
    m.deform(V, F, h, t)
    sdf = m.info["sdf_fit_s"] / args.sdf_steps
    dfm = m.info["deform_s"] / args.deform_steps
    full = ImplicitARAPParams(preset=args.preset)  # the preset's step counts
    return {"sdf_ms_per_step": 1e3 * sdf, "deform_ms_per_step": 1e3 * dfm, "device": m.info["device"],
            "case_estimate_s": full.sdf_steps * sdf + full.deform_steps * dfm, "threads": m.info["threads"]}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mesh")
    p.add_argument("--preset", default="paper")
    p.add_argument("--device", default="cuda")
    p.add_argument("--sdf-steps", type=int, default=400)
    p.add_argument("--deform-steps", type=int, default=40)
    p.add_argument("--handles", type=int, default=180)
    p.add_argument("--move", type=float, default=0.02)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--both", action="store_true", help="also time PyTorch's default kernels")
    args = p.parse_args()
    if args.device == "cuda" and not torch.cuda.is_available():
        print("error: --device cuda: PyTorch sees no CUDA device", file=sys.stderr)
        return 2
    V, F = read_mesh(args.mesh)
    rng = np.random.default_rng(args.seed)
    h = np.sort(rng.choice(len(V), args.handles, replace=False))
    t = V[h] + np.array([args.move, 0.0, 0.0])
    out = {"mesh": args.mesh, "n_vertices": len(V), "handles": args.handles, "seed": args.seed,
           "preset": args.preset, "torch": torch.__version__,
           "gpu": torch.cuda.get_device_name(0) if args.device == "cuda" else None,
           "deterministic": step_times(V, F, h, t, args)}
    if args.both:
        ia.deterministic = contextlib.nullcontext  # the method's kernels as PyTorch's defaults
        out["default_kernels"] = step_times(V, F, h, t, args)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

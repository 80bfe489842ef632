"""How many deformation steps Implicit-ARAP needs to reach its handles, per case and
preset: the largest handle-to-target distance (% of the rest bounding-box diagonal, the
evaluator's Handle column and its 1 % bound) after every ``--every`` steps of one run.

Each case runs once with ``deform_steps`` = the largest of ``--steps``; the error read
after step s is the result a run of s steps would give (same seed, same draws: the
schedule, patches and Adam states up to step s do not depend on the later steps).

    python benchmarks/implicit_arap_steps.py --dataset faust --root DIR [--cases s0_p1,s0_p3]
        [--preset cpu] [--set arap_weight=1000 --set reference_weights=true] [--steps 500 1000 1500]
    python benchmarks/implicit_arap_steps.py --dataset defaust --root data/defaust --cases s00_p01

Prints one Markdown table: case, handles, the handle error at each of ``--steps``, the
SDF-fit and deformation seconds. Needs PyTorch (extra [neural]).
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from baselines.implicit_arap import ImplicitARAP  # noqa: E402
from baselines.implicit_arap.method import apply_field  # noqa: E402
from baselines.implicit_arap.sdf import normalisation  # noqa: E402
from eval.datasets import load_cases  # noqa: E402
from sshade.guard import handle_error  # noqa: E402


def handle_errors(case, preset: str, settings: dict, steps: list[int], every: int) -> tuple[dict, dict]:
    """{step: handle error %} at each multiple of ``every`` and each of ``steps``, and the run's info."""
    V, F, H, T = case.V, case.F, case.handles, case.targets
    centre, scale = normalisation(V, F)
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    m = ImplicitARAP(preset=preset, device="cpu", **{**settings, "deform_steps": max(steps)})
    errors = {}

    def watch(step, field):
        if step % every == 0 or step in steps:
            U = apply_field(field, (V[H] - centre) * scale, "cpu") / scale + centre
            errors[step] = handle_error(np.asarray(U), np.arange(len(H)), T, diag)

    m.monitor = watch
    m.deform(V, F, H, T)
    return errors, m.info


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--dataset", required=True, choices=("faust", "defaust"))
    p.add_argument("--root", required=True)
    p.add_argument("--cases", default="", help="comma-separated case names (default: every case)")
    p.add_argument("--preset", default="cpu")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting over the preset's (JSON value), e.g. arap_weight=1000")
    p.add_argument("--steps", type=int, nargs="+", default=[500, 1000, 1500])
    p.add_argument("--every", type=int, default=100)
    a = p.parse_args(argv)
    settings = {k: json.loads(v) for k, v in (s.split("=", 1) for s in a.set)}
    want = set(filter(None, a.cases.split(",")))
    print(f"preset {a.preset}, settings {settings or 'the preset'}, seed 0, CPU")
    print("| case | handles | " + " | ".join(f"Handle (%) at {s}" for s in a.steps) + " | SDF (s) | deform (s) |")
    print("|---|---:|" + "---:|" * (len(a.steps) + 2))
    for case in load_cases(a.dataset, a.root):
        if want and case.name not in want:
            continue
        err, info = handle_errors(case, a.preset, settings, sorted(a.steps), a.every)
        cells = " | ".join(f"{err[s]:.2f}" for s in a.steps)
        print(f"| {case.name} | {len(case.handles)} | {cells} | {info['sdf_fit_s']:.0f} | {info['deform_s']:.0f} |",
              flush=True)


if __name__ == "__main__":
    main()

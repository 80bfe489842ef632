"""How much stiffer Implicit-ARAP's patch ARAP term is with the reference code's cotangent
weights than with the correct ones, at the same ARAP weight
(baselines/implicit_arap/patches.py; docs/methods.md, "Decisions on the reference code's
quirks").

Each trial draws a patch disk as the method does (``disk(k, sqrt(1e-3))``: the centre and
k - 1 points uniform by area, Delaunay-triangulated), lifts it onto a random smooth
height field, deforms it by a random smooth non-rigid map (an affine part plus quadratic
terms, displacements about 5 % of the radius) with the rotations set to the identity,
and evaluates the patch energy with both weightings. Prints, per disk size k, the median
and quartiles of the ratio E_reference / E_correct over the trials: the factor by which
``arap_weight`` must grow for the correct weights to be as rigid as the reference's.

    python benchmarks/implicit_arap_weights.py [--trials 2000] [--seed 0]

Needs PyTorch (extra [neural]).
"""
import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from baselines.implicit_arap.backend import torch  # noqa: E402
from baselines.implicit_arap.patches import disk, edge_structure, patch_energy  # noqa: E402


def ratios(k: int, trials: int, rng: np.random.Generator) -> np.ndarray:
    """E_reference / E_correct for ``trials`` random disks of ``k`` points."""
    r = math.sqrt(1e-3)
    out = []
    for _ in range(trials):
        pts, tris = disk(k, r, rng)
        h = (pts @ rng.normal(size=2)) * 0.1 + ((pts / r) ** 2 @ rng.normal(size=2)) * 0.05 * r
        X = np.c_[pts, h][None]
        A = np.eye(3) + 0.05 * rng.normal(size=(3, 3))
        Q = 0.05 * rng.normal(size=(3, 3)) / r
        TX = X @ A.T + (X ** 2) @ Q.T
        Xt, Tt = torch.as_tensor(X), torch.as_tensor(TX)
        eye = torch.eye(3, dtype=torch.float64).expand(1, k, 3, 3)
        e_ref = patch_energy(Xt, eye, Tt, tris, edge_structure(tris, True)).item()
        e_cor = patch_energy(Xt, eye, Tt, tris, edge_structure(tris)).item()
        out.append(e_ref / e_cor)
    return np.asarray(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=2000, help="random disks per size (default 2000)")
    ap.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    a = ap.parse_args()
    rng = np.random.default_rng(a.seed)
    print(f"seed {a.seed}, {a.trials} disks per size")
    print("| k (points per patch) | median ratio | quartiles |")
    print("|---:|---:|---|")
    for k in (16, 30):
        q = np.percentile(ratios(k, a.trials, rng), [25, 50, 75])
        print(f"| {k} | {q[1]:.1f} | {q[0]:.1f} - {q[2]:.1f} |")


if __name__ == "__main__":
    main()

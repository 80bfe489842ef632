"""SShaDe's transfer, average and low-res energy on deformation cases with a ground truth.

For every case (FAUST's 8 paper-protocol cases, or a DeFAUST build's cases), k samplings
(warm-started from sampling 0 as ``sshade.deform``) of one low-res energy and protocol are
solved once; each combination of ``transfer`` ("triangle", "vertex") and ``average``
("uniform", "proximity", "distortion") is rebuilt from the same low-res solutions, and the
result is scored as Table 1 scores it: ground-truth mean vertex error, volume, area and
edge-length errors (% ; eval.metrics.measures). Prints one line per case, then the means.

    python benchmarks/sshade_variants.py faust ../shared/data/faust_reg [--energy arap_sr] [--protocol paper]
    python benchmarks/sshade_variants.py defaust data/defaust --cases s00_p01 s01_p02 s02_p03 s03_p04

n_low: FAUST ``auto`` (sshade.pipeline.auto_n_low), DeFAUST 6000; k 5, seed 0.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from eval.datasets.defaust_dataset import load_defaust  # noqa: E402
from eval.datasets.faust import faust_cases  # noqa: E402
from eval.metrics.measures import area_error, edge_length_error, ground_truth_metrics, volume_error  # noqa: E402
from harness.command import run_command  # noqa: E402
from sshade.arap import ArapOptions, arap_deform  # noqa: E402
from sshade.averaging import (  # noqa: E402
    AVERAGES,  # noqa: E402,I001
    combine,
    sampling_weights,
)
from sshade.mesh.unit_frame import unit_frame  # noqa: E402
from sshade.mesh.validate import validate_mesh  # noqa: E402
from sshade.pipeline import auto_n_low, prepare_sampling  # noqa: E402
from sshade.remesh import mesh_topology  # noqa: E402
from sshade.sampling import sampling_seeds  # noqa: E402
from sshade.smooth_transfer import TRANSFERS, rebuild  # noqa: E402

METRICS = ("gt", "volume", "area", "edge_length")


def case_rows(c, n_low: int, k: int, energy: str, protocol: str) -> dict:
    """``{"transfer average": {metric: value}}`` for one case ``c`` (a DeformationCase)."""
    V, F, he = validate_mesh(c.V, c.F, return_halfedges=True)
    fr = unit_frame(V)
    U, T = fr.to_unit(V), fr.to_unit(c.targets)
    topo = mesh_topology(U, F, he)
    outs, first = [], None
    for s in sampling_seeds(0, k):
        prep, _ = prepare_sampling(U, F, c.handles, n_low, s, topo)
        VN, tri, FN, bary = U[prep["seeds"]], prep["tri"], prep["F"], prep["bary"]
        res = arap_deform(VN, FN, prep["low_handles"], T, ArapOptions(energy=energy, protocol=protocol),
                          U0=None if first is None else first[prep["seeds"]])
        X = {t: rebuild(U, tri, bary, VN, res.V, FN, transfer=t) for t in TRANSFERS}
        W = {a: sampling_weights(a, U, tri, bary, VN, res.V, FN) for a in AVERAGES}
        first = X["vertex"] if first is None else first
        outs.append((X, W))
    rows = {}
    for t in TRANSFERS:
        for a in AVERAGES:
            Vd = fr.from_unit(combine([o[0][t] for o in outs], [o[1][a] for o in outs]))
            Vd[c.handles] = c.targets
            rows[f"{t} {a}"] = {"gt": ground_truth_metrics(Vd, F, c.V_gt)["gt_vertex_mean_pct"],
                                "volume": volume_error(V, Vd, F), "area": area_error(V, Vd, F),
                                "edge_length": edge_length_error(V, Vd, F)}
    return rows


def main(dataset, root, cases, energy, protocol, k):
    found = faust_cases(root) if dataset == "faust" else load_defaust(root)
    found = [c for c in found if not cases or c.name in cases]
    means: dict = {}
    for c in found:
        n_low = auto_n_low(len(c.V)) if dataset == "faust" else 6000
        rows = case_rows(c, n_low, k, energy, protocol)
        for name, m in rows.items():
            means.setdefault(name, []).append(m)
        print(c.name, " ".join(f"{name}: {m['gt']:.3f}" for name, m in rows.items()), flush=True)
    print(f"\n{dataset}, {len(found)} cases, energy {energy}, protocol {protocol}, k {k}: means (%)")
    for name, ms in means.items():
        print(f"{name:22s} " + " ".join(f"{m} {np.mean([x[m] for x in ms]):.3f}" for m in METRICS))


if __name__ == "__main__":
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("dataset", choices=("faust", "defaust"))
    a.add_argument("root", help="FAUST registrations folder, or a DeFAUST build")
    a.add_argument("--cases", nargs="*", default=None, help="case names (default: all)")
    a.add_argument("--energy", default="spokes_and_rims")
    a.add_argument("--protocol", default="converged")
    a.add_argument("--k", type=int, default=5)
    args = a.parse_args()
    raise SystemExit(run_command(lambda: main(args.dataset, args.root, args.cases, args.energy, args.protocol,
                                              args.k)))

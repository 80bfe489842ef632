"""Frames of a smooth handle path with SShaDe prepared once (sshade.prepare), beside a
one-shot sshade.deform and libigl's arap_solve on the same mesh.

The meshes: ``--mesh NAME=PATH[:hard]`` (repeatable; default the scaling experiment's clean
armadillo and hard centaur), each built to every ``--sizes`` as the scaling experiment
builds them (``:hard``: LS3 Loop only, else LS3 Loop then isotropic remeshing:
eval.experiments.scaling.scaling_experiment.build_mesh), cached in ``--cache`` under the scaling experiment's
file names (eval.experiments.scaling.mesh_set.cache_name), so both share the built meshes. The
handles and the final targets: the scaling experiment's edit
(eval.datasets.shapes.axis_handles: two regions fixed, one turned 20 degrees, one moved
5 % of the diagonal), or with ``--regions 8`` eight regions (:func:`eight_regions`: four
fixed, four each turned 20 degrees about its own centre and moved 5 % of the diagonal).
Frame i of f moves the handles to ``rest + s(i / f) (final - rest)``, s the smoothstep.

    python benchmarks/frames.py [--mesh armadillo=../shared/data/classic/armadillo.obj ...]
        [--sizes 200000 1000000] [--frames 60] [--k 5] [--n-low 6000] [--workers W]
        [--regions 4|8] [--cache data/scaling] [--out DIR]

Per mesh and size it prints and tabulates: ``prepare`` seconds and the memory the prepared
object holds (PSS after prepare minus before, MB, the allocator trimmed before each
reading); the per-frame solve seconds of frames 2..f (the first also warms caches) as
median and range, and the low-res iterations per frame summed over the samplings (median);
whether every frame converged; the one-shot ``sshade.deform`` of the last frame's targets
(seconds, default workers) and the last frame's distance to it (mean, % of the diagonal);
libigl's ``arap_solve`` seconds per iteration (spokes and rims, one iteration per call, as
the paper protocol runs it; after its precomputation), and two ratios to it: the frame
median over one libigl iteration, and 1000 libigl iterations (the paper's protocol) over
the one-shot ``deform``. With ``--out`` also
DIR/table.md and DIR/frames.csv (every frame of every mesh), in a folder that is new, empty
or this benchmark's earlier output.
"""
import argparse
import contextlib
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from defaust.fixed_order import dot3, rotvec_to_matrix  # noqa: E402
from eval.datasets.shapes import axis_handles, axis_landmarks  # noqa: E402
from eval.experiments.scaling.mesh_set import MeshEntry  # noqa: E402
from eval.experiments.scaling.scaling_experiment import size_mesh  # noqa: E402
from eval.run.memory import release_freed, tree_pss_mb  # noqa: E402
from eval.run.outdir import claim_output_dir  # noqa: E402
from eval.run.runinfo import git_info  # noqa: E402
from harness.command import run_command  # noqa: E402
from sshade import deform, prepare  # noqa: E402
from sshade.cores import available_cores  # noqa: E402
from sshade.errors import SShaDeError  # noqa: E402
from sshade.mesh.io import read_mesh  # noqa: E402

DEFAULT_MESHES = ["armadillo=../shared/data/classic/armadillo.obj", "centaur=../shared/data/tosca/centaur0.off:hard"]
TARGETS = {200_000: 0.100, 1_000_000: 0.300}  # the frame targets (s) at about these sizes


def mesh_entry(spec: str) -> MeshEntry:
    """``NAME=PATH[:hard]`` as a scaling-set entry."""
    name, sep, path = spec.partition("=")
    if not sep or not name or not path:
        raise SShaDeError(f"--mesh wants NAME=PATH[:hard], got {spec!r}")
    hard = path.endswith(":hard")
    return MeshEntry(name, path[:-5] if hard else path, not hard)


def sized_mesh(entry: MeshEntry, size: int, cache: Path):
    """The entry's mesh at ``size`` (built and cached on first use) and its base mesh."""
    V0, F0 = read_mesh(entry.path)
    _, V, F, _ = size_mesh(entry, V0, F0, size, cache)
    return V, F, V0


def eight_regions(V: np.ndarray, V0: np.ndarray, *, n_per_group: int = 30, region_radius: float = 0.06,
                  rotate_deg: float = 20.0, translate: float = 0.05, seed: int = 0):
    """Eight handle regions and their targets on ``V`` (the edit of ``--regions 8``).

    The landmarks: the base mesh ``V0``'s vertices of smallest and largest coordinate along
    its principal axes a1 and a2 (:func:`eval.datasets.shapes.axis_landmarks`), then along
    a3 and (a1 + a2) / sqrt 2. The regions around them are picked as the scaling edit picks
    its four (:func:`eval.datasets.shapes.axis_handles`: up to ``n_per_group`` vertices of
    ``V`` within ``region_radius`` x its diagonal, seeded per region, none in an earlier
    region). The regions at even places stay; each at an odd place turns ``rotate_deg``
    about the principal axis of its place (a1, a2, a3, a1 again) around its own centroid
    and moves ``translate`` x the diagonal along a3 (alternating sign).

    V : (n, 3) float64, V0 : (n0, 3) float64. Returns ``handles`` (h,) int64 and
    ``targets`` (h, 3) float64. Raises SShaDeError if a region holds no free vertex.
    """
    lm, center, axes = axis_landmarks(V0)
    a1, a2, a3 = axes
    marks = [*lm]
    for d in (a3, (a1 + a2) / np.sqrt(2.0)):
        p = dot3(V0 - center, d)
        marks += [V0[p.argmin()], V0[p.argmax()]]
    h, _, _, group = axis_handles(V, np.stack(marks), center, axes, n_per_group=n_per_group,
                                  region_radius=region_radius, seed=seed)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    T = V[h]
    for g in range(1, 8, 2):
        P = T[group == g]
        R = rotvec_to_matrix(np.deg2rad(rotate_deg) * np.asarray(axes[(g // 2) % 3]))
        c = P.mean(0)
        sign = 1.0 if (g // 2) % 2 == 0 else -1.0
        T[group == g] = (P - c) @ R.T + c + sign * translate * diag * a3
    return h, T


def igl_iteration_s(V, F, h, T, n: int = 3, energy: str = "spokes_and_rims") -> float:
    """Seconds per ``igl.arap_solve`` iteration with ``energy`` (``"spokes"`` or
    ``"spokes_and_rims"``): ``max_iter`` 1, ``n`` calls from the rest pose."""
    import igl
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES if energy == "spokes" else igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
    data.max_iter = 1
    igl.arap_precomputation(V, F, 3, h.astype(np.int32), data)
    U = V.copy()
    t0 = time.perf_counter()
    for _ in range(n):
        U = igl.arap_solve(T, data, U)
    return (time.perf_counter() - t0) / n


def _frames(a, p, h, rest, T_end, rows: list, label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """Solve the f frames; appends one dict per frame to ``rows``; returns (seconds,
    iterations, last frame, all converged)."""
    secs, its, ok = [], [], True
    for i in range(1, a.frames + 1):
        s = i / a.frames
        s = s * s * (3 - 2 * s)
        Vd, info = p.solve(rest + s * (T_end - rest), return_info=True)
        secs.append(info["total_s"])
        its.append(info["iterations"])
        ok &= bool(info["converged"])
        rows.append({"mesh": label, "frame": i, "solve_s": info["total_s"], "iterations": info["iterations"],
                     "arap_s": info["arap_s"], "transfer_s": info["transfer_s"], "status": info["status"]})
        print(f"{label} frame {i:3d}  {info['total_s']:.3f} s  {info['iterations']:5d} it  "
              f"arap {info['arap_s']:.3f} s  transfer {info['transfer_s']:.3f} s  {info['status']}", flush=True)
    return np.array(secs), np.array(its), Vd, ok


def _one(a, entry: MeshEntry, size: int, frames: list) -> dict:
    """The row of one mesh at one size (module docstring)."""
    V, F, V0 = sized_mesh(entry, size, Path(a.cache))
    if a.regions == 8:
        h, T_end = eight_regions(V, V0, seed=a.seed)
    else:
        lm, center, axes = axis_landmarks(V0)
        h, T_end, _, _ = axis_handles(V, lm, center, axes)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    label = f"{entry.name} {len(V)}"
    print(f"{entry.name} ({entry.kind}) -> {len(V)} vertices, {len(F)} faces; {len(h)} handles in {a.regions} "
          f"regions; k={a.k}, n_low={a.n_low}", flush=True)
    release_freed()
    mem0 = tree_pss_mb()
    t0 = time.perf_counter()
    with prepare(V, F, h, n_low=a.n_low, n_samplings=a.k, seed=a.seed, workers=a.workers) as p:
        prepare_s = time.perf_counter() - t0
        release_freed()
        held = tree_pss_mb() - mem0
        print(f"prepare {prepare_s:.3f} s on {p.workers} threads; the prepared object holds {held:.0f} MB")
        secs, its, Vd, ok = _frames(a, p, h, V[h], T_end, frames, label)
        workers = p.workers
    rest = secs[1:] if len(secs) > 1 else secs  # the first frame also warms the kernels' caches
    t0 = time.perf_counter()
    one = deform(V, F, h, T_end, n_low=a.n_low, n_samplings=a.k, seed=a.seed)
    deform_s = time.perf_counter() - t0
    igl_s = igl_iteration_s(V, F, h, T_end)
    row = {"mesh": entry.name, "kind": entry.kind, "vertices": len(V), "regions": a.regions, "k": a.k,
           "n_low": a.n_low, "workers": workers, "prepare_s": prepare_s, "prepared_mb": held,
           "frame_median_s": float(np.median(rest)),
           "frame_min_s": float(rest.min()), "frame_max_s": float(rest.max()),
           "iterations_median": float(np.median(its[1:] if len(its) > 1 else its)), "all_converged": ok,
           "deform_s": deform_s, "last_vs_deform_pct": float(100 * np.linalg.norm(Vd - one, axis=1).mean() / diag),
           "igl_iteration_s": igl_s}
    print(f"frames 2..{a.frames}: {row['frame_median_s']:.3f} s median ({row['frame_min_s']:.3f}-"
          f"{row['frame_max_s']:.3f}), {row['iterations_median']:.0f} iterations median; one-shot deform "
          f"{deform_s:.3f} s, last frame vs it {row['last_vs_deform_pct']:.4f} % of the diagonal (mean); "
          f"libigl arap_solve {igl_s:.3f} s per iteration", flush=True)
    return row


def _target(n: int) -> str:
    """The frame target (ms) of the target size within a factor 1.5 of ``n``, else "-"."""
    near = [s for s in TARGETS if abs(np.log(n / s)) < np.log(1.5)]
    return f"{1e3 * TARGETS[near[0]]:.0f}" if near else "-"


def _table(rows: list) -> str:
    out = ["| Mesh | Vertices | Regions | k | n_low | Threads | Prepare (s) | One-shot deform (s) | Prepare / deform | "
           "Prepared (MB) | Frame median (ms) | Frame range (ms) | Target (ms) | Iterations per frame (median) | "
           "All converged | Last frame vs deform (% diag, mean) | libigl s / iteration | Frame / libigl iteration | "
           "1000 libigl iterations / one-shot deform |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['mesh']} ({r['kind']}) | {r['vertices']} | {r['regions']} | {r['k']} | {r['n_low']} | "
                   f"{r['workers']} | "
                   f"{r['prepare_s']:.2f} | {r['deform_s']:.2f} | {r['prepare_s'] / r['deform_s']:.2f} | "
                   f"{r['prepared_mb']:.0f} | {1e3 * r['frame_median_s']:.0f} | {1e3 * r['frame_min_s']:.0f}-"
                   f"{1e3 * r['frame_max_s']:.0f} | {_target(r['vertices'])} | {r['iterations_median']:.0f} | "
                   f"{'yes' if r['all_converged'] else 'no'} | {r['last_vs_deform_pct']:.4f} | "
                   f"{r['igl_iteration_s']:.3f} | {r['frame_median_s'] / r['igl_iteration_s']:.2f} | "
                   f"{1000 * r['igl_iteration_s'] / r['deform_s']:.0f} |")
    return "\n".join(out) + "\n"


def main(a) -> int:
    entries = [mesh_entry(s) for s in (a.mesh or DEFAULT_MESHES)]
    for e in entries:
        if not Path(e.path).is_file():
            raise SShaDeError(f"mesh {e.name!r}: {e.path} not found")
    claim = claim_output_dir(a.out, "frames", option="", name="--out") if a.out else None
    with claim or contextlib.nullcontext():
        rows, frames = [], []
        for e in entries:
            for size in a.sizes:
                rows.append(_one(a, e, size, frames))
        table = _table(rows)
        print("\n" + table)
        if claim is not None:
            _write(claim.path, a, table, rows, frames)
    return 0


def _write(out: Path, a, table: str, rows: list, frames: list) -> None:
    """table.md, table.csv and frames.csv into ``out``."""
    import pandas as pd
    pd.DataFrame(frames).to_csv(out / "frames.csv", index=False, float_format="%.6g")
    pd.DataFrame(rows).to_csv(out / "table.csv", index=False, float_format="%.6g")
    gi = git_info()
    (out / "table.md").write_text(
        f"### SShaDe prepared once, solved per frame ({a.frames}-frame smooth handle path)\n\n{table}\n"
        f"Made by `python benchmarks/frames.py {' '.join('--mesh ' + m for m in (a.mesh or DEFAULT_MESHES))} "
        f"--sizes {' '.join(map(str, a.sizes))} --frames {a.frames} --k {a.k} --n-low {a.n_low} "
        f"--regions {a.regions}` at git commit "
        f"{gi.get('commit')} (dirty: {gi.get('dirty')}), seed {a.seed}, on {available_cores()} cores. The "
        f"columns: the benchmark's docstring; every frame's time and iterations in frames.csv.\n")

if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", action="append", help="NAME=PATH[:hard] (repeatable; default: armadillo, centaur)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[200_000, 1_000_000])
    ap.add_argument("--cache", default="data/scaling", help="where built meshes are kept (the scaling experiment's)")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--k", type=int, default=5)
    ap.add_argument("--n-low", type=int, default=6000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--regions", type=int, choices=(4, 8), default=4,
                    help="handle regions of the edit: the scaling experiment's 4, or eight_regions' 8")
    ap.add_argument("--workers", type=int, default=None, help="threads of the prepared samplings (default: the cores)")
    ap.add_argument("--out", help="also write table.md, table.csv and frames.csv into this folder")
    args = ap.parse_args()
    raise SystemExit(run_command(lambda: main(args), where=args.out))

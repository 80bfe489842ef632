"""Frames of a smooth handle path with SShaDe prepared once (sshade.prepare), beside a
one-shot sshade.deform and libigl's arap_solve on the same mesh.

The mesh: ``--mesh`` as it is, or built to about ``--size`` vertices as the scaling
experiment builds its meshes (LS3 Loop, then isotropic remeshing unless ``--no-remesh``:
eval.experiments.scaling.build_mesh), cached in ``--cache``. The handles and the final
targets: the scaling experiment's edit (eval.datasets.shapes.axis_handles: two regions
fixed, one turned 20 degrees, one moved 5 % of the diagonal). Frame i of f moves the
handles to ``rest + s(i / f) (final - rest)``, s the smoothstep.

    python benchmarks/frames.py --mesh ../shared/data/classic/armadillo.obj --size 200000 [--frames 60]
        [--k 5] [--n-low 6000] [--workers W] [--no-remesh] [--cache data/scaling]

Prints the prepare time; per frame the solve time and low-res iterations (summed over the
samplings), then their median and range; the one-shot deform of the last frame (default
workers) and its distance to the last frame; libigl's arap_solve seconds per iteration
(spokes and rims, one iteration per call, as the paper protocol runs it).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from eval.datasets.shapes import axis_handles, axis_landmarks  # noqa: E402
from eval.experiments.scaling import build_mesh  # noqa: E402
from sshade import deform, prepare  # noqa: E402
from sshade.clirun import run_command  # noqa: E402
from sshade.mesh.io import read_mesh, write_mesh  # noqa: E402


def _mesh(path, size, remesh, cache):
    V0, F0 = read_mesh(path)
    if not size:
        return V0, F0, V0
    mp = Path(cache) / f"{Path(path).stem}_{'remesh' if remesh else 'ls3'}_{size}.ply"
    if mp.is_file():
        V, F = read_mesh(mp)
    else:
        V, F = build_mesh(V0, F0, size, remesh=remesh)
        mp.parent.mkdir(parents=True, exist_ok=True)
        write_mesh(mp, V, F)
    return V, F, V0


def _igl_iteration_s(V, F, h, T, n: int = 3) -> float:
    import igl
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
    data.max_iter = 1
    igl.arap_precomputation(V, F, 3, h.astype(np.int32), data)
    U = V.copy()
    t0 = time.perf_counter()
    for _ in range(n):
        U = igl.arap_solve(T, data, U)
    return (time.perf_counter() - t0) / n


def main(a) -> int:
    V, F, V0 = _mesh(a.mesh, a.size, not a.no_remesh, a.cache)
    lm, center, axes = axis_landmarks(V0)
    h, T_end, _, _ = axis_handles(V, lm, center, axes)
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    print(f"mesh {a.mesh} -> {len(V)} vertices, {len(F)} faces; {len(h)} handles; k={a.k}, n_low={a.n_low}")
    t0 = time.perf_counter()
    p = prepare(V, F, h, n_low=a.n_low, n_samplings=a.k, seed=a.seed, workers=a.workers)
    print(f"prepare {time.perf_counter() - t0:.3f} s on {p.workers} threads")
    rest = V[h]
    secs, its = [], []
    for i in range(1, a.frames + 1):
        s = i / a.frames
        s = s * s * (3 - 2 * s)
        Vd, info = p.solve(rest + s * (T_end - rest), return_info=True)
        secs.append(info["total_s"])
        its.append(info["iterations"])
        print(f"frame {i:3d}  {info['total_s']:.3f} s  {info['iterations']:5d} it  arap {info['arap_s']:.3f} s  "
              f"transfer {info['transfer_s']:.3f} s  {'converged' if info['converged'] else info['status']}")
    secs = np.array(secs[1:] if len(secs) > 1 else secs)  # the first frame also warms the kernels' caches
    print(f"frames 2..{a.frames}: {np.median(secs):.3f} s median ({secs.min():.3f}-{secs.max():.3f}), "
          f"{int(np.median(its))} iterations median")
    t0 = time.perf_counter()
    one = deform(V, F, h, T_end, n_low=a.n_low, n_samplings=a.k, seed=a.seed)
    print(f"one-shot deform of the last frame {time.perf_counter() - t0:.3f} s; last frame vs it: "
          f"{100 * np.linalg.norm(Vd - one, axis=1).mean() / diag:.4f} % of the diagonal (mean)")
    print(f"libigl arap_solve (spokes and rims) {_igl_iteration_s(V, F, h, T_end):.3f} s per iteration")
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", required=True, help="base mesh")
    ap.add_argument("--size", type=int, default=0, help="build to about this many vertices (0: the mesh as is)")
    ap.add_argument("--no-remesh", action="store_true", help="LS3 Loop only (the scaling set's hard meshes)")
    ap.add_argument("--cache", default="data/scaling", help="where built meshes are kept")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--k", type=int, default=5)
    ap.add_argument("--n-low", type=int, default=6000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=None, help="threads of the prepared samplings (default: the cores)")
    args = ap.parse_args()
    raise SystemExit(run_command(lambda: main(args)))

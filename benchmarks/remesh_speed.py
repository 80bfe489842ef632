"""Speed of one SShaDe sampling's remesh + projection and of the once-per-call
validation/topology pass, on a ~200k-vertex mesh.

    python benchmarks/remesh_speed.py [--cache data/benchmarks/armadillo_200k.npz]
                                      [--mesh path.ply] [--n-low 6000] [--seeds 3] [--repeat 3]
                                      [--ref GIT_REF]

``--ref HEAD`` (any commit) benchmarks the ``sshade`` package of that commit instead of
the working tree (extracted with ``git archive`` into a temporary folder), for a
before/after comparison in the same conditions; the first repeat then includes numba
compilation, so use ``--repeat`` >= 2.

The 200k mesh is built once from ``../shared/data/classic/armadillo.obj`` with
:func:`defaust.highres.subdivide_remesh` (LS3 Loop + isotropic remesh, vertex range
190k-210k; a minute or two) and cached as an ``.npz`` (``--cache``; ``data/`` is
git-ignored). Handles: the scaling benchmark's fixed edit (4 groups of 30 vertices,
:func:`eval.datasets.shapes.axis_handles`), which ``sshade.pipeline.prepare_sampling`` adds as
required low-res vertices. For each of ``--seeds`` sampling seeds (the first ones
:func:`sshade.sampling.sampling_seeds` gives for master seed 0) the script runs
``remesh`` + ``project_to_fans`` exactly as ``prepare_sampling`` does, ``--repeat`` times, and
prints the best time of each stage (single thread; stages from ``RemeshResult.timings``)
and digests of the seeds, low-res faces and projection triangles (to compare versions).
Timings are wall-clock, with the process CPU time of the totals next to them (less
sensitive to other jobs on the machine): run on a quiet machine.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def load_mesh(cache: Path, mesh: str | None):
    """(V, F) from ``mesh`` if given, else the cached 200k armadillo (built if missing)."""
    if mesh:
        from sshade.mesh.io import read_mesh
        return read_mesh(mesh)
    if cache.is_file():
        d = np.load(cache)
        return np.ascontiguousarray(d["V"], np.float64), np.ascontiguousarray(d["F"], np.int64)
    from defaust.highres import subdivide_remesh
    from sshade.mesh.io import read_mesh
    base = ROOT.parent / "shared" / "data" / "classic" / "armadillo.obj"
    if not base.is_file():
        base = Path("/work/shared/data/classic/armadillo.obj")
    print(f"building the 200k mesh from {base} (cached as {cache}) ...", flush=True)
    V0, F0 = read_mesh(base)
    r = subdivide_remesh(V0, F0, vertex_range=(190_000, 210_000))
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, V=r.V, F=r.F)
    return r.V, r.F


def handles_for(V):
    from eval.datasets.shapes import axis_handles, axis_landmarks
    lm, center, axes = axis_landmarks(V)
    h, _, _, _ = axis_handles(V, lm, center, axes)
    return h


def digest(*arrays) -> str:
    h = hashlib.sha1()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:12]


def best(fn, repeat):
    ts, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return min(ts), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cache", default=str(ROOT / "data" / "benchmarks" / "armadillo_200k.npz"))
    ap.add_argument("--mesh", default=None, help="use this mesh file instead (e.g. a FAUST .ply)")
    ap.add_argument("--n-low", type=int, default=None, help="default: sshade.pipeline.auto_n_low(n)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--ref", default=None, help="benchmark the sshade package of this git commit")
    a = ap.parse_args(argv)
    if a.ref:
        tmp = tempfile.mkdtemp(prefix="sshade_ref_")
        subprocess.run(f"git -C '{ROOT}' archive '{a.ref}' sshade | tar -x -C '{tmp}'", shell=True, check=True)
        sys.path.insert(0, tmp)

    from sshade.mesh.validate import validate_mesh
    from sshade.pipeline import auto_n_low
    from sshade.projection import project_to_fans
    from sshade.remesh import mesh_topology, remesh
    from sshade.sampling import sampling_seeds, warm_kernels

    V, F = load_mesh(Path(a.cache), a.mesh)
    n_low = a.n_low or auto_n_low(len(V))
    h = handles_for(V)
    import sshade
    print(f"sshade from {Path(sshade.__file__).parent}" + (f" (git {a.ref})" if a.ref else ""))
    print(f"mesh: {len(V)} vertices, {len(F)} faces; n_low {n_low}; {len(h)} handles; "
          f"repeat {a.repeat} (best); pid {os.getpid()}")
    warm_kernels()

    def setup():
        c0, t0 = time.process_time(), time.perf_counter()
        V2, F2, he = validate_mesh(V, F, return_halfedges=True)
        t1 = time.perf_counter()
        topo = mesh_topology(V2, F2, he)
        t2, c2 = time.perf_counter(), time.process_time()
        return V2, F2, topo, {"validate": t1 - t0, "topology": t2 - t1, "total": t2 - t0, "cpu": c2 - c0}

    # validation + topology (once per deform call)
    runs = [setup() for _ in range(a.repeat)]
    V, F, topo = runs[0][:3]
    vt = {k: min(r[3][k] for r in runs) for k in runs[0][3]}
    print(f"validate_mesh {vt['validate']:.3f} s + mesh_topology {vt['topology']:.3f} s "
          f"(best of {a.repeat}; CPU {vt['cpu']:.3f} s)")

    stages = ("fps_s", "required_s", "check_s", "add_s")
    tot = []
    for s in sampling_seeds(0, a.seeds):
        runs = []
        for _ in range(a.repeat):
            c0, t0 = time.process_time(), time.perf_counter()
            rm = remesh(V, F, n_low, seed=s, required=h, topology=topo)
            t1 = time.perf_counter()
            P = project_to_fans(V, rm.label, V[rm.seeds], rm.F)
            t2, c2 = time.perf_counter(), time.process_time()
            runs.append(dict(total=t2 - t0, remesh=t1 - t0, projection=t2 - t1, cpu=c2 - c0,
                             **{k[:-2]: rm.timings.get(k, np.nan) for k in stages + ("sampling_s", "repair_s")}))
        b = {k: min(r[k] for r in runs) for k in runs[0]}
        tot.append(b["total"])
        print(f"seed {s:>10}: total {b['total']:.3f} s (CPU {b['cpu']:.3f}) = remesh {b['remesh']:.3f} "
              f"[sampling {b['sampling']:.3f} = fps {b['fps']:.3f} + handles {b['required']:.3f}; repair "
              f"{b['repair']:.3f} = checks {b['check']:.3f} + repair seeds {b['add']:.3f}] "
              f"+ projection {b['projection']:.3f}")
        print(f"{'':>17} {len(rm.seeds)} low-res vertices ({rm.n_repair} repair), {len(rm.F)} faces, "
              f"{rm.iterations} check rounds; digest seeds+F {digest(rm.seeds, rm.F)}, tri {digest(P.tri)}")
    print(f"mean over seeds of the best totals: {np.mean(tot):.3f} s (target: 0.4 s at 200k); "
          "per stage: best of the repeats")


if __name__ == "__main__":
    main()

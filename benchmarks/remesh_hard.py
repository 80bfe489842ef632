"""Check-and-repair rounds of the remesher on hard meshes: LS3 Loop
subdivisions of TOSCA models (thin fingers and tails, stretched triangles) against the
clean 200k armadillo of ``benchmarks/remesh_speed.py``.

    python benchmarks/remesh_hard.py [--meshes centaur0:2 wolf0:3 armadillo]
                                     [--n-low 6000] [--seeds 4] [--repeat 2]
                                     [--ref GIT_REF ...]

A mesh is ``model:k`` (``k`` LS3 Loop iterations of ``<shared data>/tosca/model.off``
with ``threshold=PercentageValue(0)``: without it pymeshlab skips the short edges) or
``armadillo`` (the isotropic 200k armadillo of ``remesh_speed.py``). Meshes are built
once and cached as ``.npz`` under ``--cache-dir`` (``data/`` is git-ignored).

For every mesh and sampling seed the script runs :func:`sshade.remesh.remesh` exactly as
``sshade.pipeline.prepare_sampling`` does (the scaling edit's handles as required vertices) and
prints the check-and-repair rounds, the repair seeds and the best remesh time of
``--repeat`` runs. Rounds and repair seeds do not depend on the machine's load; times do.

With ``--ref`` (repeatable; ``.`` is the working tree) every version runs in its own
child process, the versions interleaved mesh by mesh and repeat by repeat, so that a
before/after comparison sees the same load; the summary gives the after/before time
ratio of each mesh. A ref other than ``.`` benchmarks the ``sshade`` package of that
commit (``git archive`` into a temporary folder).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("SSHADE_SHARED_DATA", ROOT.parent / "shared" / "data"))


def build_mesh(name: str, cache_dir: Path):
    """(V, F) of ``model:k`` or ``armadillo`` (see the module docstring), cached."""
    path = cache_dir / f"{name.replace(':', '_ls3x')}.npz"
    if path.is_file():
        d = np.load(path)
        return np.ascontiguousarray(d["V"], np.float64), np.ascontiguousarray(d["F"], np.int64)
    sys.path.insert(0, str(ROOT))
    from sshade.mesh.io import read_mesh
    if name == "armadillo":
        from defaust.highres import subdivide_remesh
        V0, F0 = read_mesh(SHARED / "classic" / "armadillo.obj")
        r = subdivide_remesh(V0, F0, vertex_range=(190_000, 210_000))
        V, F = r.V, r.F
    else:
        from defaust.highres import ls3_loop
        model, k = name.split(":")
        V, F = read_mesh(SHARED / "tosca" / f"{model}.off")
        V, F = ls3_loop(V, F, int(k))
    cache_dir.mkdir(parents=True, exist_ok=True)
    np.savez(path, V=V, F=F)
    return np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int64)


def child(a) -> None:
    """Run one version on one mesh (``sys.path`` already set); print one JSON line."""
    from benchmarks.remesh_speed import digest, handles_for
    from sshade.mesh.validate import validate_mesh
    from sshade.remesh import mesh_topology, remesh
    from sshade.sampling import sampling_seeds, warm_kernels

    V, F = build_mesh(a.meshes[0], Path(a.cache_dir))
    h = handles_for(V)
    V, F, he = validate_mesh(V, F, return_halfedges=True)
    topo = mesh_topology(V, F, he)
    warm_kernels()
    remesh(V, F, 200, seed=0, topology=topo)  # compile outside the timings
    out = []
    for s in sampling_seeds(0, a.seeds):
        ts = []
        for _ in range(a.repeat):
            t = time.perf_counter()
            rm = remesh(V, F, a.n_low, seed=s, required=h, topology=topo)
            ts.append(time.perf_counter() - t)
        assert np.isin(h, rm.seeds).all() and rm.n_flipped >= 0
        out.append(dict(seed=int(s), rounds=rm.iterations, repair=rm.n_repair, k=len(rm.seeds),
                        flipped=rm.n_flipped, s=min(ts), check=rm.timings["check_s"], add=rm.timings["add_s"],
                        digest=digest(rm.seeds, rm.F)))
    import sshade
    print("RESULT " + json.dumps(dict(n=len(V), runs=out, package=str(Path(sshade.__file__).parent))))


def package_path(ref: str) -> str:
    if ref == ".":
        return str(ROOT)
    tmp = tempfile.mkdtemp(prefix="sshade_ref_")
    subprocess.run(f"git -C '{ROOT}' archive '{ref}' sshade | tar -x -C '{tmp}'", shell=True, check=True)
    return tmp


def run_child(pkg: str, mesh: str, a) -> dict:
    code = (f"import sys; sys.path[:0] = [{pkg!r}, {str(ROOT)!r}]; "
            "import sshade; from benchmarks.remesh_hard import main; main()")
    cmd = [sys.executable, "-c", code, "--child", "--meshes", mesh, "--n-low", str(a.n_low),
           "--seeds", str(a.seeds), "--repeat", "1", "--cache-dir", a.cache_dir]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    line = [x for x in r.stdout.splitlines() if x.startswith("RESULT ")]
    if r.returncode or not line:
        raise RuntimeError(f"child failed ({mesh}, {pkg}):\n{r.stdout}\n{r.stderr}")
    return json.loads(line[0][7:])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["centaur0:2", "wolf0:3", "armadillo"])
    ap.add_argument("--n-low", type=int, default=6000)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--ref", action="append", default=None)
    ap.add_argument("--cache-dir", default=str(ROOT / "data" / "benchmarks"))
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        return child(a)
    refs = a.ref or ["."]
    pkgs = {r: package_path(r) for r in refs}
    for m in a.meshes:
        build_mesh(m, Path(a.cache_dir))
    res = {(m, r): [] for m in a.meshes for r in refs}
    for m in a.meshes:
        for _ in range(a.repeat):  # interleaved: ref A, ref B, ref A, ref B ...
            for r in refs:
                res[m, r].append(run_child(pkgs[r], m, a))
        for r in refs:
            runs = res[m, r]
            print(f"{m} ({runs[0]['n']} vertices, n_low {a.n_low}) version {r} ({runs[0]['package']}):")
            for i, x in enumerate(runs[0]["runs"]):
                t = min(rr["runs"][i]["s"] for rr in runs)
                print(f"  seed {x['seed']:>10}: {x['rounds']:>3} rounds, {x['repair']:>4} repair seeds, "
                      f"{x['k']} low-res vertices, {x['flipped']} flipped, remesh {t:.3f} s (best of {len(runs)}), "
                      f"check {min(rr['runs'][i]['check'] for rr in runs):.3f} s, seeds+faces {x.get('digest', '-')}")
        if len(refs) > 1:
            tb = [np.mean([min(rr["runs"][i]["s"] for rr in res[m, r]) for i in range(a.seeds)]) for r in refs]
            print("  mean remesh time per version: " + ", ".join(f"{r} {t:.3f} s" for r, t in zip(refs, tb))
                  + f"; ratio {refs[-1]}/{refs[0]} = {tb[-1] / tb[0]:.2f}")


if __name__ == "__main__":
    main()

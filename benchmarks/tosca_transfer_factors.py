"""Where SShaDe's transfer loses accuracy on TOSCA (paper §4.2): each factor alone.

The §4.2 experiment (rest pose remeshed, low-res vertices read off the true pose, the
full mesh rebuilt through the frames, averaged over k samplings), with one factor changed
at a time from BASE (Alg. 1's frame per triangle, anchor=projection, gradient=normalized,
frame fallback below |grad x| = 0.5, projection onto the seed's own fan, n_low=6000, k=10,
the uniform mean):

- anchor: barycenter (Alg. 1) instead of the vertex's projection (docs/differences.md M8);
- gradient: raw (paper eq. (2)) instead of normalised frames (M1);
- fallback: |grad x| < 0.1 instead of 0.5 (M6);
- projection: onto the nearest low-res triangle anywhere (libigl) instead of the own fan;
- n_low 3000 / 9000; k 1 / 5 / 20; a per-vertex median over the samplings instead of the mean;
- average: weighted by proximity or distortion (sshade/averaging.py) instead of uniform;
- transfer: the corners' deformation gradients blended (sshade/smooth_transfer.py), or a
  gradient-domain (Poisson) reconstruction from them (``_poisson``, this benchmark only).

Beside d_H and d_C (shapes in the true pose's unit sphere, eval.metrics.measures) and the vertex
mean / max (% of the true pose's diagonal), two columns locate the error on the data:
``stretched``, the share of the vertices whose 1-ring edges change length by more than
25 % from the rest pose to the TOSCA pose (the ground truth is not isometric there), and
``d_C share``: the part of the one-way (result -> truth) Chamfer sum that those vertices
carry. ``iso max``: the vertex max over the other vertices.

    python benchmarks/tosca_transfer_factors.py ../shared/data/tosca [--classes cat centaur] [--out DIR]

Prints one line per case and variant, then a Markdown table of the means over the cases;
with ``--out`` also writes them to DIR/cases.csv and DIR/table.md (a folder that is new,
empty or this benchmark's earlier output; ``results/tosca_factors`` under
``python -m eval.reproduce``).
"""
import argparse
import contextlib
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from eval.experiments.tosca import discover_tosca  # noqa: E402
from eval.metrics.measures import chamfer, hausdorff, normalize_unit_sphere, point_surface_distance  # noqa: E402
from eval.run.outdir import claim_output_dir  # noqa: E402
from eval.run.runinfo import git_info  # noqa: E402
from harness.command import run_command  # noqa: E402
from sshade.averaging import distortion_weights, normalize_weights, proximity_weights, weighted_sum  # noqa: E402
from sshade.lrf import frame_functions, transfer  # noqa: E402
from sshade.mesh.io import read_mesh  # noqa: E402
from sshade.mesh.validate import validate_mesh  # noqa: E402
from sshade.projection import project_to_fans  # noqa: E402
from sshade.remesh import mesh_topology, remesh  # noqa: E402
from sshade.sampling import sampling_seeds  # noqa: E402
from sshade.smooth_transfer import smooth_decode, vertex_jacobians  # noqa: E402

#: The settings every row starts from: Alg. 1's transfer (one frame per triangle) with the
#: projection anchor, normalised frames, the fallback below |grad x| = 0.5, the seed's own
#: fan, n_low 6000, k 10, the uniform mean (paper §3.3).
BASE = {"n_low": 6000, "k": 10, "anchor": "projection", "gradient": "normalized", "min_gradient": 0.5,
        "projection": "fan", "transfer": "triangle", "average": "uniform"}
#: row name -> the settings it changes from BASE
VARIANTS = {
    "triangle frames, uniform mean": {},
    "anchor=barycenter": {"anchor": "barycenter"},
    "gradient=raw": {"gradient": "raw"},
    "fallback=0.1": {"min_gradient": 0.1},
    "projection=nearest": {"projection": "nearest"},
    "n_low=3000": {"n_low": 3000},
    "n_low=9000": {"n_low": 9000},
    "k=1": {"k": 1},
    "k=5": {"k": 5},
    "k=20": {"k": 20},
    "average=median": {"average": "median"},
    "average=distortion": {"average": "distortion"},
    "average=proximity": {"average": "proximity"},
    "transfer=vertex": {"transfer": "vertex"},
    "transfer=vertex, average=proximity": {"transfer": "vertex", "average": "proximity"},
    "transfer=poisson": {"transfer": "poisson"},
    "paper (barycenter, raw)": {"anchor": "barycenter", "gradient": "raw"},
}
STRETCH = 25.0  # % edge length change from which a vertex counts as stretched


def _nearest(V, VN, FN):
    """Triangle and barycentric coordinates of each vertex's closest point on (VN, FN), any triangle."""
    import igl
    _, tri, C = igl.point_mesh_squared_distance(V, VN, FN)
    A, B, Cc = (VN[FN[tri, i]] for i in range(3))
    return tri.astype(np.int64), np.asarray(igl.barycentric_coordinates(C, A, B, Cc), np.float64)


def _stretched(V0, V1, F) -> np.ndarray:
    """(n,) bool: a vertex with an incident edge whose length changes by more than STRETCH %."""
    E = np.unique(np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=1), axis=0)
    length = [np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) for X in (V0, V1)]
    s = np.abs(length[1] / length[0] - 1)
    out = np.zeros(len(V0), bool)
    bad = E[s * 100 > STRETCH]
    out[bad.ravel()] = True
    return out


def _samplings(V, F, T, topo, n_low, k):
    """k samplings: (remesh, own-fan projection, low-res rest and true positions)."""
    out = []
    for s in sampling_seeds(0, k):
        rm = remesh(V, F, n_low, seed=s, topology=topo)
        VN = V[rm.seeds]
        out.append((rm, project_to_fans(V, rm.label, VN, rm.F), VN, T[rm.seeds]))
    return out


def _result(V, F, samp, opt):
    """The k samplings of ``samp`` rebuilt and averaged under the settings ``opt`` (BASE's keys)."""
    outs, weights, jacs = [], [], []
    for rm, pr, VN, TN in samp:
        tri, bary = (pr.tri, pr.bary) if opt["projection"] == "fan" else _nearest(V, VN, rm.F)
        bary = bary if opt["anchor"] == "projection" else None
        if opt["transfer"] == "triangle":
            axis = frame_functions(VN, rm.F, min_gradient=opt["min_gradient"])
            outs.append(transfer(V, tri, VN, TN, rm.F, gradient=opt["gradient"], axis=axis, bary=bary))
        else:
            Jv = vertex_jacobians(VN, TN, rm.F)
            outs.append(smooth_decode(V, tri, bary, VN, TN, rm.F, Jv=Jv))
            jacs.append(np.einsum("ni,nijk->njk", bary, Jv[rm.F[tri]]))
        weights.append(proximity_weights(V, tri, bary, VN, rm.F) if opt["average"] == "proximity" else
                       distortion_weights(tri, VN, TN, rm.F) if opt["average"] == "distortion" else
                       np.ones(len(V)))
    if opt["average"] == "median":
        return np.median(outs, axis=0)
    X = weighted_sum(outs, normalize_weights(weights))
    return _poisson(V, F, X, np.mean(jacs, axis=0)) if opt["transfer"] == "poisson" else X


def _poisson(V, F, Y, J, w=1e5):
    """Gradient-domain reconstruction (deformation transfer, Sumner & Popovic 2004): the
    high-res positions X whose per-face gradients best match the samplings' mean vertex
    deformation gradients ``J`` (n, 3, 3), taken per face as its corners' mean, with a
    soft pull ``w / diag^2`` to ``Y`` (n, 3) (the mean of the vertex transfers): the best
    of w = 1e2, 1e3, 1e4, 1e5 on §4.2."""
    import igl
    import scipy.sparse as sp
    from scipy.sparse.linalg import factorized
    G, m = igl.grad(V, F), len(F)
    Mw = sp.diags(np.tile(igl.doublearea(V, F) / 2, 3))
    Mv = igl.massmatrix(V, F, igl.MASSMATRIX_TYPE_VORONOI)
    D = np.asarray(G @ V).reshape(3, m, 3).transpose(1, 0, 2)            # rest gradient, (m, d, e)
    T = np.einsum("mde,mce->mdc", D, J[F].mean(axis=1)).transpose(1, 0, 2).reshape(3 * m, 3)
    ww = w / np.sum((V.max(0) - V.min(0)) ** 2)
    solve = factorized((G.T @ Mw @ G + ww * Mv).tocsc())
    rhs = G.T @ (Mw @ T) + ww * (Mv @ Y)
    return np.column_stack([solve(np.ascontiguousarray(rhs[:, c])) for c in range(3)])


def _metrics(Vp, V1, F, stretched) -> dict:
    diag = np.linalg.norm(V1.max(0) - V1.min(0))
    e = np.linalg.norm(Vp - V1, axis=1) / diag * 100
    Xn, c, s = normalize_unit_sphere(Vp, V1)
    d = point_surface_distance(Xn, (V1 - c) / s, F) ** 2
    return {"d_H": hausdorff(Vp, F, V1, F), "d_C": chamfer(Vp, F, V1, F), "v_mean": e.mean(), "v_max": e.max(),
            "iso_max": e[~stretched].max(), "dC_share": d[stretched].sum() / d.sum(), "stretched": stretched.mean()}


def main(root, classes, out=None):
    found = discover_tosca(root)
    claim = claim_output_dir(out, "tosca_factors", option="", name="--out") if out else None
    rows, lines = {name: [] for name in VARIANTS}, []
    with claim or contextlib.nullcontext():
        for c in classes:
            _class_rows(c, found[c], rows, lines)
        table = _table(rows, classes)
        print("\n" + table)
        if claim is not None:
            import pandas as pd
            pd.DataFrame(lines).to_csv(claim.path / "cases.csv", index=False, float_format="%.6g")
            (claim.path / "table.md").write_text(
                f"### Where the TOSCA transfer loses accuracy (paper §4.2), one factor at a time\n\n{table}\n"
                f"Made by `python benchmarks/tosca_transfer_factors.py {root} --classes {' '.join(classes)}` "
                f"at git commit {git_info().get('commit')} (dirty: {git_info().get('dirty')}), seed 0; "
                f"the factors and columns: the benchmark's docstring. 'stretched': vertices with an incident "
                f"edge whose length changes by more than {STRETCH:g} % from the rest pose to TOSCA's pose.\n")

def _class_rows(c, files, rows, lines):
    """Every pose of class ``c`` (``files``: pose -> path) under every variant: appended to
    ``rows`` (variant -> metrics) and ``lines`` (one dict per case and variant)."""
    V0, F0 = read_mesh(files[0], validate=False)
    V0, F0, he = validate_mesh(V0, F0, return_halfedges=True)
    topo = mesh_topology(V0, F0, he)
    for p, path in files.items():
        if p == 0:
            continue
        V1, _ = read_mesh(path, validate=False)
        st = _stretched(V0, V1, F0)
        cache = {}
        for name, change in VARIANTS.items():
            opt = {**BASE, **change}
            n_low, k = opt["n_low"], opt["k"]
            if n_low not in cache or len(cache[n_low]) < k:
                cache[n_low] = _samplings(V0, F0, V1, topo, n_low, max(k, 10))
            m = _metrics(_result(V0, F0, cache[n_low][:k], opt), V1, F0, st)
            rows[name].append(m)
            lines.append({"case": f"{c}{p}", "variant": name, **m})
            print(f"{c}{p} {name:26s} " + " ".join(f"{kk} {v:.4g}" for kk, v in m.items()), flush=True)


def _table(rows, classes) -> str:
    cols = ["d_H", "d_C", "v_mean", "v_max", "iso_max", "dC_share", "stretched"]
    out = [f"| variant ({', '.join(classes)}: {len(rows[next(iter(rows))])} cases) | d_H | d_C | vertex mean (%) | "
           "vertex max (%) | iso max (%) | d_C share of stretched | stretched vertices |",
           "|---|" + "---:|" * len(cols)]
    for name, r in rows.items():
        mean = {k: np.mean([x[k] for x in r]) for k in cols}
        out.append(f"| {name} | {mean['d_H']:.3e} | {mean['d_C']:.3e} | {mean['v_mean']:.4f} | "
                   f"{mean['v_max']:.3f} | {mean['iso_max']:.3f} | {mean['dC_share']:.2f} | "
                   f"{mean['stretched']:.3f} |")
    out.append("| paper §4.2 (all TOSCA classes but wolf, gorilla) | 5.660e-03 | 3.760e-08 | | | | | |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    a = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    a.add_argument("root", help="folder of TOSCA NAMEk.off meshes")
    a.add_argument("--classes", nargs="+", default=["cat", "centaur"])
    a.add_argument("--out", help="also write cases.csv and table.md into this folder")
    args = a.parse_args()
    raise SystemExit(run_command(lambda: main(args.root, args.classes, args.out), where=args.out))

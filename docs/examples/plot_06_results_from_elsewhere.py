"""
Results computed elsewhere, scored and ranked
=============================================

A method written in C++, MATLAB or anything else never runs inside the evaluator: export
the cases into plain files (OBJ, PLY, JSON, CSV, libigl's DMAT), deform them with your own
program, write one mesh per case (and, optionally, the times it measured), and score the
folder as a row beside ours. Here the outside program is a separate process that reads only
the exported files: linear Laplacian editing with the cotangent-free uniform Laplacian,
squared (a biharmonic fill-in of the handles' displacements), in NumPy and SciPy.
"""
# %%
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

import sshade

ROOT = Path(sshade.__file__).resolve().parents[1]
data = ROOT / "build" / "gallery" / "defaust_synthetic_ci"  # the small synthetic DeFAUST (as the plug-in example)
subprocess.run([sys.executable, "-m", "defaust", "source=synthetic", "preset=ci", "n_subjects=1", f"out={data}"],
               cwd=ROOT, check=True, capture_output=True)
work = Path(tempfile.mkdtemp())

# %%
# 1. Export the cases.
subprocess.run([sys.executable, "-m", "eval", "experiment=export", "dataset=defaust", f"dataset.root={data}",
                f"out_dir={work / 'exchange'}"], cwd=ROOT, check=True, capture_output=True)
print(sorted(p.name for p in (work / "exchange").iterdir()))

# %%
# 2. The outside program: it knows the file layout, not this package.
program = work / "biharmonic.py"
program.write_text(textwrap.dedent('''
    import csv, json, sys, time
    from pathlib import Path
    import numpy as np, scipy.sparse as sp, scipy.sparse.linalg as sla
    src, dst = Path(sys.argv[1]), Path(sys.argv[2]); dst.mkdir(exist_ok=True)
    rows = []
    for case in json.load(open(src / "cases.json"))["cases"]:
        name = case["name"]; t0 = time.perf_counter()
        lines = (src / name / "rest.obj").read_text().split("\\n")
        V = np.array([l.split()[1:4] for l in lines if l.startswith("v ")], float)
        F = np.array([l.split()[1:4] for l in lines if l.startswith("f ")], int) - 1
        h = json.load(open(src / name / "handles.json"))
        b, T = np.array(h["handles"]), np.array(h["targets"])
        n = len(V); i = F.ravel(); j = np.roll(F, -1, 1).ravel()
        A = sp.coo_matrix((np.ones(2 * len(i)), (np.r_[i, j], np.r_[j, i])), (n, n)).tocsr(); A.data[:] = 1
        L = sp.diags(np.asarray(A.sum(1)).ravel()) - A; K = (L @ L).tocsr()
        free = np.setdiff1d(np.arange(n), b); D = np.zeros((n, 3)); D[b] = T - V[b]
        D[free] = sla.splu(K[free][:, free].tocsc()).solve(-K[free][:, b] @ D[b])
        U = V + D
        (dst / f"{name}.obj").write_text("".join(f"v {x!r} {y!r} {z!r}\\n" for x, y, z in U.tolist())
                                         + "".join(f"f {a + 1} {c + 1} {d + 1}\\n" for a, c, d in F))
        rows.append((name, time.perf_counter() - t0))
    with open(dst / "times.csv", "w", newline="") as f:
        csv.writer(f).writerows([("case", "time_s", "machine"), *[(c, f"{t:.4f}", "gallery") for c, t in rows]])
'''))
subprocess.run([sys.executable, str(program), str(work / "exchange"), str(work / "mine")], check=True)

# %%
# 3. Score the folder beside SShaDe and ARAP in one table.
out = work / "run"
scored = f"{{_target_:eval.exchange.scored.ScoredResults,name:Biharmonic,results:{work / 'mine'}," \
         f"times:{work / 'mine' / 'times.csv'}}}"
subprocess.run([sys.executable, "-m", "eval", "dataset=defaust", f"dataset.root={data}", f"out_dir={out}",
                f"methods=[SShaDe,ARAP,{scored}]"], cwd=ROOT, check=True, capture_output=True)
print("\n".join(ln for ln in (out / "table.md").read_text().splitlines() if ln.startswith("|")))

# %%
# The distance to the true pose and the edge-length error of each case, per method.
cases = pd.read_csv(out / "cases.csv")
assert cases["error"].isna().all(), cases["error"].dropna().tolist()  # every file was read and scored
fig, axs = plt.subplots(1, 2, figsize=(10, 3.5))
for ax, col, label in zip(axs, ("gt_vertex_mean_pct", "edge_err_pct"), ("GT mean (% diag.)", "EL (%)")):
    means = cases.groupby("method")[col].mean().sort_values()
    ax.bar(means.index, means.values, color=["tab:orange" if m == "Biharmonic" else "tab:blue" for m in means.index])
    ax.set_ylabel(label)
fig.suptitle("a row scored from files written by another program (orange)")
fig.tight_layout()

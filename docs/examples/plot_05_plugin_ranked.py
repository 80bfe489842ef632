"""
A method of your own, ranked
============================

Any object with a ``name`` and ``deform(V, F, handles, targets) -> (n, 3)`` runs in the
evaluator beside ours (the ``sshade.Deformer`` interface). ``tests.plugin_example.MyMethod``
is a toy one: the handles' displacements spread over the mesh by a few Jacobi steps of the
uniform graph Laplacian. Listed in ``methods`` as a mapping that Hydra instantiates, it is
scored with every measure and ranked by its distance to the ground truth.

The data: a small DeFAUST built from the synthetic bodies (``python -m defaust
source=synthetic preset=ci``, one subject, four target poses, about 9k vertices), so this
runs on a machine with nothing but the package.
"""
# %%
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

import sshade

ROOT = Path(sshade.__file__).resolve().parents[1]
data = ROOT / "build" / "gallery" / "defaust_synthetic_ci"  # built once, resumed by later examples
subprocess.run([sys.executable, "-m", "defaust", "source=synthetic", "preset=ci", "n_subjects=1", f"out={data}"],
               cwd=ROOT, check=True, capture_output=True)

# %%
# The evaluator's command line, as typed in a shell: SShaDe, the ARAP baseline and the plug-in.
out = Path(tempfile.mkdtemp()) / "run"
cmd = [sys.executable, "-m", "eval", "dataset=defaust", f"dataset.root={data}", f"out_dir={out}",
       "methods=[SShaDe,ARAP,{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:20}]"]
subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True)
table = (out / "table.md").read_text()
print("\n".join(ln for ln in table.splitlines() if ln.startswith("|")))

# %%
# Each case's distance to the true pose (% of the bounding-box diagonal), per method.
cases = pd.read_csv(out / "cases.csv")
assert set(cases.method) == {"SShaDe", "ARAP", "Mine"} and cases["error"].isna().all()
order = cases.groupby("method")["gt_vertex_mean_pct"].mean().sort_values().index
fig, ax = plt.subplots(figsize=(7, 3.5))
for i, m in enumerate(order):
    y = cases.loc[cases.method == m, "gt_vertex_mean_pct"]
    ax.scatter([i] * len(y), y, color="tab:blue")
    ax.plot([i - 0.2, i + 0.2], [y.mean()] * 2, color="black")
ax.set_xticks(range(len(order)), [f"{i + 1}. {m}" for i, m in enumerate(order)])
ax.set_ylabel("GT mean (% diag.)")
ax.set_title("ranked by the distance to the true pose (line: the mean)")
fig.tight_layout()

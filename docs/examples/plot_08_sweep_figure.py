"""
A Hydra sweep and its figure
============================

``python -m eval.sweeps -m`` runs one evaluation per combination of the comma-separated
values (Hydra's multirun; locally, or as a SLURM job array with ``hydra/launcher=slurm``)
and summarises the sweep in ``sweep_table.csv``. Here SShaDe's low resolution ``n_low``
against its number of samplings ``k`` on the small synthetic DeFAUST of the other examples:
the distance to the true pose and the time, per job.
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
data = ROOT / "build" / "gallery" / "defaust_synthetic_ci"
subprocess.run([sys.executable, "-m", "defaust", "source=synthetic", "preset=ci", "n_subjects=1", f"out={data}"],
               cwd=ROOT, check=True, capture_output=True)

# %%
# The sweep: 3 x 2 jobs, one after the other in this machine's process.
sweep = Path(tempfile.mkdtemp()) / "sweep"
subprocess.run([sys.executable, "-m", "eval.sweeps", "-m", "dataset=defaust", f"dataset.root={data}",
                "methods=[SShaDe]", "sshade.n_low=300,600,1200", "sshade.n_samplings=1,5", "sshade.workers=1",
                f"hydra.sweep.dir={sweep}"], cwd=ROOT, check=True, capture_output=True)
table = pd.read_csv(sweep / "sweep_table.csv")
gt, tm = "SShaDe/gt_vertex_mean_pct", "SShaDe/time_s"  # the table's columns: <method>/<cases.csv column>
print(table[["job", "sshade.n_low", "sshade.n_samplings", "status", gt, tm]].to_string(index=False))

# %%
# One line per k: the distance to the true pose and SShaDe's time against n_low.
fig, axs = plt.subplots(1, 2, figsize=(10, 3.5))
for k, rows in table.groupby("sshade.n_samplings"):
    rows = rows.sort_values("sshade.n_low")
    axs[0].plot(rows["sshade.n_low"], rows[gt], marker="o", label=f"k = {k}")
    axs[1].plot(rows["sshade.n_low"], rows[tm], marker="o", label=f"k = {k}")
axs[0].set(xlabel="n_low", ylabel="GT mean (% diag.), mean over the cases")
axs[1].set(xlabel="n_low", ylabel="SShaDe's time per case (s)")
axs[0].legend()
fig.tight_layout()

"""
DeFAUST in PyTorch and in HuggingFace datasets
==============================================

``defaust.load`` reads a DeFAUST build as NumPy arrays (no Hydra, no evaluator), checked
against its manifest's checksums; ``defaust.torch_dataset`` wraps the cases for PyTorch's
``DataLoader``; ``python -m defaust export DIR --format hf`` writes Parquet shards that
HuggingFace ``datasets`` (or pandas) reads. The build here is the small synthetic one of the
other examples (one subject, four target poses). PyTorch is the ``[neural]`` extra and
``datasets`` the ``[hf]`` one: without them those two steps say so and the rest runs.
"""
# %%
import importlib.util
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import defaust
import sshade
from eval.present.render import render_mesh

ROOT = Path(sshade.__file__).resolve().parents[1]
data = ROOT / "build" / "gallery" / "defaust_synthetic_ci"
subprocess.run([sys.executable, "-m", "defaust", "source=synthetic", "preset=ci", "n_subjects=1", f"out={data}"],
               cwd=ROOT, check=True, capture_output=True)

# %%
# NumPy: every case with its rest mesh, handles, targets and ground truth.
cases = defaust.load(data)
case = cases[0]
print(f"{len(cases)} cases; {case.name}: V {case.V.shape} {case.V.dtype}, F {case.F.shape}, "
      f"handles {case.handles.shape}, targets {case.targets.shape}, V_gt {case.V_gt.shape}")

# %%
# PyTorch: a map-style dataset and a DataLoader (variable-size meshes: a list per batch).
if importlib.util.find_spec("torch"):
    import torch
    loader = torch.utils.data.DataLoader(defaust.torch_dataset(cases), batch_size=2,
                                         collate_fn=defaust.collate_cases)
    batch = next(iter(loader))
    print("torch batch:", {k: (type(v).__name__, len(v)) for k, v in batch.items() if isinstance(v, list)})
else:
    print("PyTorch is not installed (pip install -e .[neural])")

# %%
# HuggingFace datasets: the Parquet export, one row per case.
if importlib.util.find_spec("datasets") and importlib.util.find_spec("pyarrow"):
    import datasets
    out = Path(tempfile.mkdtemp()) / "hf"
    subprocess.run([sys.executable, "-m", "defaust", "export", str(data), "--to", str(out), "--format", "hf"],
                   cwd=ROOT, check=True, capture_output=True)
    ds = datasets.load_dataset("parquet", data_dir=str(out), split="train")
    print("datasets:", ds.num_rows, "rows; columns", ds.column_names)
    assert np.allclose(np.array(ds[0]["V"]), case.V)  # the same numbers as defaust.load
else:
    print("HuggingFace datasets is not installed (pip install -e .[hf])")

# %%
# The first case: the rest pose with its handles (static black, moved red) and the ground
# truth with the handles' targets.
box = np.vstack([case.V, case.V_gt])
fig, axs = plt.subplots(1, 2, figsize=(8, 4.5))
axs[0].imshow(render_mesh(case.V, case.F, points=case.V[case.handles],
                          point_colors=np.where(case.static, "black", "red"), frame=box, title="rest"))
axs[1].imshow(render_mesh(case.V_gt, case.F, points=case.targets, point_colors="red", frame=box,
                          title=f"ground truth, {case.pose_name}"))
for a in axs:
    a.axis("off")
fig.tight_layout()

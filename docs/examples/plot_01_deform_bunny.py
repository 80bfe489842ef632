"""
Deform the bunny by a handle file
=================================

The Stanford bunny (3,485 vertices) with a handle file in the deformation benchmark's
format (Botsch & Sorkine 2008): a ``.sel`` file marks each vertex fixed, free or handle,
a ``.def`` file holds the handle's 4x4 motion. ``sshade.deform`` moves the handles exactly
onto their targets and the rest of the surface as rigidly as it can (paper §3).
The same from the command line::

    python -m sshade deform bunny.off --sel bunny.sel --def bunny.def -o bunny_deformed.off
"""
# %%
# Write the handle files: the 50 lowest vertices fixed, the 50 highest the handle, moved
# by 15 % of the bounding-box diagonal along z.
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import sshade
from eval.present.render import render_mesh
from sshade.mesh.handle_files import FIXED, FREE, HANDLE, apply_def, read_def, read_sel, write_def, write_sel
from sshade.mesh.io import read_mesh

SHARED = Path(sshade.__file__).resolve().parents[2] / "shared" / "data" / "classic" / "bunny.off"
if SHARED.is_file():
    V, F = read_mesh(SHARED)
else:  # no shared data: the package's own capped cylinder
    from sshade.arap.problems import capped_cylinder
    V, F = capped_cylinder()
order = np.argsort(V[:, 1])
status = np.full(len(V), FREE, np.int8)
status[order[:50]] = FIXED
status[order[-50:]] = HANDLE
M = np.eye(4)
M[2, 3] = 0.15 * np.linalg.norm(V.max(0) - V.min(0))
folder = Path(tempfile.mkdtemp())
write_sel(folder / "bunny.sel", status)
write_def(folder / "bunny.def", M)

# %%
# Read them back as a user would, and deform.
status = read_sel(folder / "bunny.sel", len(V))
handles = np.flatnonzero(status != FREE)
targets = V[handles].copy()
moved = status[handles] == HANDLE
targets[moved] = apply_def(read_def(folder / "bunny.def"), V[handles][moved])
U = sshade.deform(V, F, handles, targets, n_low=1000, n_samplings=5, seed=0)
print(f"handle error {np.abs(U[handles] - targets).max():.2e}; largest move {np.linalg.norm(U - V, axis=1).max():.4f}")

# %%
# The rest pose and the deformed one, coloured by how far each vertex moved.
move = np.linalg.norm(U - V, axis=1)
frame = np.vstack([V, U])
fig, axes = plt.subplots(1, 2, figsize=(9, 4.5))
for ax, (W, title) in zip(axes, [(V, "rest"), (U, "deformed")]):
    ax.imshow(render_mesh(W, F, colors=move if W is U else None, points=W[handles],
                          point_colors=np.where(moved, "red", "black"), frame=frame, title=title))
    ax.axis("off")
fig.tight_layout()

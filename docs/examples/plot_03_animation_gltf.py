"""
A drag written to glTF and played back
======================================

``python -m sshade animate`` deforms a mesh through a sequence of handle targets (SShaDe
prepared once) and writes a glTF 2.0 binary: one mesh with a morph target per frame and
their keyframes, which Blender, three.js or any glTF viewer plays;
``python -m sshade view OUT.glb`` plays it too. Here the command runs from Python on the
bunny, and the file is read back frame by frame.
"""
# %%
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import sshade
from eval.present.render import render_mesh
from sshade.animate import main as animate
from sshade.mesh.gltf import read_glb_animation
from sshade.mesh.handle_files import FIXED, FREE, HANDLE, write_sel
from sshade.mesh.io import read_mesh, write_mesh

SHARED = Path(sshade.__file__).resolve().parents[2] / "shared" / "data" / "classic" / "bunny.off"
if SHARED.is_file():
    V, F = read_mesh(SHARED)
else:  # no shared data: the package's own capped cylinder
    from sshade.arap.problems import capped_cylinder
    V, F = capped_cylinder()

# %%
# The files a user brings: the mesh, a selection (50 lowest vertices fixed, 50 highest the
# handle) and the frames as 4x4 matrices of the handle (a turn of 40 degrees about the
# vertical axis through the body's centre, in 24 steps).
folder = Path(tempfile.mkdtemp())
write_mesh(folder / "bunny.off", V, F)
order = np.argsort(V[:, 1])
status = np.full(len(V), FREE, np.int8)
status[order[:50]] = FIXED
status[order[-50:]] = HANDLE
write_sel(folder / "bunny.sel", status)
c = V.mean(0)
mats = []
for t in np.linspace(0, np.radians(40), 24):
    R = np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, c - R @ c
    mats.append(M)
np.save(folder / "frames.npy", np.array(mats))

# %%
# The command, as typed in a shell (here called in-process); it prints one line per frame.
status_code = animate([str(folder / "bunny.off"), "--sel", str(folder / "bunny.sel"),
                       "--frames", str(folder / "frames.npy"), "-o", str(folder / "bunny.glb"),
                       "--n-low", "1000", "--fps", "12"])
glb = read_glb_animation(folder / "bunny.glb")
print(f"exit {status_code}; {glb.n_frames} keyframes at {glb.times[1] - glb.times[0]:.4f} s apart, "
      f"{len(glb.targets)} morph targets, {(folder / 'bunny.glb').stat().st_size / 1e6:.1f} MB")

# %%
# Keyframes read back from the file (base plus weighted morph targets), as a viewer plays them.
shown = (0, 8, 16, glb.n_frames - 1)
box = np.vstack([glb.frame(i) for i in shown])
fig, axes = plt.subplots(1, len(shown), figsize=(12, 3.5))
for ax, i in zip(axes, shown):
    ax.imshow(render_mesh(glb.frame(i), glb.F, frame=box, title=f"t = {glb.times[i]:.2f} s"))
    ax.axis("off")
fig.tight_layout()

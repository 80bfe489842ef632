"""
SShaDe against ARAP on a hard mesh
==================================

A hard mesh for a low-resolution method: TOSCA's centaur Loop-subdivided once with LS3
(Boyé et al. 2010), 63k vertices of very uneven triangles, as the paper's scaling
experiment builds its hard meshes. The edit turns one region 20 degrees and moves another
(``eval.datasets.shapes.axis_handles``, the scaling experiment's). The full-resolution ARAP
baseline (cotangent weights, run to its energy-verified minimiser) and SShaDe deform it;
each result is coloured by its local stretch: the mean relative change of the lengths of
the edges at each vertex, in %. Cotangent weights turn negative on LS3's obtuse triangles,
and ARAP's minimiser crumples there; SShaDe solves on its own low-resolution remesh.
"""
# %%
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import sshade
from baselines import ARAP
from defaust.highres import ls3_loop
from eval.datasets.shapes import axis_handles, axis_landmarks
from eval.present.render import render_mesh
from eval.present.render_style import ERROR_CMAP, RenderStyle
from sshade.mesh.io import read_mesh

SHARED = Path(sshade.__file__).resolve().parents[2] / "shared" / "data" / "tosca" / "centaur0.off"
if SHARED.is_file():
    V0, F0 = read_mesh(SHARED)
else:  # no shared data: the package's own twisted bar
    from sshade.arap.problems import box_surface
    V0, F0 = box_surface()
V, F = ls3_loop(V0, F0, iterations=1)
lm, center, axes = axis_landmarks(V0)
handles, targets, static, group = axis_handles(V, lm, center, axes)
print(f"{len(V)} vertices, {len(F)} faces; {len(handles)} handles in 4 regions")

# %%
# Both methods on the same problem.
t0 = time.perf_counter()
U_arap = ARAP().deform(V, F, handles, targets)
arap_s = time.perf_counter() - t0
t0 = time.perf_counter()
U = sshade.deform(V, F, handles, targets, n_low=3000, n_samplings=5, seed=0)
sshade_s = time.perf_counter() - t0


def stretch(U):
    """(n,) mean |l' / l - 1| over the edges at each vertex, in %."""
    E = np.unique(np.sort(np.vstack([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    rel = np.abs(np.linalg.norm(U[E[:, 0]] - U[E[:, 1]], axis=1) / np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1) - 1)
    return 100 * np.bincount(E.ravel(), np.repeat(rel, 2), len(V)) / np.bincount(E.ravel(), minlength=len(V))


s_arap, s_ours = stretch(U_arap), stretch(U)
print(f"ARAP (converged) {arap_s:.1f} s, mean stretch {s_arap.mean():.2f} %; "
      f"SShaDe {sshade_s:.2f} s ({arap_s / sshade_s:.0f}x), mean stretch {s_ours.mean():.2f} %")

# %%
# The rest pose with the handles (static black, moved red), and both results coloured by
# their stretch on one scale.
box = np.vstack([V, U_arap, U])
style = RenderStyle(up="z", cmap=ERROR_CMAP)
clim = (0, float(np.percentile(np.r_[s_arap, s_ours], 99)))
fig, axs = plt.subplots(1, 3, figsize=(13, 4.5))
axs[0].imshow(render_mesh(V, F, points=V[handles], point_colors=np.where(static, "black", "red"), frame=box,
                          title="rest and handles", style=style))
axs[1].imshow(render_mesh(U_arap, F, colors=s_arap, clim=clim, frame=box, style=style,
                          title=f"ARAP, {arap_s:.1f} s"))
axs[2].imshow(render_mesh(U, F, colors=s_ours, clim=clim, frame=box, style=style, colorbar_label="stretch (%)",
                          title=f"SShaDe, {sshade_s:.2f} s"))
for a in axs:
    a.axis("off")
fig.tight_layout()

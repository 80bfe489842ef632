"""
Prepare once, solve frames
==========================

``sshade.prepare`` does once what does not depend on where the handles go (per sampling
the remesh, the projection, the local coordinates and the low-res ARAP's set-up);
``Prepared.solve(targets)`` then deforms one frame. Each later frame starts from the
earlier ones extrapolated along the targets' path, so a smooth drag costs a fraction of a
one-shot ``sshade.deform``. Here: 30 frames of the bunny's ears lifted along a smoothstep.
"""
# %%
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import sshade
from eval.present.render import render_mesh
from sshade.mesh.io import read_mesh

SHARED = Path(sshade.__file__).resolve().parents[2] / "shared" / "data" / "classic" / "bunny.off"
if SHARED.is_file():
    V, F = read_mesh(SHARED)
else:  # no shared data: the package's own capped cylinder
    from sshade.arap.problems import capped_cylinder
    V, F = capped_cylinder()
order = np.argsort(V[:, 1])
handles = np.r_[order[:50], order[-50:]]
final = V[handles].copy()
final[50:, 1] += 0.2 * np.linalg.norm(V.max(0) - V.min(0))
s = lambda t: 3 * t**2 - 2 * t**3  # noqa: E731  (smoothstep)
path = [V[handles] + s(i / 30) * (final - V[handles]) for i in range(1, 31)]

# %%
# Prepare once, then time every frame; a one-shot deform of the last frame beside them.
t0 = time.perf_counter()
prepared = sshade.prepare(V, F, handles, n_low=1000, n_samplings=5, seed=0)
prepare_s = time.perf_counter() - t0
frames, seconds = [], []
for T in path:
    t0 = time.perf_counter()
    frames.append(prepared.solve(T))
    seconds.append(time.perf_counter() - t0)
t0 = time.perf_counter()
one_shot = sshade.deform(V, F, handles, path[-1], n_low=1000, n_samplings=5, seed=0)
one_shot_s = time.perf_counter() - t0
diag = np.linalg.norm(V.max(0) - V.min(0))
print(f"prepare {prepare_s:.2f} s; frames 2-30: median {np.median(seconds[1:]) * 1e3:.0f} ms; "
      f"one-shot deform {one_shot_s * 1e3:.0f} ms; last frame to the one-shot: "
      f"{100 * np.linalg.norm(frames[-1] - one_shot, axis=1).mean() / diag:.3f} % of the diagonal")

# %%
# Seconds per frame, and four of the frames.
fig = plt.figure(figsize=(10, 6))
ax = fig.add_subplot(2, 1, 1)
ax.bar(np.arange(1, 31), np.array(seconds) * 1e3, color="tab:blue", label="prepared.solve")
ax.axhline(one_shot_s * 1e3, color="tab:red", ls="--", label="one-shot sshade.deform")
ax.set_xlabel("frame")
ax.set_ylabel("ms")
ax.legend()
box = np.vstack([V, *frames])
for j, i in enumerate((0, 9, 19, 29)):
    a = fig.add_subplot(2, 4, 5 + j)
    a.imshow(render_mesh(frames[i], F, frame=box, title=f"frame {i + 1}"))
    a.axis("off")
fig.tight_layout()

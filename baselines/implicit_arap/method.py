"""Implicit-ARAP (Baieri, Maggioli, Lähner, Melzi, Rodolà 2024, "Implicit-ARAP: efficient
handle-guided deformation of high-resolution meshes and neural fields via local patch
meshing"; reference code github.com/dbaieri/implicit-arap, MIT licence) behind the
:class:`sshade.method_interface.Deformer` interface. Our own code, a port of the method.

:class:`ImplicitARAP` fits a neural SDF (:mod:`.sdf`), trains a deformation field
``T(x) = R(x) x + t(x)`` (:mod:`.field`) with Adam on the patch ARAP energy plus the
handle terms (:mod:`.patches`) and applies ``T`` to every input vertex. Handles are
vertex indices; one whose target equals its rest position is static, any other moving.
The steps, the loss and the presets: docs/methods.md, "Implicit-ARAP".
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_handles, validate_mesh

from .backend import require_torch, torch
from .field import DeformationField
from .patches import disk, edge_structure, mesh_patches, patch_energy
from .sdf import (
    SurfaceSampler,
    fit_sdf,
    normalisation,
    project_to_level,
    sample_zero_level,
)

__all__ = ["PRESETS", "ImplicitARAP", "deterministic", "fit_field", "patch_centres"]

#: The configurations. ``paper``: the reference code's as of its last commit before the
#: paper (fa0cb78, 2024-05-02; GPU-sized): its loss weights (ARAP 1000, each handle MSE
#: 1000), its cotangent weights (``reference_weights``: wrong edges, overwritten repeats)
#: and its learning-rate schedule (MultiStepLR, halved at steps 1000, 2000, 5000).
#: ``cpu`` (the default) and ``cpu_soft`` share ``_CPU``: smaller networks, fewer samples
#: and patches, zero-level centres drawn on the mesh and projected (instead of rejection
#: sampling in the box), at most 128 handle patches per step. ``cpu``: correct cotangent
#: weights with ARAP weight 120, at least as stiff as the reference's mesh default since
#: d6efd08 (weight 10 with its own weights, which are 5.0-12.1x stiffer on the cpu
#: preset's 16-point disks: benchmarks/implicit_arap_weights.py), run for ``STIFF_STEPS``
#: steps. ``cpu_soft``: ARAP weight 10 with correct weights, 500 steps (about 8x softer
#: than the reference; the default before ``cpu``). Measurements: docs/methods.md.
#: ``handle_patches`` 0 = every handle is a patch centre at every step (the reference);
#: n > 0 = a random n of them per step when there are more.
_CPU = dict(layers=4, width=128, skip=2, octaves=6, sdf_steps=1000, sdf_lr=5e-4, sdf_samples=2048,
            deform_lr=1e-3, surface_patches=256, handle_patches=128, space_patches=128, patch_points=16,
            patch_radius=math.sqrt(1e-3), projections=2, level_threshold=0.01, centres="mesh",
            handle_weight=1000.0, reference_weights=False, lr_milestones=(1000, 2000, 5000), lr_gamma=0.5)
#: The cpu preset's deformation steps: the fewest after which the largest handle error
#: stops falling on most FAUST and DeFAUST cases at its ARAP weight (three FAUST cases
#: stay above 1 % of the diagonal, kept with their handle error: docs/methods.md).
STIFF_STEPS = 1500
PRESETS = {
    "paper": dict(layers=8, width=256, skip=4, octaves=6, sdf_steps=10000, sdf_lr=1e-4, sdf_samples=16384,
                  deform_steps=1000, deform_lr=1e-3, surface_patches=1000, handle_patches=0, space_patches=1000,
                  patch_points=30, patch_radius=math.sqrt(1e-3), projections=5, level_threshold=0.01,
                  centres="rejection", arap_weight=1000.0, handle_weight=1000.0, reference_weights=True,
                  lr_milestones=(1000, 2000, 5000), lr_gamma=0.5),
    "cpu": dict(_CPU, deform_steps=STIFF_STEPS, arap_weight=120.0),
    "cpu_soft": dict(_CPU, deform_steps=500, arap_weight=10.0),
}
_INTS = {"layers": 2, "width": 1, "skip": 0, "octaves": 0, "sdf_steps": 0, "sdf_samples": 1, "deform_steps": 0,
         "surface_patches": 0, "handle_patches": 0, "space_patches": 0, "patch_points": 4, "projections": 0}
_FLOATS = ("sdf_lr", "deform_lr", "patch_radius", "level_threshold", "arap_weight", "handle_weight", "lr_gamma")


def check_settings(preset: str, given: dict) -> dict:
    """The preset's settings with the ``given`` non-None values over them, checked.

    Raises
    ------
    SShaDeError naming the parameter and its value: an unknown preset, an integer below
    its minimum (``layers`` 2, ``patch_points`` 4, ``skip`` a hidden layer or 0, ...), a
    float that is not finite and > 0 (``arap_weight`` may be 0), ``centres`` not
    ``mesh`` / ``rejection``, ``reference_weights`` not a bool.
    """
    if preset not in PRESETS:
        raise SShaDeError(f"Implicit-ARAP: unknown preset {preset!r}; use one of {sorted(PRESETS)}")
    s = {**PRESETS[preset], **{k: v for k, v in given.items() if v is not None}}
    for k, lo in _INTS.items():
        v = s[k]
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise SShaDeError(f"Implicit-ARAP: {k} must be an integer >= {lo}, got {v!r}")
        s[k] = int(v)
    for k in _FLOATS:
        v = s[k]
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        if not ok or v < 0 or (v == 0 and k != "arap_weight"):
            raise SShaDeError(f"Implicit-ARAP: {k} must be a finite number > 0, got {v!r}")
        s[k] = float(v)
    if s["skip"] and not 1 <= s["skip"] <= s["layers"] - 2:
        raise SShaDeError(f"Implicit-ARAP: skip must be 0 or in [1, layers - 2 = {s['layers'] - 2}], got {s['skip']}")
    if s["centres"] not in ("mesh", "rejection"):
        raise SShaDeError(f"Implicit-ARAP: centres must be 'mesh' or 'rejection', got {s['centres']!r}")
    if not isinstance(s["reference_weights"], (bool, np.bool_)):
        raise SShaDeError(f"Implicit-ARAP: reference_weights must be true or false, got {s['reference_weights']!r}")
    s["reference_weights"] = bool(s["reference_weights"])
    s["lr_milestones"] = _milestones(s["lr_milestones"])
    return s


def _milestones(v) -> tuple:
    """``lr_milestones`` as a tuple of increasing integers >= 1 (SShaDeError otherwise)."""
    try:
        m = tuple(v)
    except TypeError:
        m = None
    if m is None or not all(isinstance(x, (int, np.integer)) and not isinstance(x, bool) and x >= 1 for x in m) \
            or any(b <= a for a, b in zip(m, m[1:])):
        raise SShaDeError(f"Implicit-ARAP: lr_milestones must be increasing integers >= 1, got {v!r}")
    return tuple(int(x) for x in m)


@contextmanager
def deterministic():
    """Deterministic PyTorch kernels (``warn_only``: an op without one warns) inside the
    block; the previous setting is restored after it."""
    was, warn = torch.are_deterministic_algorithms_enabled(), torch.is_deterministic_algorithms_warn_only_enabled()
    torch.use_deterministic_algorithms(True, warn_only=True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(was, warn_only=warn)


def patch_centres(sdf, H, s: dict, sampler, generator):
    """One step's patch centres: handles (all, or a random ``handle_patches`` of them),
    zero-level points up to ``surface_patches`` centres in all (``centres="mesh"``: drawn
    on the mesh and projected ``projections`` times onto the zero level set;
    ``"rejection"``: the reference's rejection sampling, |f| < ``level_threshold``) and
    ``space_patches`` uniform points of ``[-1, 1]^3``.

    Parameters
    ----------
    sdf : callable; H : (h, 3) tensor of handle rest positions (normalised); s : the
    settings (:func:`check_settings`); sampler : :class:`SurfaceSampler` of the mesh;
    generator : CPU torch.Generator.

    Returns
    -------
    (P, 3) tensor.
    """
    dev, dt = H.device, H.dtype
    hc = H
    if s["handle_patches"] and len(H) > s["handle_patches"]:
        hc = H[torch.randperm(len(H), generator=generator)[:s["handle_patches"]].to(dev)]
    n_surf = max(0, s["surface_patches"] - len(hc))
    if s["centres"] == "mesh":
        xs, _ = sampler.sample(n_surf, generator)
        xs = project_to_level(sdf, xs, torch.zeros(n_surf, device=dev, dtype=dt), s["projections"])
    else:
        xs = sample_zero_level(sdf, n_surf, threshold=s["level_threshold"], iters=s["projections"],
                               generator=generator, device=dev, dtype=dt)
    xu = (2 * torch.rand(s["space_patches"], 3, generator=generator, dtype=torch.float64) - 1).to(dev, dt)
    return torch.cat([hc, xs, xu])


def fit_field(sdf, X: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray, moving: np.ndarray, *,
              s: dict, generator, rng: np.random.Generator, device, reference_weights: bool = False, monitor=None):
    """Train the deformation field (Baieri et al. 2024 §4; reference ``deform-sdf``).

    Parameters
    ----------
    sdf : callable (N, 3) -> (N,), the shape; X : (n, 3) float64 normalised vertices;
    F : (m, 3) int64; handles : (h,) int64; targets : (h, 3) float64 normalised targets;
    moving : (h,) bool; s : settings (:func:`check_settings`); generator : CPU
    torch.Generator; rng : numpy Generator (the disks); device : torch device;
    reference_weights : bool, the reference code's cotangent weights
    (:mod:`baselines.implicit_arap.patches`); monitor : None or callable ``(step, field)``
    called after each step (``step`` from 1; e.g. to record the handle error on the way).

    Returns
    -------
    (DeformationField, list of the loss per step, mean number of patches per step).
    """
    dt = torch.float32
    field = DeformationField(layers=s["layers"], width=s["width"], skip=s["skip"], octaves=s["octaves"],
                             generator=generator, device=device, dtype=dt)
    opt = torch.optim.Adam(field.parameters(), lr=s["deform_lr"])
    # the reference's schedule (MultiStepLR): the rate times lr_gamma at each milestone
    sched = torch.optim.lr_scheduler.MultiStepLR(opt, milestones=list(s["lr_milestones"]), gamma=s["lr_gamma"])
    H = torch.as_tensor(X[handles], dtype=dt, device=device)
    goal = torch.where(torch.as_tensor(moving, device=device)[:, None],
                       torch.as_tensor(targets, dtype=dt, device=device), H)
    sampler = SurfaceSampler(X, F, device, dt)
    groups = [g for g in (torch.as_tensor(moving, device=device), torch.as_tensor(~moving, device=device)) if g.any()]
    history, n_patches = [], 0
    for _ in range(s["deform_steps"]):
        pts, tris = disk(s["patch_points"], s["patch_radius"], rng)
        Xp = mesh_patches(sdf, patch_centres(sdf, H, s, sampler, generator), pts, s["projections"])
        P, k = Xp.shape[:2]
        x = torch.cat([Xp.reshape(-1, 3), H])
        R, t = field.rotation_translation(x)
        Tx = (R @ x[:, :, None])[:, :, 0] + t
        arap = patch_energy(Xp, R[:P * k].view(P, k, 3, 3), Tx[:P * k].view(P, k, 3), tris,
                            edge_structure(tris, reference_weights))
        err = ((Tx[P * k:] - goal) ** 2).sum(-1)
        fit = sum(err[g].mean() / 3 for g in groups)  # the MSE of each group (per coordinate)
        loss = s["arap_weight"] * arap + s["handle_weight"] * fit
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        history.append(float(loss.detach()))
        if monitor is not None:
            monitor(len(history), field)
        n_patches += P
    return field, history, n_patches / max(s["deform_steps"], 1)


def apply_field(field, X: np.ndarray, device, chunk: int = 32768) -> np.ndarray:
    """``T`` at (n, 3) float64 normalised points, in chunks; (n, 3) float64."""
    out = []
    with torch.no_grad():
        for i in range(0, len(X), chunk):
            out.append(field(torch.as_tensor(X[i:i + chunk], dtype=torch.float32, device=device)).cpu().double())
    return torch.cat(out).numpy()


class ImplicitARAP:
    """Implicit-ARAP (Baieri et al. 2024) as one of our methods.

    Parameters
    ----------
    preset : ``"cpu"`` (default; minutes per case on 2 cores, at least as stiff as the
        reference), ``"cpu_soft"`` (ARAP weight 10 with correct weights, 500 steps) or
        ``"paper"`` (the reference configuration: 8 x 256 networks, 10,000 SDF steps,
        1,000 deformation steps, 2,000 patches of 30 points per step; sized for a GPU).
        See :data:`PRESETS`.
    device : ``"auto"`` (CUDA when available), ``"cpu"`` or ``"cuda"``.
    seed : int, seeds every draw (torch and numpy); the same seed on the same device
        and thread count gives bit-identical output.
    reference_weights : bool or None, the reference code's cotangent weights (wrong edges,
        overwritten repeats) instead of the correct ones (docs/methods.md); None: the
        preset's (paper: True, cpu and cpu_soft: False).
    layers, width, skip, octaves, sdf_steps, sdf_lr, sdf_samples, deform_steps,
    deform_lr, surface_patches, handle_patches, space_patches, patch_points,
    patch_radius, projections, level_threshold, centres, arap_weight, handle_weight,
    lr_milestones (increasing steps), lr_gamma (the rate's factor at each milestone) :
        override the preset's value (None: the preset's). Lengths in the normalised box.

    Raises
    ------
    SShaDeError at construction: PyTorch missing (one line: ``Implicit-ARAP needs
    PyTorch: pip install -e .[neural]``), a bad parameter, ``device="cuda"`` without CUDA.

    Example::

        m = ImplicitARAP(preset="cpu")
        Vd = m.deform(V, F, handles, targets)
        m.info["sdf_fit_s"], m.info["deform_s"]
    """

    def __init__(self, *, preset: str = "cpu", device: str = "auto", seed: int = 0, reference_weights=None,
                 name: str = "Implicit-ARAP", layers=None, width=None, skip=None, octaves=None, sdf_steps=None,
                 sdf_lr=None, sdf_samples=None, deform_steps=None, deform_lr=None, surface_patches=None,
                 handle_patches=None, space_patches=None, patch_points=None, patch_radius=None, projections=None,
                 level_threshold=None, centres=None, arap_weight=None, handle_weight=None,
                 lr_milestones=None, lr_gamma=None):
        require_torch()
        given = {k: v for k, v in locals().items() if k in PRESETS["paper"]}
        self.settings = check_settings(str(preset), given)
        if device not in ("auto", "cpu", "cuda"):
            raise SShaDeError(f"Implicit-ARAP: device must be auto, cpu or cuda, got {device!r}")
        if device == "cuda" and not torch.cuda.is_available():
            raise SShaDeError("Implicit-ARAP: device=cuda but PyTorch sees no CUDA device (use auto or cpu)")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise SShaDeError(f"Implicit-ARAP: seed must be an integer >= 0, got {seed!r}")
        self.preset, self.device, self.seed = str(preset), device, int(seed)
        self.reference_weights = self.settings["reference_weights"]
        self.name = name
        self.info: dict = {}
        #: None, or a callable ``(step, field)`` run after each deformation step
        #: (:func:`fit_field`; normalised coordinates, :func:`baselines.implicit_arap.sdf.normalisation`)
        self.monitor = None

    def effective_params(self) -> dict:
        """The parameters :meth:`deform` runs with: ``preset``, ``device`` (as asked;
        ``auto``: CUDA when PyTorch sees one, the case's ``device`` info says which),
        ``seed`` and every setting of :data:`PRESETS` with the given ones over the
        preset's (:func:`check_settings`): no None stands for a preset's value."""
        return {"preset": self.preset, "device": self.device, "seed": self.seed, **self.settings}

    def torch_device(self) -> str:
        """The device the next :meth:`deform` runs on (``auto`` resolved)."""
        if self.device == "auto":
            return "cuda" if torch.cuda.is_available() else "cpu"
        return self.device

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` so ``V[handles]`` move to ``targets`` (soft constraints, as
        in the paper); returns (n, 3) float64 in the input's units. The time includes
        the SDF fit. Raises ``SShaDeError`` on invalid mesh or handles."""
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        s, dev = self.settings, self.torch_device()
        centre, scale = normalisation(V, F)
        X = (V - centre) * scale
        with deterministic():
            gen = torch.Generator().manual_seed(self.seed)
            rng = np.random.default_rng(self.seed)
            t0 = time.perf_counter()
            net = {k: s[k] for k in ("layers", "width", "skip", "octaves")}
            sdf, sdf_hist = fit_sdf(X, F, steps=s["sdf_steps"], lr=s["sdf_lr"], samples=s["sdf_samples"],
                                    generator=gen, device=dev, **net)
            t1 = time.perf_counter()
            moving = ~np.all(targets == V[handles], axis=1)
            field, hist, n_patches = fit_field(sdf, X, F, handles, (targets - centre) * scale, moving, s=s,
                                               generator=gen, rng=rng, device=dev,
                                               reference_weights=self.reference_weights, monitor=self.monitor)
            t2 = time.perf_counter()
            out = apply_field(field, X, dev) / scale + centre
        self.info = {"preset": self.preset, "device": dev, "seed": self.seed, "handles": "soft",
                     "sdf_steps": s["sdf_steps"],
                     "deform_steps": s["deform_steps"], "lr_milestones": list(s["lr_milestones"]),
                     "sdf_fit_s": t1 - t0, "deform_s": t2 - t1,
                     "map_s": time.perf_counter() - t2, "sdf_loss": _tail(sdf_hist), "loss": _tail(hist),
                     "loss_first": hist[0] if hist else None, "patches_per_step": n_patches,
                     "moving_handles": int(moving.sum()), "static_handles": int((~moving).sum()),
                     "reference_weights": self.reference_weights, "threads": torch.get_num_threads()}
        return out

    def warmup(self, n_vertices: int | None = None) -> float:
        """Run PyTorch once on a few points (thread pool, kernels) outside the timed
        call; returns the seconds spent."""
        t0 = time.perf_counter()
        dev = self.torch_device()
        field = DeformationField(layers=2, width=8, skip=0, octaves=1, device=dev)
        x = torch.zeros(8, 3, device=dev, requires_grad=True)
        torch.autograd.grad(field(x).sum(), x, create_graph=True)[0].sum().backward()
        return time.perf_counter() - t0


def _tail(history: list) -> float | None:
    """Mean of the last 10 values of a loss history (None when empty)."""
    return float(np.mean(history[-10:])) if history else None

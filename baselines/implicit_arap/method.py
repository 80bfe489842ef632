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

import inspect
import time
from collections.abc import Mapping
from contextlib import contextmanager
from dataclasses import fields

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_handles, validate_mesh

from .backend import require_torch, resolve_device, torch
from .field import DeformationField
from .params import PRESETS, ImplicitARAPParams, implicit_arap_params
from .patches import disk, edge_structure, mesh_patches, patch_energy
from .sdf import (
    SurfaceSampler,
    fit_sdf,
    normalisation,
    project_to_level,
    sample_zero_level,
)

__all__ = ["PRESETS", "ImplicitARAP", "ImplicitARAPParams", "deterministic", "fit_field", "patch_centres",
           "apply_field"]


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


def patch_centres(sdf, H, params: ImplicitARAPParams, sampler, generator):
    """One step's patch centres: handles (all, or a random ``handle_patches`` of them),
    zero-level points up to ``surface_patches`` centres in all (``centres="mesh"``: drawn
    on the mesh and projected ``projections`` times onto the zero level set;
    ``"rejection"``: the reference's rejection sampling, |f| < ``level_threshold``) and
    ``space_patches`` uniform points of ``[-1, 1]^3``.

    Parameters
    ----------
    sdf : callable; H : (h, 3) tensor of handle rest positions (normalised); params :
    :class:`ImplicitARAPParams` (the fields named above); sampler : :class:`SurfaceSampler`
    of the mesh; generator : CPU torch.Generator.

    Returns
    -------
    (P, 3) tensor.
    """
    p = params
    dev, dt = H.device, H.dtype
    hc = H
    if p.handle_patches and len(H) > p.handle_patches:
        hc = H[torch.randperm(len(H), generator=generator)[:p.handle_patches].to(dev)]
    n_surf = max(0, p.surface_patches - len(hc))
    if p.centres == "mesh":
        xs, _ = sampler.sample(n_surf, generator)
        xs = project_to_level(sdf, xs, torch.zeros(n_surf, device=dev, dtype=dt), p.projections)
    else:
        xs = sample_zero_level(sdf, n_surf, threshold=p.level_threshold, iters=p.projections,
                               generator=generator, device=dev, dtype=dt)
    xu = (2 * torch.rand(p.space_patches, 3, generator=generator, dtype=torch.float64) - 1).to(dev, dt)
    return torch.cat([hc, xs, xu])


def fit_field(sdf, X: np.ndarray, F: np.ndarray, handles: np.ndarray, targets: np.ndarray, moving: np.ndarray,
              params: ImplicitARAPParams, *, generator, rng: np.random.Generator, monitor=None):
    """Train the deformation field (Baieri et al. 2024 §4; reference ``deform-sdf``).

    Parameters
    ----------
    sdf : callable (N, 3) -> (N,), the shape; X : (n, 3) float64 normalised vertices;
    F : (m, 3) int64; handles : (h,) int64; targets : (h, 3) float64 normalised targets;
    moving : (h,) bool; params : :class:`ImplicitARAPParams`: the network (``layers``,
    ``width``, ``skip``, ``octaves``), the steps and their rate schedule, the patches
    (:func:`patch_centres`, ``patch_points``, ``patch_radius``), the loss weights, the
    cotangent weights (``reference_weights``, :mod:`baselines.implicit_arap.patches`) and
    the device (``auto`` resolved: :func:`baselines.implicit_arap.backend.resolve_device`);
    generator : CPU torch.Generator; rng : numpy Generator (the disks); monitor : None or
    callable ``(step, field)`` called after each step (``step`` from 1; e.g. to record the
    handle error on the way).

    Returns
    -------
    (DeformationField, list of the loss per step, mean number of patches per step).
    """
    p, device, dt = params, resolve_device(params.device), torch.float32
    field = DeformationField(layers=p.layers, width=p.width, skip=p.skip, octaves=p.octaves,
                             generator=generator, device=device, dtype=dt)
    opt = torch.optim.Adam(field.parameters(), lr=p.deform_lr)
    # the reference's schedule (MultiStepLR): the rate times lr_gamma at each milestone
    sched = torch.optim.lr_scheduler.MultiStepLR(opt, milestones=list(p.lr_milestones), gamma=p.lr_gamma)
    H = torch.as_tensor(X[handles], dtype=dt, device=device)
    goal = torch.where(torch.as_tensor(moving, device=device)[:, None],
                       torch.as_tensor(targets, dtype=dt, device=device), H)
    sampler = SurfaceSampler(X, F, device, dt)
    groups = [g for g in (torch.as_tensor(moving, device=device), torch.as_tensor(~moving, device=device)) if g.any()]
    history, n_patches = [], 0
    for _ in range(p.deform_steps):
        pts, tris = disk(p.patch_points, p.patch_radius, rng)
        Xp = mesh_patches(sdf, patch_centres(sdf, H, p, sampler, generator), pts, p.projections)
        P, k = Xp.shape[:2]
        x = torch.cat([Xp.reshape(-1, 3), H])
        R, t = field.rotation_translation(x)
        Tx = (R @ x[:, :, None])[:, :, 0] + t
        arap = patch_energy(Xp, R[:P * k].view(P, k, 3, 3), Tx[:P * k].view(P, k, 3), tris,
                            edge_structure(tris, p.reference_weights))
        err = ((Tx[P * k:] - goal) ** 2).sum(-1)
        fit = sum(err[g].mean() / 3 for g in groups)  # the MSE of each group (per coordinate)
        loss = p.arap_weight * arap + p.handle_weight * fit
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        history.append(float(loss.detach()))
        if monitor is not None:
            monitor(len(history), field)
        n_patches += P
    return field, history, n_patches / max(p.deform_steps, 1)


def apply_field(field, X: np.ndarray, device, chunk: int = 32768) -> np.ndarray:
    """``T`` at (n, 3) float64 normalised points, in chunks; (n, 3) float64."""
    out = []
    with torch.no_grad():
        for i in range(0, len(X), chunk):
            out.append(field(torch.as_tensor(X[i:i + chunk], dtype=torch.float32, device=device)).cpu().double())
    return torch.cat(out).numpy()


def _spelled_out(init) -> inspect.Signature:
    """The signature of ``init`` (a constructor taking ``**overrides`` of
    :class:`ImplicitARAPParams`) without ``self``, the overrides spelled out as
    keyword-only parameters with the fields' defaults: what introspection (help, a plug-in
    builder asking whether ``name`` is a parameter, an editor) sees."""
    sig = inspect.signature(init)
    head = [q for q in sig.parameters.values() if q.kind is not q.VAR_KEYWORD and q.name != "self"]
    return sig.replace(parameters=[*head, *(inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default)
                                            for f in fields(ImplicitARAPParams))])


class ImplicitARAP:
    """Implicit-ARAP (Baieri et al. 2024) as one of our methods.

    Parameters
    ----------
    params : :class:`ImplicitARAPParams`, a mapping of some of its fields, or None (the
        defaults: the ``cpu`` preset).
    name : str, default ``"Implicit-ARAP"``, the method's row name.
    **overrides : fields of :class:`ImplicitARAPParams` over ``params`` (None: the
        preset's value), e.g. ``preset="paper"``, ``arap_weight=1000.0``: the reference for
        each (meaning, range, the presets' values and their source) is there.

    Attributes
    ----------
    params : the checked :class:`ImplicitARAPParams`; ``preset``, ``device``, ``seed``,
    ``reference_weights`` are its fields'. info : dict, the last :meth:`deform`'s. monitor :
    None, or a callable ``(step, field)`` run after each deformation step (:func:`fit_field`).

    Raises
    ------
    SShaDeError at construction: PyTorch missing (one line: ``Implicit-ARAP needs
    PyTorch: pip install -e .[neural]``), a bad parameter (:class:`ImplicitARAPParams`),
    ``device="cuda"`` without CUDA.

    Example::

        m = ImplicitARAP(preset="cpu")
        Vd = m.deform(V, F, handles, targets)
        m.info["sdf_fit_s"], m.info["deform_s"]
    """

    def __init__(self, params: ImplicitARAPParams | Mapping | None = None, *, name: str = "Implicit-ARAP",
                 **overrides):
        require_torch()
        self.params = implicit_arap_params(params, **overrides)
        if self.params.device == "cuda" and not torch.cuda.is_available():
            raise SShaDeError("Implicit-ARAP: device=cuda but PyTorch sees no CUDA device (use auto or cpu)")
        self.name = name
        self.info: dict = {}
        #: None, or a callable ``(step, field)`` run after each deformation step
        #: (:func:`fit_field`; normalised coordinates, :func:`baselines.implicit_arap.sdf.normalisation`)
        self.monitor = None

    __signature__ = _spelled_out(__init__)  # the keywords it takes: ImplicitARAPParams' fields

    @property
    def preset(self) -> str:
        """The preset (:attr:`ImplicitARAPParams.preset`)."""
        return self.params.preset

    @property
    def device(self) -> str:
        """The device as asked (``auto``, ``cpu`` or ``cuda``; :meth:`torch_device` resolves it)."""
        return self.params.device

    @property
    def seed(self) -> int:
        """The seed (:attr:`ImplicitARAPParams.seed`)."""
        return self.params.seed

    @property
    def reference_weights(self) -> bool:
        """Whether the reference code's cotangent weights are used (:attr:`ImplicitARAPParams.reference_weights`)."""
        return self.params.reference_weights

    def effective_params(self) -> dict:
        """The parameters :meth:`deform` runs with (:meth:`ImplicitARAPParams.as_dict`):
        ``preset``, ``device`` (as asked; ``auto``: CUDA when PyTorch sees one, the case's
        ``device`` info says which), ``seed`` and every setting of :data:`PRESETS` with the
        given ones over the preset's: no None stands for a preset's value."""
        return self.params.as_dict()

    def torch_device(self) -> str:
        """The device the next :meth:`deform` runs on (``auto`` resolved)."""
        return resolve_device(self.params.device)

    def deform(self, V, F, handles, targets) -> np.ndarray:
        """Deform ``(V, F)`` so ``V[handles]`` move to ``targets`` (soft constraints, as
        in the paper); returns (n, 3) float64 in the input's units. The time includes
        the SDF fit. Raises ``SShaDeError`` on invalid mesh or handles."""
        V, F = validate_mesh(V, F)
        handles, targets = validate_handles(V, handles, targets)
        p, dev = self.params, self.torch_device()
        centre, scale = normalisation(V, F)
        X = (V - centre) * scale
        with deterministic():
            gen = torch.Generator().manual_seed(p.seed)
            rng = np.random.default_rng(p.seed)
            t0 = time.perf_counter()
            sdf, sdf_hist = fit_sdf(X, F, steps=p.sdf_steps, lr=p.sdf_lr, samples=p.sdf_samples, generator=gen,
                                    device=dev, layers=p.layers, width=p.width, skip=p.skip, octaves=p.octaves)
            t1 = time.perf_counter()
            moving = ~np.all(targets == V[handles], axis=1)
            field, hist, n_patches = fit_field(sdf, X, F, handles, (targets - centre) * scale, moving, p,
                                               generator=gen, rng=rng, monitor=self.monitor)
            t2 = time.perf_counter()
            out = apply_field(field, X, dev) / scale + centre
        self.info = {"preset": p.preset, "device": dev, "seed": p.seed, "handles": "soft",
                     "sdf_steps": p.sdf_steps,
                     "deform_steps": p.deform_steps, "lr_milestones": list(p.lr_milestones),
                     "sdf_fit_s": t1 - t0, "deform_s": t2 - t1,
                     "map_s": time.perf_counter() - t2, "sdf_loss": _tail(sdf_hist), "loss": _tail(hist),
                     "loss_first": hist[0] if hist else None, "patches_per_step": n_patches,
                     "moving_handles": int(moving.sum()), "static_handles": int((~moving).sum()),
                     "reference_weights": p.reference_weights, "threads": torch.get_num_threads()}
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

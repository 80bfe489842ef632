"""Implicit-ARAP's shape: a neural signed distance function fitted to the input mesh
(IGR loss), and the level-set tools the patch meshing uses (gradient, projection onto a
level set, sampling of the zero level set).

Source: Baieri, Maggioli, Lähner, Melzi, Rodolà 2024, "Implicit-ARAP" (reference code
github.com/dbaieri/implicit-arap, MIT licence: its ``train-sdf`` configuration), with
the loss of Gropp et al. 2020 (IGR). Our own code.

Units: every position here is in the normalised box ``[-1, 1]^3`` of
:func:`normalisation` (the mesh is centred on its area centroid and scaled so its
largest coordinate is 0.8); an SDF is any callable ``(N, 3) tensor -> (N,) tensor``.
"""
from __future__ import annotations

import numpy as np

from sshade.errors import SShaDeError

from .backend import torch
from .field import MLP

__all__ = [
    "IGR_WEIGHTS",
    "NeuralSDF",
    "SurfaceSampler",
    "fit_sdf",
    "normalisation",
    "project_to_level",
    "sample_zero_level",
    "sphere_sdf",
    "value_and_grad",
]

#: Loss weights of the SDF fit (reference ``train-sdf``): zero on the surface, eikonal,
#: normals, off-surface zero penalty (``exp(-100 |f|)``).
IGR_WEIGHTS = (3000.0, 100.0, 50.0, 3000.0)


def normalisation(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and scale of the normalised box (the reference code's ``MeshData``).

    Parameters
    ----------
    V : (n, 3) float64 positions (any units); F : (m, 3) int64 faces.

    Returns
    -------
    centre : (3,) float64, the area-weighted surface centroid (``trimesh``'s
        ``centroid``, which the reference code uses); scale : float, ``0.8 / max |V -
        centre|`` with the max over coordinates (the largest coordinate becomes 0.8).
        Normalised positions are ``(V - centre) * scale``.

    Raises
    ------
    SShaDeError on a mesh of zero extent.
    """
    T = V[F]
    area = 0.5 * np.linalg.norm(np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0]), axis=1)
    centre = (area[:, None] * T.mean(1)).sum(0) / area.sum() if area.sum() > 0 else V.mean(0)
    extent = np.abs(V - centre).max()
    if not np.isfinite(extent) or extent <= 0:
        raise SShaDeError("Implicit-ARAP: the mesh has zero extent")
    return centre, 0.8 / float(extent)


class SurfaceSampler:
    """Uniform (area-weighted) points on a triangle mesh with their face normals.

    Parameters
    ----------
    V : (n, 3) float64 normalised positions; F : (m, 3) int64 faces.
    device, dtype : of the samples.
    """

    def __init__(self, V: np.ndarray, F: np.ndarray, device="cpu", dtype=None):
        dtype = dtype or torch.float32
        T = torch.as_tensor(V[F], dtype=torch.float64)
        cross = torch.linalg.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0], dim=-1)
        area = cross.norm(dim=-1)
        self.weights = area / area.sum()
        self.normals = (cross / area.clamp_min(1e-300)[:, None]).to(device, dtype)
        self.corners = T.to(device, dtype)
        self.device, self.dtype = device, dtype

    def sample(self, n: int, generator):
        """``n`` points (n, 3) and their face normals (n, 3), drawn with the CPU
        ``generator``."""
        if n == 0:
            return self.corners[:0, 0], self.normals[:0]
        f = torch.multinomial(self.weights, n, replacement=True, generator=generator).to(self.device)
        uv = torch.rand(n, 2, generator=generator, dtype=torch.float64).to(self.device, self.dtype)
        su = uv[:, :1].sqrt()
        a, b, c = self.corners[f, 0], self.corners[f, 1], self.corners[f, 2]
        return (1 - su) * a + su * (1 - uv[:, 1:]) * b + su * uv[:, 1:] * c, self.normals[f]


class NeuralSDF:
    """A one-output :class:`baselines.implicit_arap.field.MLP` as an SDF callable,
    ``(N, 3) -> (N,)``; the constructor's keywords are the MLP's (sphere initialised)."""

    def __init__(self, **mlp_args):
        self.net = MLP(1, init="sphere", **mlp_args)

    def parameters(self) -> list:
        """The trainable tensors."""
        return self.net.parameters()

    def __call__(self, x):
        """(N, 3) -> (N,) signed distances (normalised units)."""
        return self.net(x)[:, 0]


def value_and_grad(sdf, x, create_graph: bool = False):
    """``f(x)`` (N,) and ``grad f(x)`` (N, 3) by automatic differentiation; with
    ``create_graph`` both stay differentiable in the SDF's parameters."""
    with torch.enable_grad():
        x = x.detach().requires_grad_(True)
        f = sdf(x)
        g, = torch.autograd.grad(f.sum(), x, create_graph=create_graph)
    return (f, g) if create_graph else (f.detach(), g.detach())


def fit_sdf(V: np.ndarray, F: np.ndarray, *, steps: int, lr: float, samples: int, generator, device="cpu",
            dtype=None, **mlp_args):
    """Fit a :class:`NeuralSDF` to a mesh with the IGR loss (Baieri et al. 2024,
    reference ``train-sdf``; Gropp et al. 2020).

    Each Adam step draws ``samples`` surface points ``x_s`` (face normals ``n_s``) and
    ``samples`` uniform points ``x_u`` of ``[-1, 1]^3`` and minimises
    ``3000 |f(x_s)| + 100 | |grad f| - 1 | + 50 (1 - cos(grad f(x_s), n_s))
    + 3000 exp(-100 |f(x_u)|)`` (means; the eikonal term over both sets).

    Parameters
    ----------
    V : (n, 3) float64 normalised positions; F : (m, 3) int64 faces.
    steps : int >= 0; lr : float, Adam's learning rate; samples : int >= 1.
    generator : CPU torch.Generator (initial weights and every draw).
    device, dtype : where the network is trained.
    **mlp_args : ``layers``, ``width``, ``skip``, ``octaves`` of the network.

    Returns
    -------
    (NeuralSDF with its parameters frozen, list of the loss per step).
    """
    sdf = NeuralSDF(generator=generator, device=device, dtype=dtype, **mlp_args)
    sampler = SurfaceSampler(V, F, device, dtype)
    opt = torch.optim.Adam(sdf.parameters(), lr=lr)
    w0, w1, w2, w3 = IGR_WEIGHTS
    history = []
    for _ in range(steps):
        xs, ns = sampler.sample(samples, generator)
        xu = (2 * torch.rand(samples, 3, generator=generator, dtype=torch.float64) - 1).to(device, sampler.dtype)
        f, g = value_and_grad(sdf, torch.cat([xs, xu]), create_graph=True)
        fs, fu, gs = f[:samples], f[samples:], g[:samples]
        loss = (w0 * fs.abs().mean() + w1 * (g.norm(dim=-1) - 1).abs().mean()
                + w2 * (1 - torch.nn.functional.cosine_similarity(gs, ns, dim=-1)).mean()
                + w3 * torch.exp(-100.0 * fu.abs()).mean())
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        history.append(float(loss.detach()))
    sdf.net.freeze()
    return sdf, history


def sphere_sdf(radius: float = 0.5, centre=(0.0, 0.0, 0.0)):
    """The analytic SDF of a sphere (tests, and a stand-in for a fitted one):
    ``x -> |x - centre| - radius``, (N, 3) -> (N,)."""
    def f(x):
        return (x - torch.as_tensor(centre, dtype=x.dtype, device=x.device)).norm(dim=-1) - radius
    return f


def project_to_level(sdf, x, level, iters: int):
    """Newton steps ``x <- x - (f(x) - level) grad f / |grad f|^2`` onto level sets.

    Parameters
    ----------
    x : (N, 3) tensor; level : (N,) tensor, each point's target value; iters : int >= 0.

    Returns
    -------
    (N, 3) tensor, detached.
    """
    x = x.detach()
    for _ in range(iters):
        f, g = value_and_grad(sdf, x)
        x = x - ((f - level) / (g * g).sum(-1).clamp_min(1e-12))[:, None] * g
    return x


def sample_zero_level(sdf, n: int, *, threshold: float, iters: int, generator, device="cpu", dtype=None,
                      batch: int = 10000, max_rounds: int = 100):
    """``n`` points on the zero level set: uniform points of ``[-1, 1]^3`` with
    ``|f| < threshold`` (rejection, batches of ``batch``), then :func:`project_to_level`
    ``iters`` times.

    Returns
    -------
    (k, 3) tensor with ``k <= n`` (fewer only when ``max_rounds`` batches do not find
    ``n``; none for an SDF without a zero level set in the box).
    """
    dtype = dtype or torch.float32
    found, count = [], 0
    with torch.no_grad():
        for _ in range(max_rounds if n > 0 else 0):
            u = (2 * torch.rand(batch, 3, generator=generator, dtype=torch.float64) - 1).to(device, dtype)
            keep = u[sdf(u).abs() < threshold]
            found.append(keep)
            count += len(keep)
            if count >= n:
                break
    x = torch.cat(found)[:n] if found else torch.zeros(0, 3, device=device, dtype=dtype)
    return project_to_level(sdf, x, torch.zeros(len(x), device=device, dtype=dtype), iters)


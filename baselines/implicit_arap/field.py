"""The two networks of Implicit-ARAP (Baieri et al. 2024): a neural signed distance function
of the input shape and a neural deformation field (a rotation and a translation per point).

The network is IGR's (Gropp et al. 2020, "Implicit geometric regularization for learning
shapes"): positional encoding, Softplus(beta=100), weight normalisation, the input
concatenated again at one layer, geometric (sphere) initialisation. Our own code. The
networks are plain parameter lists and functions (no ``torch.nn.Module``), so this module
imports without PyTorch (:mod:`baselines.implicit_arap.backend`); positions are in the
normalised box of :func:`baselines.implicit_arap.sdf.normalisation`.
"""
from __future__ import annotations

import math

from sshade.errors import SShaDeError

from .backend import torch

__all__ = ["MLP", "DeformationField", "encode", "rodrigues"]


def encode(x, octaves: int):
    """Positional encoding ``[x, sin(2 pi 2^k x), cos(2 pi 2^k x)]``, ``k < octaves``.

    Parameters
    ----------
    x : (..., 3) tensor, normalised positions.
    octaves : int >= 0.

    Returns
    -------
    (..., 3 + 6 octaves) tensor (39 columns for 6 octaves), raw ``x`` first.
    """
    if octaves == 0:
        return x
    freqs = (2.0 * math.pi) * 2.0 ** torch.arange(octaves, device=x.device, dtype=x.dtype)
    s = (x[..., :, None] * freqs).flatten(-2)
    return torch.cat([x, torch.sin(s), torch.cos(s)], dim=-1)


class MLP:
    """IGR-style multilayer perceptron on encoded positions (Gropp et al. 2020, as used
    by Baieri et al. 2024).

    Parameters
    ----------
    n_out : int, outputs (1: a distance; 6: a rotation vector and a translation).
    layers : int >= 2, linear layers (the last one is the output layer).
    width : int >= 1, hidden width.
    skip : int, the layer whose input is ``[encoded input, hidden]`` (0: none); must
        be a hidden layer, ``1 <= skip <= layers - 2``.
    octaves : int >= 0, positional encoding octaves (:func:`encode`).
    init : ``"sphere"``: geometric initialisation, the output approximates the signed
        distance of a sphere of ``radius`` around the origin, every layer weight
        normalised; ``"zero"``: the same hidden layers, the output layer zero and not
        normalised (the network starts at exactly 0).
    radius : float, sphere radius of ``init="sphere"`` (normalised units).
    generator : torch.Generator on the CPU (the draws are made there, then moved, so a
        seed gives the same weights on every device).
    device, dtype : where the parameters live.

    Raises
    ------
    SShaDeError on a bad ``layers`` / ``width`` / ``skip`` / ``init``.
    """

    def __init__(self, n_out: int, *, layers: int, width: int, skip: int, octaves: int, init: str = "sphere",
                 radius: float = 0.5, generator=None, device="cpu", dtype=None):
        if layers < 2 or width < 1:
            raise SShaDeError(f"Implicit-ARAP: layers must be >= 2 and width >= 1, got {layers}, {width}")
        if skip and not 1 <= skip <= layers - 2:
            raise SShaDeError(f"Implicit-ARAP: skip must be 0 or a hidden layer in [1, {layers - 2}], got {skip}")
        if init not in ("sphere", "zero"):
            raise SShaDeError(f"Implicit-ARAP: init must be 'sphere' or 'zero', got {init!r}")
        self.octaves, self.skip, self.n_out = int(octaves), int(skip), int(n_out)
        self.n_in = 3 + 6 * self.octaves
        dtype = dtype or torch.float32
        self.layers = []
        for j in range(layers):
            fan_in = self.n_in if j == 0 else width + (self.n_in if j == self.skip and j else 0)
            fan_out = n_out if j == layers - 1 else width
            W, b = self._init_layer(j, layers, fan_in, fan_out, init, radius, generator)
            normed = not (j == layers - 1 and init == "zero")
            layer = {"v": W, "b": b}
            if normed:
                layer["g"] = W.norm(dim=1, keepdim=True)
            self.layers.append({k: t.to(device=device, dtype=dtype).requires_grad_() for k, t in layer.items()})

    def _init_layer(self, j, layers, fan_in, fan_out, init, radius, generator):
        """Geometric initialisation of layer ``j`` (Atzmon & Lipman 2020, the encoded
        variant of the reference code): (fan_out, fan_in) weights and (fan_out,) bias."""
        std = math.sqrt(2.0) / math.sqrt(fan_out)
        b = torch.zeros(fan_out, dtype=torch.float64)
        if j == layers - 1:
            if init == "zero":
                return torch.zeros(fan_out, fan_in, dtype=torch.float64), b
            W = math.sqrt(math.pi) / math.sqrt(fan_in) + 1e-4 * torch.randn(
                fan_out, fan_in, generator=generator, dtype=torch.float64)
            return W, b - radius
        W = std * torch.randn(fan_out, fan_in, generator=generator, dtype=torch.float64)
        if j == 0:
            W[:, 3:] = 0.0  # the encoding starts switched off: the first layer sees x only
        elif j == self.skip:
            W[:, 3:self.n_in] = 0.0  # the re-injected input: x only as well
        return W, b

    def parameters(self) -> list:
        """The trainable tensors (weight directions, gains, biases)."""
        return [t for layer in self.layers for t in layer.values()]

    def freeze(self) -> MLP:
        """Stop tracking gradients of the parameters (the fitted SDF during the
        deformation); returns self."""
        for t in self.parameters():
            t.requires_grad_(False)
        return self

    def __call__(self, x):
        """(N, 3) positions -> (N, n_out) outputs."""
        h0 = encode(x, self.octaves)
        h = h0
        last = len(self.layers) - 1
        for j, layer in enumerate(self.layers):
            if j == self.skip and j:
                h = torch.cat([h0, h], dim=-1)
            W = layer["v"]
            if "g" in layer:
                W = layer["g"] * W / W.norm(dim=1, keepdim=True)
            h = torch.nn.functional.linear(h, W, layer["b"])
            if j < last:
                h = torch.nn.functional.softplus(h, beta=100.0)
        return h


def rodrigues(w):
    """Rotation matrices from rotation vectors (axis times angle in radians).

    ``R = I + A [w]x + B [w]x^2`` with ``A = sin t / t``, ``B = (1 - cos t) / t^2``,
    ``t = |w|``, by their Taylor series below ``t = 1e-3`` (finite gradients at 0).

    Parameters
    ----------
    w : (N, 3) tensor.

    Returns
    -------
    (N, 3, 3) tensor.
    """
    t2 = (w * w).sum(-1)
    small = t2 < 1e-6
    t2s = torch.where(small, torch.ones_like(t2), t2)
    ts = torch.sqrt(t2s)
    A = torch.where(small, 1.0 - t2 / 6.0, torch.sin(ts) / ts)
    B = torch.where(small, 0.5 - t2 / 24.0, (1.0 - torch.cos(ts)) / t2s)
    z = torch.zeros_like(w[:, 0])
    K = torch.stack([z, -w[:, 2], w[:, 1], w[:, 2], z, -w[:, 0], -w[:, 1], w[:, 0], z], -1).view(-1, 3, 3)
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand_as(K)
    return eye + A[:, None, None] * K + B[:, None, None] * (K @ K)


class DeformationField:
    """``T(x) = R(x) x + t(x)``: an :class:`MLP` with 6 outputs, a rotation vector
    (:func:`rodrigues`) and a translation, its output layer zero so ``T`` starts as the
    identity (Baieri et al. 2024, §4; the reference code parametrises ``R`` by Euler
    angles and applies the inverse map, we use the rotation vector and the forward map).

    Parameters
    ----------
    Those of :class:`MLP` but ``n_out`` and ``init``.
    """

    def __init__(self, *, layers: int, width: int, skip: int, octaves: int, generator=None, device="cpu",
                 dtype=None):
        self.net = MLP(6, layers=layers, width=width, skip=skip, octaves=octaves, init="zero",
                       generator=generator, device=device, dtype=dtype)

    def parameters(self) -> list:
        """The trainable tensors."""
        return self.net.parameters()

    def rotation_translation(self, x):
        """(N, 3) positions -> ``R`` (N, 3, 3), ``t`` (N, 3)."""
        out = self.net(x)
        return rodrigues(out[:, :3]), out[:, 3:]

    def __call__(self, x):
        """(N, 3) positions -> (N, 3) ``T(x)``."""
        R, t = self.rotation_translation(x)
        return (R @ x[:, :, None])[:, :, 0] + t

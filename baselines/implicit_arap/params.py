"""Implicit-ARAP's parameters as one checked, frozen object.

:class:`ImplicitARAPParams` states each parameter once (its meaning, range, value and
where the value comes from) and checks them all when built; :data:`PRESETS` holds the
presets' values, which a field left None takes. :func:`implicit_arap_params` builds one
from another or a mapping and keyword overrides, as
:class:`baselines.implicit_arap.ImplicitARAP` takes them (``params=None, **overrides``).
Imports without PyTorch.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from sshade.errors import SShaDeError

__all__ = ["PRESETS", "STIFF_STEPS", "DEVICES", "CENTRES", "SETTINGS", "ImplicitARAPParams", "implicit_arap_params"]

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
#: The fields a preset sets (every field but ``preset``, ``device`` and ``seed``).
SETTINGS = tuple(PRESETS["paper"])
#: ``device``'s values; ``auto``: CUDA when PyTorch sees one.
DEVICES = ("auto", "cpu", "cuda")
#: ``centres``' values.
CENTRES = ("mesh", "rejection")
_INTS = {"layers": 2, "width": 1, "skip": 0, "octaves": 0, "sdf_steps": 0, "sdf_samples": 1, "deform_steps": 0,
         "surface_patches": 0, "handle_patches": 0, "space_patches": 0, "patch_points": 4, "projections": 0}
_FLOATS = ("sdf_lr", "deform_lr", "patch_radius", "level_threshold", "arap_weight", "handle_weight", "lr_gamma")


@dataclass(frozen=True)
class ImplicitARAPParams:
    """Implicit-ARAP's checked parameters (Baieri et al. 2024; reference code
    github.com/dbaieri/implicit-arap): the reference for each one.

    A setting left None takes its ``preset``'s value (:data:`PRESETS`) when the object is
    built, so every field of a built object holds a value; to change the preset build a
    new object (:meth:`replace` refuses it: the other fields hold the old preset's values).
    Lengths are in the normalised box (:func:`baselines.implicit_arap.sdf.normalisation`).
    Each setting's values are given as ``paper`` preset (the reference code's at fa0cb78,
    GPU-sized) / ``cpu`` preset (the default); ``cpu_soft`` is ``cpu`` but for
    ``arap_weight`` and ``deform_steps``.

    Parameters
    ----------
    preset : one of :data:`PRESETS`, default ``"cpu"``
        ``"cpu"`` (minutes per case on 2 cores, ARAP term at least as stiff as the
        reference's), ``"cpu_soft"`` (ARAP weight 10 with correct weights, 500 steps) or
        ``"paper"`` (the reference configuration: 8 x 256 networks, 10,000 SDF steps,
        1,000 deformation steps, 2,000 patches of 30 points per step; sized for a GPU).
    device : one of :data:`DEVICES`, default ``"auto"``
        ``"auto"`` (CUDA when PyTorch sees one), ``"cpu"`` or ``"cuda"``.
    seed : int >= 0, default 0
        Seeds every draw (torch and numpy): the same seed on the same device and thread
        count gives bit-identical output.
    layers : int >= 2; paper 8 / cpu 4
        Linear layers of both networks (the SDF and the deformation field).
    width : int >= 1; paper 256 / cpu 128
        Hidden width of both networks.
    skip : int, 0 or in [1, layers - 2]; paper 4 / cpu 2
        The hidden layer that sees the encoded input again (0: none).
    octaves : int >= 0; 6 (the reference's)
        Positional-encoding octaves (6: x plus sin/cos at 6 octaves, 39 inputs).
    sdf_steps : int >= 0; paper 10000 / cpu 1000
        Adam steps of the SDF fit.
    sdf_lr : float > 0; paper 1e-4 / cpu 5e-4
        Learning rate of the SDF fit.
    sdf_samples : int >= 1; paper 16384 / cpu 2048
        Surface samples and uniform box samples per SDF step, each.
    deform_steps : int >= 0; paper 1000 / cpu 1500 (:data:`STIFF_STEPS`) / cpu_soft 500
        Adam steps of the deformation field.
    deform_lr : float > 0; 1e-3 (the reference's)
        Initial learning rate of the deformation field.
    surface_patches : int >= 0; paper 1000 / cpu 256
        Zero-level patch centres per step, the handle centres included.
    handle_patches : int >= 0; paper 0 / cpu 128
        At most this many handle centres per step, a random such subset when there are
        more; 0: every handle at every step (the reference).
    space_patches : int >= 0; paper 1000 / cpu 128
        Uniform patch centres in ``[-1, 1]^3`` per step.
    patch_points : int >= 4; paper 30 / cpu 16
        Points per patch disk.
    patch_radius : float > 0; sqrt(1e-3) (the reference's)
        Radius of a patch disk, in normalised units.
    projections : int >= 0; paper 5 / cpu 2
        Projections onto a level set (each patch onto its centre's; the zero-level centres).
    level_threshold : float > 0; 0.01 (the reference's)
        ``|f|`` below which a box sample is a zero-level point (``centres="rejection"``).
    centres : one of :data:`CENTRES`; paper ``"rejection"`` / cpu ``"mesh"``
        The zero-level centres: the reference's rejection sampling in the box, or points
        drawn on the mesh and projected onto the zero level set.
    arap_weight : float >= 0; paper 1000 (the reference at the paper's time) / cpu 120 / cpu_soft 10
        Weight of the patch ARAP energy in the loss.
    handle_weight : float > 0; 1000 (the reference's)
        Weight of each handle MSE (the moving handles', the static handles').
    reference_weights : bool; paper True / cpu False
        The reference code's cotangent weights (wrong edges, overwritten repeats;
        :mod:`baselines.implicit_arap.patches`, docs/methods.md) instead of the correct ones.
    lr_milestones : tuple of increasing ints >= 1 (any sequence); (1000, 2000, 5000) (the reference's)
        Deformation steps at which the rate is multiplied by ``lr_gamma`` (MultiStepLR).
    lr_gamma : float > 0; 0.5 (the reference's)
        The rate's factor at each milestone.

    Raises
    ------
    SShaDeError naming the first bad parameter and its value: an unknown preset, device or
    centres, an integer below its minimum (a bool is none), a float that is not finite and
    > 0 (``arap_weight`` may be 0), ``reference_weights`` not a bool, milestones not
    increasing integers >= 1.

    Examples
    --------
    >>> p = ImplicitARAPParams(preset="paper", arap_weight=10)
    >>> p.arap_weight, p.layers, p.reference_weights
    (10.0, 8, True)
    >>> ImplicitARAPParams(patch_points=3)
    Traceback (most recent call last):
    ...
    sshade.errors.SShaDeError: Implicit-ARAP: patch_points must be an integer >= 4, got 3
    """

    preset: str = "cpu"
    device: str = "auto"
    seed: int = 0
    layers: int | None = None
    width: int | None = None
    skip: int | None = None
    octaves: int | None = None
    sdf_steps: int | None = None
    sdf_lr: float | None = None
    sdf_samples: int | None = None
    deform_steps: int | None = None
    deform_lr: float | None = None
    surface_patches: int | None = None
    handle_patches: int | None = None
    space_patches: int | None = None
    patch_points: int | None = None
    patch_radius: float | None = None
    projections: int | None = None
    level_threshold: float | None = None
    centres: str | None = None
    arap_weight: float | None = None
    handle_weight: float | None = None
    reference_weights: bool | None = None
    lr_milestones: tuple[int, ...] | None = None
    lr_gamma: float | None = None

    def __post_init__(self):
        preset = str(self.preset)
        if preset not in PRESETS:
            raise SShaDeError(f"Implicit-ARAP: unknown preset {preset!r}; use one of {sorted(PRESETS)}")
        given = {k: getattr(self, k) for k in SETTINGS}
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
            raise SShaDeError(f"Implicit-ARAP: skip must be 0 or in [1, layers - 2 = {s['layers'] - 2}], "
                              f"got {s['skip']}")
        if s["centres"] not in CENTRES:
            raise SShaDeError(f"Implicit-ARAP: centres must be 'mesh' or 'rejection', got {s['centres']!r}")
        if not isinstance(s["reference_weights"], (bool, np.bool_)):
            raise SShaDeError(f"Implicit-ARAP: reference_weights must be true or false, got {s['reference_weights']!r}")
        s["reference_weights"] = bool(s["reference_weights"])
        s["lr_milestones"] = _milestones(s["lr_milestones"])
        if self.device not in DEVICES:
            raise SShaDeError(f"Implicit-ARAP: device must be auto, cpu or cuda, got {self.device!r}")
        seed = self.seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise SShaDeError(f"Implicit-ARAP: seed must be an integer >= 0, got {seed!r}")
        for k, v in {"preset": preset, "seed": int(seed), **s}.items():
            object.__setattr__(self, k, v)  # frozen: the checked values, set once here

    def as_dict(self) -> dict:
        """The parameters as a plain dict, in the fields' order (``preset``, ``device``,
        ``seed``, then :data:`SETTINGS`)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def replace(self, **changes) -> ImplicitARAPParams:
        """A copy with ``changes`` (fields; None: the preset's value), checked again.

        Raises
        ------
        SShaDeError: a name that is no field, another ``preset`` (its values would mix
        with the old preset's: build ``ImplicitARAPParams(preset=...)``), a bad value.
        """
        _known(changes)
        if "preset" in changes and str(changes["preset"]) != self.preset:
            raise SShaDeError(f"Implicit-ARAP: preset {changes['preset']!r} over parameters of preset "
                              f"{self.preset!r}: give the preset with the other parameters, not over them")
        return dataclasses.replace(self, **changes)


_FIELDS = tuple(f.name for f in fields(ImplicitARAPParams))


def _known(names) -> None:
    """SShaDeError naming the first of ``names`` that is not a field of :class:`ImplicitARAPParams`."""
    unknown = [k for k in names if k not in _FIELDS]
    if unknown:
        raise SShaDeError(f"Implicit-ARAP: no parameter {unknown[0]!r} (its parameters: {', '.join(_FIELDS)})")


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


def implicit_arap_params(params: ImplicitARAPParams | Mapping | None = None, /, **overrides) -> ImplicitARAPParams:
    """Implicit-ARAP's parameters from ``params`` with keyword ``overrides`` over them.

    Parameters
    ----------
    params : :class:`ImplicitARAPParams`, a mapping of some of its fields, or None (its
        defaults).
    **overrides : fields of :class:`ImplicitARAPParams` (None: the preset's value).

    Returns
    -------
    :class:`ImplicitARAPParams` (``params`` itself when there are no overrides).

    Raises
    ------
    SShaDeError: ``params`` of another type, a name that is no field, a ``preset`` over an
    :class:`ImplicitARAPParams` of another preset (:meth:`ImplicitARAPParams.replace`), a
    bad value.

    Examples
    --------
    >>> implicit_arap_params({"preset": "cpu_soft"}, seed=2).deform_steps
    500
    """
    if isinstance(params, ImplicitARAPParams):
        return params.replace(**overrides) if overrides else params
    if params is not None and not isinstance(params, Mapping):
        raise SShaDeError("Implicit-ARAP: params must be ImplicitARAPParams or a mapping of its fields, "
                          f"got {type(params).__name__}")
    given = {**(params or {}), **overrides}
    _known(given)
    return ImplicitARAPParams(**given)

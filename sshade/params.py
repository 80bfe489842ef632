"""SShaDe's parameters as one checked, frozen object (paper §3, §4.1 settings).

:class:`SShaDeParams` states each parameter once: its meaning, its range and its default
(its fields'); :func:`check_params` checks and normalises a mapping and keyword overrides
into one, which :mod:`sshade.pipeline`, :mod:`sshade.prepared`, :mod:`sshade.isometric`
and :mod:`sshade.refine` pass around; their functions take ``params=None, **overrides``
and list the parameters in their help (:func:`document_params`). :func:`effective_params`
resolves its defaults for run records.
"""
from __future__ import annotations

import inspect
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, fields

import numpy as np

from .arap import DEFAULT_MAX_ITER, DEFORM_ENERGIES, PROTOCOLS, ArapOptions, make_criterion
from .averaging import AVERAGES
from .cores import pool_size
from .errors import SShaDeError
from .lrf import ANCHORS, GRADIENTS
from .smooth_transfer import TRANSFERS

__all__ = ["SShaDeParams", "check_params", "effective_params", "document_params", "only_params", "params_signature",
           "MAX_SEED", "MIN_N_LOW"]

_MAX_COUNT = 2**31 - 1    # n_low, workers, max_iter: int32 range (numba kernels, libigl)
MIN_N_LOW = 4             #: the smallest n_low check_params accepts
_MAX_SAMPLINGS = 10_000   # k remeshings, each a full low-res solve
MAX_SEED = 2**63 - 1      #: seeds: int64, recorded in JSON/CSV and passed to numpy


@dataclass(frozen=True, eq=False)
class SShaDeParams(Mapping):
    """SShaDe's checked parameters; made by :func:`check_params`, never by hand. The
    reference for each parameter (its meaning, range and default, the field's).

    Parameters
    ----------
    n_low : int in [4, 2**31 - 1] or ``"auto"`` (None too), default 6000
        Farthest-point samples per low-res mesh (paper: ~6000 for 150k-200k vertices),
        capped at the vertex count; the handles are added to them. ``"auto"``:
        :func:`sshade.pipeline.auto_n_low`.
    n_samplings : int in [1, 10000], default 5
        k samplings with different first seeds, averaged (paper: 5-10).
    seed : int in [0, 2**63 - 1], default 0
        Master seed; sampling i uses ``sampling_seeds(seed, k)[i]``.
    workers : int >= 1 or None, default None
        Processes (threads for :func:`sshade.prepared.prepare`; None: min(k, the cores
        this process may use)); 1 runs in-process. The result does not depend on it.
    max_iter : int >= 1 or None, default None
        Cap on the low-res ARAP's iterations (None: the protocol's).
    tol : float > 0, default 1e-4
        Under ``protocol="paper"``: stop when the largest move of one iteration is
        below ``tol * bbox_diag`` (libigl's rule).
    gradient : one of :data:`sshade.lrf.GRADIENTS`, default ``"normalized"``
        ``"normalized"`` (orthonormal LRF) or ``"raw"`` (the paper's g_t, §3.2).
    anchor : one of :data:`sshade.lrf.ANCHORS`, default ``"projection"``
        Where a vertex is anchored in its triangle: ``"projection"`` or ``"barycenter"``
        (paper Alg. 1) (:mod:`sshade.lrf`).
    warm_start : bool, default True
        Start samplings 1..k-1 from sampling 0's result.
    protocol : one of :data:`sshade.arap.PROTOCOLS`, default ``"converged"``
        The low-res ARAP's (:func:`sshade.arap.arap_deform`): ``"converged"`` (stopped by
        the criterion of thresholds ``etol``/``gtol``) or ``"paper"`` (libigl's move rule, ``tol``).
    etol, gtol : float >= 0 or None, default None
        The converged protocol's energy and gradient thresholds (None: its defaults,
        :func:`sshade.arap.make_criterion`).
    energy : one of :data:`sshade.arap.DEFORM_ENERGIES`, default ``"spokes_and_rims"``
        The low-res ARAP's: ``"spokes_and_rims"`` (paper §4.1), ``"spokes"`` (Sorkine &
        Alexa 2007) or ``"arap_sr"`` (smooth rotations, Levi & Gotsman 2015, at the
        ARAP-SR baseline's default alpha, :data:`sshade.arap.DEFAULT_ALPHA` times the
        low-res mesh's area, as Open3D defines it).
    transfer : one of :data:`sshade.smooth_transfer.TRANSFERS`, default ``"vertex"``
        ``"vertex"`` (the corners' deformation gradients blended,
        :mod:`sshade.smooth_transfer`) or ``"triangle"`` (one frame per triangle, Alg. 1).
    average : one of :data:`sshade.averaging.AVERAGES`, default ``"uniform"``
        How the samplings are averaged: ``"uniform"`` (the paper's mean, §3.3),
        ``"proximity"`` (each sampling weighted at a vertex by the inverse second moment
        about its low-res triangle's corners: for exact low-res positions) or ``"distortion"``.

    Notes
    -----
    A read-only mapping of the same keys too (``p["n_low"]``, ``dict(p)``, ``**p``);
    :meth:`as_dict` is the plain dict for JSON and run records.
    """

    n_low: int | str = 6000
    n_samplings: int = 5
    seed: int = 0
    workers: int | None = None
    max_iter: int | None = None
    tol: float = 1e-4
    gradient: str = "normalized"
    anchor: str = "projection"
    warm_start: bool = True
    protocol: str = "converged"
    etol: float | None = None
    gtol: float | None = None
    energy: str = "spokes_and_rims"
    transfer: str = "vertex"
    average: str = "uniform"

    def __getitem__(self, key: str):
        if key not in _FIELDS:
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(_FIELDS)

    def __len__(self) -> int:
        return len(_FIELDS)

    def __hash__(self) -> int:
        return hash(tuple(self.values()))

    def as_dict(self) -> dict:
        """The parameters as a plain dict, keys in :func:`check_params`' order."""
        return {k: getattr(self, k) for k in _FIELDS}

    def replace(self, **changes) -> SShaDeParams:
        """A copy with ``changes`` (keyword parameters of :func:`check_params`), checked
        again. Raises SShaDeError as :func:`check_params`."""
        return check_params(self, **changes)

    def arap_options(self) -> ArapOptions:
        """The low-res step's options for :func:`sshade.arap.arap_deform`
        (:class:`sshade.arap.ArapOptions`): ``energy``, ``protocol``, ``max_iter``, the
        criterion of ``etol`` / ``gtol`` (:func:`sshade.arap.make_criterion`; under the
        paper protocol its ``gtol`` tells converged from stalled) and, under the paper
        protocol, the move rule's ``tol``."""
        paper = {"tol": self.tol} if self.protocol == "paper" else {}
        return ArapOptions(energy=self.energy, protocol=self.protocol, max_iter=self.max_iter,
                           criterion=make_criterion(self.etol, self.gtol), **paper)


_FIELDS = tuple(f.name for f in fields(SShaDeParams))
_DEFAULTS = {f.name: f.default for f in fields(SShaDeParams)}


def _as_int(name: str, v, lo: int, hi: int = _MAX_COUNT) -> int:
    """``v`` as an int in [lo, hi] (an integral float or numeric string allowed, a bool
    never); SShaDeError naming ``name`` otherwise."""
    if isinstance(v, (bool, np.bool_)):
        raise SShaDeError(f"SShaDe: {name} must be an integer, got {v!r}")
    try:
        iv = int(v)
    except (TypeError, ValueError, OverflowError):  # OverflowError: inf
        raise SShaDeError(f"SShaDe: {name} must be an integer, got {v!r}") from None
    if iv != v and not (isinstance(v, str) and str(iv) == v.strip()):
        raise SShaDeError(f"SShaDe: {name} must be an integer, got {v!r}")
    if iv < lo:
        extra = " (or 'auto')" if name == "n_low" else ""
        raise SShaDeError(f"SShaDe: {name} must be at least {lo}{extra}, got {v!r}")
    if iv > hi:
        raise SShaDeError(f"SShaDe: {name} must be at most {hi}, got {v!r}")
    return iv


def _as_tolerance(name: str, v) -> float | None:
    """``v`` (etol or gtol) as a finite float >= 0, or None; SShaDeError otherwise."""
    if v is None:
        return None
    try:
        fv = float(v)
    except (TypeError, ValueError):
        raise SShaDeError(f"SShaDe: {name} must be a number >= 0, got {v!r}") from None
    if isinstance(v, (bool, np.bool_)) or not (fv >= 0 and np.isfinite(fv)):
        raise SShaDeError(f"SShaDe: {name} must be a finite number >= 0, got {v!r}")
    return fv


def check_params(params: Mapping | None = None, /, **overrides) -> SShaDeParams:
    """Validate SShaDe's parameters without touching a mesh, so a bad value fails before
    any work.

    Parameters
    ----------
    params : :class:`SShaDeParams` or a mapping of some of its keys, or None
        The values to start from; the rest are :class:`SShaDeParams`' defaults.
    **overrides : any of :class:`SShaDeParams`' parameters (ranges there), over ``params``.
        An integer may be given as an integral float (``1e3``) or a numeric string but
        never as a bool, NaN, inf or a float beyond the range.

    Returns
    -------
    :class:`SShaDeParams`, normalised (ints as int, ``n_low`` as int or ``"auto"``).

    Raises
    ------
    SShaDeError naming the first bad parameter and its value, or a name that is none of
    SShaDe's (never OverflowError or TypeError).

    Examples
    --------
    >>> check_params(n_low=6000).n_low
    6000
    >>> check_params(check_params(seed=3), n_samplings=2).seed
    3
    >>> check_params(n_low=2)
    Traceback (most recent call last):
    ...
    sshade.errors.SShaDeError: SShaDe: n_low must be at least 4 (or 'auto'), got 2
    """
    if params is not None and not isinstance(params, Mapping):
        raise SShaDeError(f"SShaDe: params must be SShaDeParams or a mapping of its keys, got {type(params).__name__}")
    raw = {**_DEFAULTS, **(params or {}), **overrides}
    unknown = [k for k in raw if k not in _DEFAULTS]
    if unknown:
        raise SShaDeError(f"SShaDe: no parameter {unknown[0]!r} (its parameters: {', '.join(_FIELDS)})")
    return _checked(**raw)


def _checked(*, n_low, n_samplings, seed, workers, tol, max_iter, gradient, warm_start, protocol, etol, gtol,
             anchor, energy, transfer, average) -> SShaDeParams:
    """:func:`check_params` on every value given."""
    out = {"n_low": "auto" if n_low in (None, "auto") else _as_int("n_low", n_low, MIN_N_LOW),
           "n_samplings": _as_int("n_samplings", n_samplings, 1, _MAX_SAMPLINGS),
           "seed": _as_int("seed", seed, 0, MAX_SEED),
           "workers": None if workers is None else _as_int("workers", workers, 1),
           "max_iter": None if max_iter is None else _as_int("max_iter", max_iter, 1)}
    try:
        out["tol"] = float(tol)
    except (TypeError, ValueError):
        raise SShaDeError(f"SShaDe: tol must be a number, got {tol!r}") from None
    if isinstance(tol, (bool, np.bool_)) or not out["tol"] > 0 or not np.isfinite(out["tol"]):
        raise SShaDeError(f"SShaDe: tol must be a finite number > 0, got {tol!r}")
    if not isinstance(warm_start, (bool, np.bool_)):
        raise SShaDeError(f"SShaDe: warm_start must be true or false, got {warm_start!r}")
    if gradient not in GRADIENTS:
        raise SShaDeError(f"SShaDe: unknown gradient mode {gradient!r}; use one of {GRADIENTS}")
    if anchor not in ANCHORS:
        raise SShaDeError(f"SShaDe: unknown anchor {anchor!r}; use one of {ANCHORS}")
    if protocol not in PROTOCOLS:
        raise SShaDeError(f"SShaDe: unknown ARAP protocol {protocol!r}; use one of {PROTOCOLS}")
    if not isinstance(energy, str) or energy not in DEFORM_ENERGIES:
        raise SShaDeError(f"SShaDe: unknown low-res energy {energy!r}; use one of {DEFORM_ENERGIES}")
    if not isinstance(transfer, str) or transfer not in TRANSFERS:
        raise SShaDeError(f"SShaDe: unknown transfer {transfer!r}; use one of {TRANSFERS}")
    if not isinstance(average, str) or average not in AVERAGES:
        raise SShaDeError(f"SShaDe: unknown average {average!r}; use one of {AVERAGES}")
    return SShaDeParams(**out, gradient=gradient, anchor=anchor, warm_start=bool(warm_start), protocol=protocol,
                        etol=_as_tolerance("etol", etol), gtol=_as_tolerance("gtol", gtol), energy=energy,
                        transfer=transfer, average=average)


def only_params(where: str, overrides: Mapping, keys) -> dict:
    """``overrides`` when every key is one of ``keys`` (the parameters the function
    ``where`` uses); SShaDeError naming the first other one."""
    other = [k for k in overrides if k not in keys]
    if other:
        raise SShaDeError(f"{where}: no parameter {other[0]!r} (its parameters: {', '.join(keys)})")
    return dict(overrides)


def params_signature(fn: Callable) -> inspect.Signature:
    """The signature of ``fn`` (which takes ``**overrides`` for :class:`SShaDeParams`) with
    the overrides spelled out as keyword-only parameters, their defaults the fields', so
    that introspection (a plug-in builder asking whether ``name`` is a parameter, an
    editor) sees the keywords ``fn`` accepts; set as a class's ``__signature__``."""
    sig = inspect.signature(fn)
    head = [p for p in sig.parameters.values() if p.kind is not p.VAR_KEYWORD and p.name != "self"]
    tail = [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default) for f in fields(SShaDeParams)
            if f.name not in {p.name for p in head}]
    return sig.replace(parameters=[*head, *tail])


def document_params(fn: Callable) -> Callable:
    """``fn`` with the line ``{sshade_params}`` of its docstring replaced by
    :class:`SShaDeParams`' parameter list, so that ``help(fn)`` lists each parameter
    while its text lives once, there. Returns ``fn``."""
    doc = SShaDeParams.__doc__ or ""
    block = doc[doc.index("    n_low :"):doc.index("\n\n    Notes\n")]
    if fn.__doc__ and "{sshade_params}" in fn.__doc__:
        fn.__doc__ = fn.__doc__.replace("    {sshade_params}", block)
    return fn


def effective_params(params: SShaDeParams) -> dict:
    """SShaDe's parameters as a run uses them: ``params`` with every None resolved:
    ``max_iter`` the protocol's cap (:data:`sshade.arap.DEFAULT_MAX_ITER`), ``etol`` /
    ``gtol`` the converged criterion's (:func:`sshade.arap.make_criterion`), ``workers``
    the pool size for ``n_samplings`` samplings on this machine; ``n_low`` ``"auto"``
    stays the rule (:func:`sshade.pipeline.auto_n_low`, per mesh: each case's value is in
    its info, ``n_low``).

    Returns
    -------
    dict, JSON-serialisable, the keys of :meth:`SShaDeParams.as_dict`.
    """
    crit = make_criterion(params.etol, params.gtol)
    p = params.as_dict()
    p.update(max_iter=DEFAULT_MAX_ITER[params.protocol] if params.max_iter is None else params.max_iter,
             etol=crit.etol, gtol=crit.gtol, workers=pool_size(params.workers, params.n_samplings))
    if params.n_low == "auto":
        p["n_low"] = "auto: min(6000, n // 7), at least 100"
    return p

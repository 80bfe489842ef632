"""Build the deformation methods named in the evaluator's config.

Names (case-insensitive): ``ARAP`` (spokes, Sorkine & Alexa 2007), ``Elastic``
(spokes and rims, Chao et al. 2010) from :mod:`baselines`, and ``SShaDe`` from
:mod:`sshade`, imported lazily so the baselines run without it.

Config keys read (see ``conf/config.yaml``)::

    methods: [ARAP, Elastic, SShaDe]
    arap:   {protocol: converged, tol: 1e-4, max_iter: null, etol: null, gtol: null}
            # ARAP, Elastic, and SShaDe's low-res ARAP (ARAP-SR: tol / max_iter only)
    sshade: {n_low: 1000, n_samplings: 5, seed: 0, workers: null, gradient: normalized, warm_start: true}
            # optional sshade.tol / sshade.max_iter override the arap values for SShaDe
"""
from __future__ import annotations

import math
from collections.abc import Mapping

from sshade.errors import SShaDeError

__all__ = ["METHODS", "make_methods", "canonical_name", "arap_params"]

METHODS = ("ARAP", "Elastic", "ARAP-SR", "SShaDe", "SShaDe+refine")


def canonical_name(name) -> str:
    """``"arap"`` -> ``"ARAP"`` etc.; raises SShaDeError on an unknown name."""
    key = str(name).strip().lower()
    for m in METHODS:
        if m.lower() == key:
            return m
    raise SShaDeError(f"unknown method {name!r}; choose among {list(METHODS)}")


def _get(cfg, key, default=None):
    if cfg is None:
        return default
    if isinstance(cfg, Mapping) or hasattr(cfg, "get"):
        v = cfg.get(key, default)
        return default if v is None and default is not None else v
    return getattr(cfg, key, default)


def make_methods(cfg) -> list:
    """Instantiate the methods listed in ``cfg.methods``, in that order.

    Parameters
    ----------
    cfg : OmegaConf DictConfig or plain mapping with ``methods`` (list of names) and
        optional ``arap`` / ``sshade`` sections (defaults as in the module docstring).

    Returns
    -------
    list of objects implementing :class:`sshade.method.Deformer`.

    Raises
    ------
    SShaDeError
        Empty or non-list ``methods``, unknown or repeated name, bad parameter values
        (every method's parameters are checked here, before any case is loaded or
        built), or ``SShaDe`` requested but :class:`sshade.SShaDe` cannot be imported.

    Examples
    --------
    >>> [m.name for m in make_methods({"methods": ["ARAP", "elastic"]})]
    ['ARAP', 'Elastic']
    """
    names = _get(cfg, "methods")
    if isinstance(names, str):
        names = [n for n in names.replace(",", " ").split() if n]
    try:
        names = list(names) if names is not None else []
    except TypeError:
        raise SShaDeError(f"methods must be a list of names among {list(METHODS)}, got {names!r}") from None
    if not names:
        raise SShaDeError(f"methods is empty; choose among {list(METHODS)}")
    canon = [canonical_name(n) for n in names]
    dup = {n for n in canon if canon.count(n) > 1}
    if dup:
        raise SShaDeError(f"method(s) listed twice: {sorted(dup)}")

    ap = arap_params(_get(cfg, "arap", {}) or {})
    tol, max_iter = ap["tol"], ap["max_iter"]
    proto = {k: ap[k] for k in ("protocol", "etol", "gtol")}

    out = []
    for n in canon:
        if n == "ARAP":
            from baselines import ARAP
            out.append(ARAP(tol=tol, max_iter=max_iter, **proto))
        elif n == "Elastic":
            from baselines import Elastic
            out.append(Elastic(tol=tol, max_iter=max_iter, **proto))
        elif n == "ARAP-SR":
            from baselines import ARAPSR
            alpha = _get(_get(cfg, "arap_sr", {}) or {}, "alpha", 0.01)
            try:
                alpha = float(alpha)
            except (TypeError, ValueError):
                raise SShaDeError(f"arap_sr.alpha must be a number >= 0, got {alpha!r}") from None
            if not (alpha >= 0 and math.isfinite(alpha)):
                raise SShaDeError(f"arap_sr.alpha must be a finite number >= 0, got {alpha!r}")
            # its own local/global (smooth rotations have no libigl energy): the move rule
            out.append(ARAPSR(alpha=alpha, tol=tol, max_iter=1000 if max_iter is None else max_iter))
        elif n == "SShaDe+refine":  # SShaDe's result starts a converged full-res Elastic solve
            from sshade.refine import SShaDeRefine
            sc = _get(cfg, "sshade", {}) or {}
            out.append(SShaDeRefine(refine_etol=proto["etol"], refine_gtol=proto["gtol"], **_sshade_kwargs(sc, tol, max_iter, proto)))
        else:
            out.append(_make_sshade(_get(cfg, "sshade", {}) or {}, tol, max_iter, proto))
    return out


def _sshade_kwargs(sc, tol: float, max_iter, proto: dict) -> dict:
    """SShaDe's parameters from the ``sshade`` config section (``arap`` values as defaults)."""
    return dict(n_low=_get(sc, "n_low", "auto"), n_samplings=_get(sc, "n_samplings", 5), seed=_get(sc, "seed", 0),
                workers=_get(sc, "workers"), tol=_get(sc, "tol", tol), max_iter=_get(sc, "max_iter", max_iter),
                gradient=str(_get(sc, "gradient", "normalized")), warm_start=bool(_get(sc, "warm_start", True)),
                protocol=_get(sc, "protocol", proto["protocol"]), etol=_get(sc, "etol", proto["etol"]),
                gtol=_get(sc, "gtol", proto["gtol"]))


def arap_params(arap) -> dict:
    """The ``arap`` config section, checked: ``protocol`` (``converged`` or ``paper``, see
    :func:`sshade.arap.arap_deform`), ``tol`` (paper protocol's move rule, > 0),
    ``max_iter`` (int >= 1 or None = the protocol's default), ``etol``/``gtol`` (the
    converged criterion, >= 0 or None = defaults).

    Raises
    ------
    SShaDeError naming the bad key and value.
    """
    from sshade.arap import PROTOCOLS
    protocol = str(_get(arap, "protocol", "converged"))
    if protocol not in PROTOCOLS:
        raise SShaDeError(f"arap.protocol must be one of {list(PROTOCOLS)}, got {protocol!r}")
    out = {"protocol": protocol}
    try:
        out["tol"] = float(_get(arap, "tol", 1e-4))
        mi = _get(arap, "max_iter", None)
        out["max_iter"] = None if mi is None else int(mi)
        for k in ("etol", "gtol"):
            v = _get(arap, k, None)
            out[k] = None if v is None else float(v)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"bad arap parameters: {e}") from None
    if not (out["tol"] > 0) or (out["max_iter"] is not None and out["max_iter"] < 1):
        raise SShaDeError(f"arap.tol must be > 0 and arap.max_iter >= 1 (or null), got tol={out['tol']}, "
                          f"max_iter={out['max_iter']}")
    for k in ("etol", "gtol"):
        if out[k] is not None and not (out[k] >= 0 and math.isfinite(out[k])):
            raise SShaDeError(f"arap.{k} must be a finite number >= 0 (or null), got {out[k]}")
    return out


def _make_sshade(sc, tol: float, max_iter, proto: dict):
    try:
        from sshade import SShaDe
    except ImportError as e:
        raise SShaDeError(f"method SShaDe is not available (cannot import sshade.SShaDe: {e}); "
                          "run with methods=[ARAP,Elastic] meanwhile") from None
    # SShaDe checks its own parameters (sshade.deform.check_params) when it is built
    return SShaDe(**_sshade_kwargs(sc, tol, max_iter, proto))

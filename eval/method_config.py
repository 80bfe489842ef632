"""Build the deformation methods listed in the evaluator's Hydra config: ours by name,
anyone's as a plug-in.
Floor 1 of eval/ (beside metrics/ and datasets/, tests/test_layering.py); notes: docs/experiments.md.

Names (case-insensitive) are those of :func:`harness.method_registry.builtin_methods`, one per
file of the ``method`` config group: ``ARAP`` (spokes, Sorkine & Alexa 2007),
``Elastic`` (spokes and rims, Chao et al. 2010), ``ARAP-SR`` (Levi & Gotsman 2015) from
:mod:`baselines`, ``SShaDe`` and ``SShaDe+refine`` from :mod:`sshade`. Each file
(``conf/method/<name>.yaml``: a ``_target_`` class, its table ``order`` and its
parameters) is composed as ``method.<name>`` (``SShaDe+refine`` as
``method.SShaDe_refine``), whose values default to the shared sections::"""
from __future__ import annotations

import math
from collections.abc import Mapping

from harness.method_registry import (
    SECTIONS,
    build_builtin,
    builtin_methods,
    canonical_name,
    file_spec,
    method_key,
    method_meta,
    strip_meta,
)
from harness.plugins import as_dict, build_method, is_mapping
from sshade.arap import PROTOCOLS
from sshade.errors import SShaDeError

__all__ = ["make_methods", "method_spec", "arap_params"]


def _get(cfg, key, default=None):
    if cfg is None:
        return default
    if isinstance(cfg, Mapping) or hasattr(cfg, "get"):
        v = cfg.get(key, default)
        return default if v is None and default is not None else v
    return getattr(cfg, key, default)


def make_methods(cfg) -> list:
    """Instantiate the methods listed in ``cfg.methods``, in that order.

    An item is one of our names (:func:`harness.method_registry.builtin_methods`, any case), built from its
    definition ``cfg.method.<key>`` (:func:`method_spec`), or a plug-in: a mapping with
    ``_target_`` (``pkg.module.Class``) and keyword arguments (:func:`harness.plugins.build_method`).

    Parameters
    ----------
    cfg : OmegaConf DictConfig or plain mapping with ``methods`` (list of names and/or
        ``_target_`` mappings) and optional ``method`` / ``arap`` / ``arap_sr`` /
        ``sshade`` sections (defaults: ``conf/config.yaml``).

    Returns
    -------
    list of objects implementing :class:`sshade.method_interface.Deformer`.

    Raises
    ------
    SShaDeError
        Empty or non-list ``methods``, unknown name, a mapping without ``_target_``, a
        target that cannot be imported or built, an object without a ``name`` (str) or
        a callable ``deform``, a name breaking :data:`sshade.method_interface.NAME_RULE`, a name listed twice
        (ignoring case and repeated spaces), bad parameter values (every
        method's parameters are checked here, before any case is loaded or built), or
        ``SShaDe`` requested but :class:`sshade.SShaDe` cannot be imported.

    Examples
    --------
    >>> [m.name for m in make_methods({"methods": ["ARAP", "elastic"]})]
    ['ARAP', 'Elastic']
    """
    items = _get(cfg, "methods")
    if isinstance(items, str):
        items = [n for n in items.replace(",", " ").split() if n]
    try:
        items = list(items) if items is not None else []
    except TypeError:
        raise SShaDeError(f"methods must be a list of names among {list(builtin_methods())} or _target_ mappings, "
                          f"got {items!r}") from None
    if not items:
        raise SShaDeError(f"methods is empty; choose among {list(builtin_methods())} or give a _target_ mapping")
    canon = [None if is_mapping(it) else canonical_name(it) for it in items]
    if any(c is not None for c in canon):  # the shared sections, checked under their own names
        arap_params(_get(cfg, "arap", {}) or {})
        if any(c is not None and method_meta(c)["checks"] == "arap_sr" for c in canon):
            _alpha(_get(_get(cfg, "arap_sr", {}) or {}, "alpha", 0.01), "arap_sr.alpha")
    out = [build_method(it, where=f"methods[{i}]") if c is None else _build_ours(cfg, c)
           for i, (it, c) in enumerate(zip(items, canon))]
    keys = [" ".join(m.name.split()).lower() for m in out]  # "SShaDe" and "sshade" would be two confusing rows
    dup = {m.name for m, k in zip(out, keys) if keys.count(k) > 1}
    if dup:
        raise SShaDeError(f"method(s) listed twice: {sorted(dup)} (names are compared ignoring case; give a "
                          "plug-in another `name`)")
    return out


def method_spec(cfg, name: str) -> dict:
    """The resolved definition (``_target_`` and parameters) of our method ``name``.

    ``cfg.method.<key>`` when the config has it (composed from ``conf/method/`` by
    ``conf/config.yaml``), else ``conf/method/<name>.yaml`` resolved against ``cfg``'s
    ``arap`` / ``arap_sr`` / ``sshade`` sections merged over the defaults of
    ``conf/config.yaml`` (:func:`harness.method_registry.file_spec`; so a plain dict config
    works, and so does a method file that the defaults list does not name). Without the
    file's ``order`` (:data:`harness.method_registry.META_KEYS`).

    Raises
    ------
    SShaDeError on an unknown name or a definition that does not resolve.

    Examples
    --------
    >>> method_spec({"arap": {"tol": 1e-3}}, "elastic")["tol"]
    0.001
    """
    from omegaconf.errors import OmegaConfBaseException
    name = canonical_name(name)
    section = _get(_get(cfg, "method", None), method_key(name), None)
    if section is None:
        return file_spec(name, {k: _get(cfg, k) for k in SECTIONS})
    try:
        return strip_meta(as_dict(section))
    except OmegaConfBaseException as e:
        raise SShaDeError(f"method.{method_key(name)}: bad definition ({e})") from None


def _build_ours(cfg, name: str):
    """One of our methods from its definition in ``cfg``, its parameters checked first by
    the checks its file names (``checks``, :func:`harness.method_registry.method_meta`)."""
    spec = method_spec(cfg, name)
    where = f"method.{method_key(name)}"
    checks = method_meta(name)["checks"]
    if checks == "arap":
        arap_params(spec, where=where)
    elif checks == "arap_sr":
        _alpha(spec.get("alpha", 0.01), f"{where}.alpha")
        arap_params({"tol": spec.get("tol", 1e-4), "max_iter": spec.get("max_iter")}, where=where)
    # the others check their own parameters when built (SShaDe: sshade.pipeline.check_params)
    return build_builtin(name, spec=spec)


def _alpha(alpha, where: str) -> float:
    """ARAP-SR's smoothness weight, checked (finite, >= 0); SShaDeError naming ``where``."""
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise SShaDeError(f"{where} must be a number >= 0, got {alpha!r}") from None
    if not (a >= 0 and math.isfinite(a)):
        raise SShaDeError(f"{where} must be a finite number >= 0, got {alpha!r}")
    return a


def arap_params(arap, *, where: str = "arap") -> dict:
    """The ``arap`` config section (or a method definition's keys of the same names),
    checked: ``protocol`` (``converged`` or ``paper``, see :func:`sshade.arap.arap_deform`),
    ``tol`` (paper protocol's move rule, > 0), ``max_iter`` (int >= 1 or None = the
    protocol's default), ``etol``/``gtol`` (the converged criterion, >= 0 or None =
    defaults). ``where`` prefixes the key names in messages.

    Raises
    ------
    SShaDeError naming the bad key and value.
    """
    protocol = str(_get(arap, "protocol", "converged"))
    if protocol not in PROTOCOLS:
        raise SShaDeError(f"{where}.protocol must be one of {list(PROTOCOLS)}, got {protocol!r}")
    out = {"protocol": protocol}
    try:
        out["tol"] = float(_get(arap, "tol", 1e-4))
        mi = _get(arap, "max_iter", None)
        out["max_iter"] = None if mi is None else int(mi)
        for k in ("etol", "gtol"):
            v = _get(arap, k, None)
            out[k] = None if v is None else float(v)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"bad {where} parameters: {e}") from None
    if not (out["tol"] > 0) or (out["max_iter"] is not None and out["max_iter"] < 1):
        raise SShaDeError(f"{where}.tol must be > 0 and {where}.max_iter >= 1 (or null), got tol={out['tol']}, "
                          f"max_iter={out['max_iter']}")
    for k in ("etol", "gtol"):
        if out[k] is not None and not (out[k] >= 0 and math.isfinite(out[k])):
            raise SShaDeError(f"{where}.{k} must be a finite number >= 0 (or null), got {out[k]}")
    return out

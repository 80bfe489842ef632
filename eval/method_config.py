"""Build the deformation methods listed in the evaluator's Hydra config: ours by name,
anyone's as a plug-in.
Floor 1 of eval/ (beside metrics/ and datasets/, tests/test_layering.py); notes: docs/implementation.md.

Names (case-insensitive) are those of :func:`harness.method_registry.builtin_methods`, one per
file of the ``method`` config group: ``ARAP`` (spokes, Sorkine & Alexa 2007),
``Elastic`` (spokes and rims, Chao et al. 2010), ``ARAP-SR`` (Levi & Gotsman 2015) from
:mod:`baselines`, ``SShaDe`` and ``SShaDe+refine`` from :mod:`sshade`. Each file
(``conf/method/<name>.yaml``: a ``_target_`` class, its table ``order`` and its
parameters) is composed as ``method.<name>`` (``SShaDe+refine`` as
``method.SShaDe_refine``), whose values default to the shared sections::"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from eval.run.names import safe_name
from eval.run.spec import MethodSpec
from harness.method_registry import build_builtin, builtin_methods, canonical_name, method_key, method_meta
from harness.plugins import as_dict, build_method, is_mapping
from sshade.arap import DEFAULT_ALPHA, PROTOCOLS
from sshade.errors import SShaDeError

__all__ = ["make_methods", "method_entries", "arap_params", "check_alpha"]


def method_entries(items, definitions: Mapping) -> tuple[MethodSpec, ...]:
    """The entries of ``methods``, checked: ``items`` is a list of our names (any case) and
    plug-in mappings (``_target_`` and keyword arguments), or one string of names;
    ``definitions`` maps each of our names to its resolved definition.

    Returns
    -------
    tuple of :class:`eval.run.spec.MethodSpec`, in ``items`` order (empty when ``items`` is).

    Raises
    ------
    SShaDeError on ``items`` that is not a list or an unknown name (naming our methods).

    Examples
    --------
    >>> [m.name for m in method_entries(["arap", {"_target_": "pkg.Mine"}], {"ARAP": {}})]
    ['ARAP', None]
    """
    if isinstance(items, str):
        items = [n for n in items.replace(",", " ").split() if n]
    try:
        items = list(items) if items is not None else []
    except TypeError:
        raise SShaDeError(f"methods must be a list of names among {list(builtin_methods())} or _target_ mappings, "
                          f"got {items!r}") from None
    out = []
    for i, it in enumerate(items):
        if is_mapping(it):
            out.append(MethodSpec(name=None, definition=as_dict(it), where=f"methods[{i}]"))
        else:
            name = canonical_name(it)
            out.append(MethodSpec(name=name, definition=dict(definitions[name]), where=f"method.{method_key(name)}"))
    return tuple(out)


def make_methods(methods: Sequence[MethodSpec]) -> list:
    """Instantiate ``methods`` (the entries of ``methods``, :func:`method_entries`), in order:
    ours from their definitions, their parameters checked first by the checks their files
    name (``checks``, :func:`harness.method_registry.method_meta`), plug-ins through
    :func:`harness.plugins.build_method`.

    Returns
    -------
    list of objects implementing :class:`sshade.method_interface.Deformer`.

    Raises
    ------
    SShaDeError
        No method, a mapping without ``_target_``, a target that cannot be imported or
        built, an object without a ``name`` (str) or a callable ``deform``, a name breaking
        :data:`sshade.method_interface.NAME_RULE`, a name listed twice (ignoring case and
        repeated spaces), two names of one file name (:func:`eval.run.names.safe_name`,
        ignoring case: their records would overwrite each other), bad parameter values
        (every method's parameters are checked here, before any case is loaded or built), or ``SShaDe`` requested but
        :class:`sshade.SShaDe` cannot be imported.

    Examples
    --------
    >>> from harness.method_registry import file_spec
    >>> entries = method_entries(["ARAP", "elastic"], {n: file_spec(n) for n in ("ARAP", "Elastic")})
    >>> [m.name for m in make_methods(entries)]
    ['ARAP', 'Elastic']
    """
    if not methods:
        raise SShaDeError(f"methods is empty; choose among {list(builtin_methods())} or give a _target_ mapping")
    out = [build_method(dict(m.definition), where=m.where) if m.name is None else _build_ours(m) for m in methods]
    keys = [" ".join(m.name.split()).lower() for m in out]  # "SShaDe" and "sshade" would be two confusing rows
    dup = {m.name for m, k in zip(out, keys) if keys.count(k) > 1}
    if dup:
        raise SShaDeError(f"method(s) listed twice: {sorted(dup)} (names are compared ignoring case; give a "
                          "plug-in another `name`)")
    files = [safe_name(m.name).lower() for m in out]  # "M a" and "M_a" would share runs/<case>/M_a.json
    clash = sorted({m.name for m, f in zip(out, files) if files.count(f) > 1})
    if clash:
        raise SShaDeError(f"methods {clash} would share the file name {safe_name(clash[0])!r} (runs/<case>/"
                          f"{safe_name(clash[0])}.json; file names are compared ignoring case): give a plug-in "
                          "another `name`")
    return out


def _build_ours(m: MethodSpec):
    """One of our methods from its definition, its parameters checked first by the checks
    its file names (``checks``, :func:`harness.method_registry.method_meta`)."""
    spec = dict(m.definition)
    checks = method_meta(m.name)["checks"]
    if checks == "arap":
        arap_params(spec, where=m.where)
    elif checks == "arap_sr":
        check_alpha(spec.get("alpha", DEFAULT_ALPHA), f"{m.where}.alpha")
        arap_params({"tol": spec.get("tol", 1e-4), "max_iter": spec.get("max_iter")}, where=m.where)
    # the others check their own parameters when built (SShaDe: sshade.pipeline.check_params)
    return build_builtin(m.name, spec=spec)


def check_alpha(alpha, where: str) -> float:
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
    def _get(key, default=None):
        v = arap.get(key, default) if arap is not None else default
        return default if v is None and default is not None else v

    protocol = str(_get("protocol", "converged"))
    if protocol not in PROTOCOLS:
        raise SShaDeError(f"{where}.protocol must be one of {list(PROTOCOLS)}, got {protocol!r}")
    out = {"protocol": protocol}
    try:
        out["tol"] = float(_get("tol", 1e-4))
        mi = _get("max_iter", None)
        out["max_iter"] = None if mi is None else int(mi)
        for k in ("etol", "gtol"):
            v = _get(k, None)
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

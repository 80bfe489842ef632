"""Build the deformation methods listed in the evaluator's config: ours by name, anyone's
as a plug-in.

Names (case-insensitive): ``ARAP`` (spokes, Sorkine & Alexa 2007), ``Elastic``
(spokes and rims, Chao et al. 2010), ``ARAP-SR`` (Levi & Gotsman 2015) from
:mod:`baselines`, ``SShaDe`` and ``SShaDe+refine`` from :mod:`sshade`. Each is defined
by a file of the ``method`` config group (``conf/method/<name>.yaml``: a ``_target_``
class and its parameters), composed as ``method.<name>`` (``SShaDe+refine`` as
``method.SShaDe_refine``), whose values default to the shared sections::

    methods: [ARAP, Elastic, SShaDe]
    arap:   {protocol: converged, tol: 1e-4, max_iter: null, etol: null, gtol: null}
            # ARAP, Elastic, and SShaDe's low-res ARAP (ARAP-SR: tol / max_iter only)
    arap_sr: {alpha: 0.01}
    sshade: {n_low: auto, n_samplings: 5, seed: 0, workers: null, gradient: normalized, warm_start: true}
            # optional sshade.tol / sshade.max_iter / sshade.protocol / sshade.etol /
            # sshade.gtol override the arap values for SShaDe

so ``sshade.n_low=500`` and ``method.SShaDe.n_low=500`` both set SShaDe's ``n_low``.

A plug-in is an item of ``methods`` that is a mapping built by
:func:`hydra.utils.instantiate`, e.g. ``{_target_: mypkg.MyMethod, name: Mine,
iterations: 20}``; the object needs what :class:`sshade.method.Deformer` documents
(``name``, ``deform(V, F, handles, targets) -> (n, 3)``, optional ``info`` dict), checked
when it is built (:func:`build_method`).
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path

from sshade.errors import SShaDeError

__all__ = ["METHODS", "make_methods", "build_method", "named_or_plugin", "method_spec", "method_key", "canonical_name",
           "arap_params", "is_plugin", "check_name", "NAME_RULE"]

METHODS = ("ARAP", "Elastic", "ARAP-SR", "SShaDe", "SShaDe+refine")


def canonical_name(name) -> str:
    """``"arap"`` -> ``"ARAP"`` etc.; raises SShaDeError on an unknown name."""
    key = str(name).strip().lower()
    for m in METHODS:
        if m.lower() == key:
            return m
    raise SShaDeError(f"unknown method {name!r}; choose among {list(METHODS)} or give a plug-in mapping "
                      "{_target_: pkg.Class, ...}")


def _get(cfg, key, default=None):
    if cfg is None:
        return default
    if isinstance(cfg, Mapping) or hasattr(cfg, "get"):
        v = cfg.get(key, default)
        return default if v is None and default is not None else v
    return getattr(cfg, key, default)


def make_methods(cfg) -> list:
    """Instantiate the methods listed in ``cfg.methods``, in that order.

    An item is one of our names (:data:`METHODS`, case-insensitive), built from its
    definition ``cfg.method.<key>`` (:func:`method_spec`), or a plug-in: a mapping with
    ``_target_`` (``pkg.module.Class``) and keyword arguments (:func:`build_method`).

    Parameters
    ----------
    cfg : OmegaConf DictConfig or plain mapping with ``methods`` (list of names and/or
        ``_target_`` mappings) and optional ``method`` / ``arap`` / ``arap_sr`` /
        ``sshade`` sections (defaults: ``conf/config.yaml``).

    Returns
    -------
    list of objects implementing :class:`sshade.method.Deformer`.

    Raises
    ------
    SShaDeError
        Empty or non-list ``methods``, unknown name, a mapping without ``_target_``, a
        target that cannot be imported or built, an object without a ``name`` (str) or
        a callable ``deform``, a name breaking :data:`NAME_RULE`, a name listed twice
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
        raise SShaDeError(f"methods must be a list of names among {list(METHODS)} or _target_ mappings, "
                          f"got {items!r}") from None
    if not items:
        raise SShaDeError(f"methods is empty; choose among {list(METHODS)} or give a _target_ mapping")
    canon = [None if _is_mapping(it) else canonical_name(it) for it in items]
    if any(c is not None for c in canon):  # the shared sections, checked under their own names
        arap_params(_get(cfg, "arap", {}) or {})
        if "ARAP-SR" in canon:
            _alpha(_get(_get(cfg, "arap_sr", {}) or {}, "alpha", 0.01), "arap_sr.alpha")
    out = [build_method(it, where=f"methods[{i}]") if c is None else _build_ours(cfg, c)
           for i, (it, c) in enumerate(zip(items, canon))]
    keys = [" ".join(m.name.split()).lower() for m in out]  # "SShaDe" and "sshade" would be two confusing rows
    dup = {m.name for m, k in zip(out, keys) if keys.count(k) > 1}
    if dup:
        raise SShaDeError(f"method(s) listed twice: {sorted(dup)} (names are compared ignoring case; give a "
                          "plug-in another `name`)")
    return out


def _is_mapping(x) -> bool:
    return isinstance(x, Mapping) or (hasattr(x, "keys") and hasattr(x, "get"))


def _container(x) -> dict:
    """A mapping (DictConfig or dict) as a plain dict, interpolations resolved."""
    from omegaconf import OmegaConf
    if OmegaConf.is_config(x):
        return OmegaConf.to_container(x, resolve=True)
    return dict(x)


def method_key(name: str) -> str:
    """Key of our method ``name`` under ``method`` in the config (``SShaDe+refine`` ->
    ``SShaDe_refine``: a ``+`` cannot appear in an override key)."""
    return canonical_name(name).replace("+", "_")


def method_spec(cfg, name: str) -> dict:
    """The resolved definition (``_target_`` and parameters) of our method ``name``.

    ``cfg.method.<key>`` when the config has it (composed from ``conf/method/`` by
    ``conf/config.yaml``), else ``conf/method/<name>.yaml`` resolved against ``cfg``'s
    ``arap`` / ``arap_sr`` / ``sshade`` sections merged over the defaults of
    ``conf/config.yaml`` (so a plain dict config works as before).

    Raises
    ------
    SShaDeError on an unknown name or a definition that does not resolve.

    Examples
    --------
    >>> method_spec({"arap": {"tol": 1e-3}}, "elastic")["tol"]
    0.001
    """
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    from .confdir import config_dir
    name = canonical_name(name)
    key = method_key(name)
    section = _get(_get(cfg, "method", None), key, None)
    try:
        if section is not None:
            return _container(section)
        base = OmegaConf.load(Path(config_dir(), "config.yaml"))
        node = OmegaConf.create({k: base.get(k) for k in ("arap", "arap_sr", "sshade")})
        mine = {k: _container(_get(cfg, k)) for k in ("arap", "arap_sr", "sshade") if _get(cfg, k) is not None}
        node = OmegaConf.merge(node, OmegaConf.create(mine))
        node["_method"] = OmegaConf.load(Path(config_dir("method"), f"{name}.yaml"))
        return OmegaConf.to_container(node["_method"], resolve=True)
    except OmegaConfBaseException as e:
        raise SShaDeError(f"method.{key}: bad definition ({e})") from None


def _build_ours(cfg, name: str, overrides: Mapping | None = None):
    """One of our methods from its definition (with ``overrides`` of its parameters,
    e.g. from the command line), its parameters checked first."""
    spec = method_spec(cfg, name)
    where = f"method.{method_key(name)}"
    unknown = sorted(set(overrides or {}) - set(spec) - {"name"})
    if unknown:
        raise SShaDeError(f"{name} has no parameter(s) {unknown}; its parameters: "
                          f"{sorted(k for k in spec if k != '_target_')}")
    spec.update(overrides or {})
    if name in ("ARAP", "Elastic"):
        arap_params(spec, where=where)
    elif name == "ARAP-SR":
        _alpha(spec.get("alpha", 0.01), f"{where}.alpha")
        arap_params({"tol": spec.get("tol", 1e-4), "max_iter": spec.get("max_iter")}, where=where)
    elif name == "SShaDe":
        try:
            from sshade import SShaDe  # noqa: F401
        except ImportError as e:
            raise SShaDeError(f"method SShaDe is not available (cannot import sshade.SShaDe: {e}); "
                              "run with methods=[ARAP,Elastic] meanwhile") from None
    # SShaDe and SShaDe+refine check their own parameters (sshade.deform.check_params) when built
    return build_method(spec, where=where)


def named_or_plugin(method: str, params: Mapping | None = None, cfg=None):
    """One method from a name or a dotted path (the command line's ``--method``).

    Parameters
    ----------
    method : str, one of :data:`METHODS` (case-insensitive; its definition from
        ``conf/method/``, resolved against ``cfg``) or ``pkg.module.Class`` (a plug-in).
    params : mapping of keyword parameters: for our methods overrides of their
        definition's keys (``n_low``, ``tol``, ...), for a plug-in its constructor's
        arguments.
    cfg : optional config mapping (``arap`` / ``sshade`` sections) for our methods.

    Returns
    -------
    The built method (:func:`build_method`).

    Raises
    ------
    SShaDeError on an unknown name that is not a dotted path, a parameter our method
    does not have, and everything :func:`build_method` raises.
    """
    params = dict(params or {})
    try:
        name = canonical_name(method)
    except SShaDeError:
        if "." not in str(method):
            raise
        return build_method({"_target_": str(method), **params}, where=f"method {method}")
    return _build_ours(cfg or {}, name, params)


def build_method(spec, *, where: str = "method"):
    """Build one method from a ``_target_`` mapping and check its interface.

    Parameters
    ----------
    spec : mapping (dict or DictConfig) with ``_target_`` (dotted path of a class or
        factory) and its keyword arguments; a ``name`` the target does not accept as an
        argument is set on the built object instead (so ``{_target_: sshade.SShaDe,
        name: SShaDe-500, n_low: 500}`` is a second SShaDe row).
    where : str, names the item in error messages (e.g. ``methods[1]``).

    Returns
    -------
    The built object, with a ``name`` (non-empty str), a callable ``deform`` and an
    ``info`` mapping (set to ``{}`` when the object has none).

    Raises
    ------
    SShaDeError naming ``where`` and the target: no ``_target_``, an import or
    construction failure (a :class:`SShaDeError` raised by the constructor is re-raised
    unchanged, e.g. ``SShaDe: n_low must be at least 4``), an object lacking the
    :class:`sshade.method.Deformer` interface, or a ``name`` breaking :data:`NAME_RULE`
    (:func:`check_name`; a newline or ``|`` would break a table row).

    Examples
    --------
    >>> build_method({"_target_": "baselines.Elastic", "tol": 1e-3}).name
    'Elastic'
    """
    from hydra.errors import InstantiationException
    from hydra.utils import instantiate
    if not _is_mapping(spec):
        raise SShaDeError(f"{where}: a method is a name among {list(METHODS)} or a mapping with _target_, "
                          f"got {spec!r}")
    spec = _container(spec)
    target = spec.get("_target_")
    if not isinstance(target, str) or not target.strip():
        raise SShaDeError(f"{where}: a method mapping needs _target_ (e.g. mypkg.MyMethod), got keys {sorted(spec)}")
    try:
        obj = _locate(target)
    except Exception as e:  # ImportError, AttributeError, ...: whatever the import raised
        raise SShaDeError(f"{where}: cannot import _target_ {target!r} ({_one_line(e)})") from None
    rename = spec.pop("name") if "name" in spec and not _takes(obj, "name") else None
    try:
        m = instantiate(spec, _convert_="all")
    except InstantiationException as e:
        cause = e.__cause__
        if isinstance(cause, SShaDeError):
            raise cause from None
        raise SShaDeError(f"{where}: cannot build {target} ({_one_line(cause or e)})") from None
    except SShaDeError:
        raise
    except Exception as e:
        raise SShaDeError(f"{where}: cannot build {target} ({_one_line(e)})") from None
    if rename is not None:
        m.name = str(rename)
    name = getattr(m, "name", None)
    if not isinstance(name, str) or not name.strip():
        raise SShaDeError(f"{where}: {target} built an object without a `name` (non-empty str), got {name!r}; "
                          "a method needs `name` and deform(V, F, handles, targets) (sshade.method.Deformer)")
    check_name(name, where=f"{where}: {target}")
    if not callable(getattr(m, "deform", None)):
        raise SShaDeError(f"{where}: {target} ({name!r}) has no callable deform(V, F, handles, targets) "
                          "(sshade.method.Deformer)")
    info = getattr(m, "info", None)
    if info is None:
        m.info = {}
    elif not isinstance(info, Mapping):
        raise SShaDeError(f"{where}: {target} ({name!r}) has an `info` that is not a dict: {type(info).__name__}")
    return m


#: A method name: the row label of cases.csv, table.md and table.tex (issue 19).
_NAME_RE = re.compile(r"[A-Za-z0-9_+.()/-]([A-Za-z0-9 _+.()/-]{0,62}[A-Za-z0-9_+.()/-])?")
NAME_RULE = ("method names are 1-64 characters among ASCII letters, digits, space and _ - + . ( ) /, "
             "not starting or ending with a space")


def check_name(name, *, where: str = "method") -> str:
    """``name`` if it is a valid method name (:data:`NAME_RULE`), else SShaDeError
    (one line: ``where``, the name as Python writes it, the rule). A name with a
    newline, ``|``, ``&``, ``%`` ... would break a row of table.md or table.tex."""
    if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
        raise SShaDeError(f"{where}: bad name {name!r}: {NAME_RULE}")
    return name


def _one_line(e: BaseException) -> str:
    """``Type: message`` of an exception on one line (whitespace runs collapsed)."""
    return " ".join(f"{type(e).__name__}: {e}".split())


def _locate(path: str):
    """The object at the dotted ``path`` (``pkg.module.Class``): the longest importable
    module prefix, then attributes. An ImportError raised inside an existing module (a
    missing dependency of the user's code) is not mistaken for a wrong path."""
    import importlib
    parts = path.strip().split(".")
    obj, i = None, len(parts)
    while i > 0:
        mod = ".".join(parts[:i])
        try:
            obj = importlib.import_module(mod)
            break
        except ModuleNotFoundError as e:
            if e.name is None or not (mod == e.name or mod.startswith(e.name + ".")):
                raise
            i -= 1
    if obj is None:
        raise ImportError(f"no module named {parts[0]!r} (is it on the Python path? the folder the command "
                          "runs in is)")
    for j, p in enumerate(parts[i:], i):
        if not hasattr(obj, p):
            raise ImportError(f"{'.'.join(parts[:j])} has no attribute {p!r}")
        obj = getattr(obj, p)
    return obj


def _takes(obj, arg: str) -> bool:
    """Whether calling ``obj`` accepts the keyword ``arg`` (True when unknown)."""
    import inspect
    try:
        params = inspect.signature(obj).parameters
    except (TypeError, ValueError):
        return True
    return arg in params or any(p.kind is p.VAR_KEYWORD for p in params.values())


def is_plugin(method) -> bool:
    """True for a method that is not one of this project's (its class is defined outside
    the ``sshade`` and ``baselines`` packages): the evaluator records any exception such
    a method raises on a case, not only :class:`SShaDeError`."""
    mod = type(method).__module__ or ""
    return mod.split(".")[0] not in ("sshade", "baselines")


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
    from sshade.arap import PROTOCOLS
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

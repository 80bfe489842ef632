"""Our built-in methods, by name: each a module (its class implements
:class:`sshade.method_interface.Deformer`) plus one file ``conf/method/<name>.yaml`` of the config
folder of :func:`harness.confdir.config_dir` (``_target_``, table ``order``, parameters, and
under ``harness`` what the evaluator knows of it, :func:`method_meta`). The file name is the
method's name; its config key has ``+`` as ``_`` (:func:`method_key`). No method's module
is imported until it is built (:func:`build_builtin`), so this floor names the baselines
without an upward import; :func:`builtin_methods`, :func:`table_order` and ``python -m
harness deform --method`` follow the files. A method file, and how to add one: docs/methods.md,
"Adding a method"; why: docs/implementation.md, "Implementation notes: harness/method_registry.py".
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from harness.confdir import config_dir
from harness.plugins import as_dict, build_method
from sshade.errors import SShaDeError

__all__ = ["builtin_methods", "table_order", "canonical_name", "method_key", "method_file", "file_spec",
           "method_meta", "strip_meta", "build_builtin", "named_or_plugin", "META_KEYS", "META_DEFAULTS", "SECTIONS"]

#: Keys of a method file that describe the method instead of being its parameters:
#: ``order`` (table row order, smaller first) and ``harness``, the evaluator's facts of it
#: (:func:`method_meta`, :data:`META_DEFAULTS`).
META_KEYS = ("order", "harness")
#: The keys of a method file's ``harness`` and what a file that leaves one out (and a
#: plug-in) gets: ``cost`` (the plan's prior: ``scale`` ``vertices`` or ``const``,
#: ``prior`` in seconds per vertex or per case, optional ``preset``: the only preset the
#: prior holds for, optional ``paper``: the prior under ``arap.protocol=paper``, optional
#: ``exponent``: how the prior grows with the vertices, :mod:`eval.run.progress`),
#: ``reference`` (an energy of :data:`sshade.arap.ENERGIES`, or ``arap_sr``: ARAP-SR's
#: own with the method's ``alpha``), ``cases`` (``baseline`` or ``all``), ``checks``
#: (``arap``, ``arap_sr`` or ``none``), ``iterations`` (what its iteration count counts,
#: said beside it in the tables; empty: plain iterations).
META_DEFAULTS = {"cost": {"scale": "vertices"}, "reference": "spokes_and_rims", "cases": "baseline",
                 "checks": "none", "iterations": ""}
_META_CHOICES = {"cases": ("baseline", "all"), "checks": ("arap", "arap_sr", "none")}
#: The shared sections of ``conf/config.yaml`` the method files' values default to.
SECTIONS = ("arap", "arap_sr", "sshade")

_CACHE: dict = {}


def _definitions() -> dict[str, dict]:
    """``{name: unresolved definition}`` of every ``conf/method/*.yaml``, read once per
    config folder."""
    from omegaconf import OmegaConf  # Hydra's config library, loaded on use
    folder = Path(config_dir("method"))
    stamp = (str(folder), tuple(sorted((p.name, p.stat().st_mtime_ns) for p in folder.glob("*.yaml"))))
    if _CACHE.get("stamp") != stamp:
        defs = {}
        for p in sorted(folder.glob("*.yaml")):
            node = OmegaConf.load(p)
            if not isinstance(node.get("_target_", None), str):
                raise SShaDeError(f"{p}: a method file needs _target_ (the class, e.g. baselines.ARAP)")
            defs[p.stem] = node
        _CACHE.update(stamp=stamp, defs=defs)
    return _CACHE["defs"]


def _order(name: str) -> tuple:
    node = _definitions().get(name)
    v = None if node is None else node.get("order", None)
    try:
        return (float(v), name) if v is not None else (float("inf"), name)
    except (TypeError, ValueError):
        raise SShaDeError(f"conf/method/{name}.yaml: order must be a number, got {v!r}") from None


def builtin_methods() -> tuple[str, ...]:
    """The names of our methods (one per ``conf/method/*.yaml``), in table order.

    >>> builtin_methods()
    ('ARAP', 'Elastic', 'ARAP-SR', 'Implicit-ARAP', 'SShaDe', 'SShaDe+refine')
    """
    return tuple(sorted(_definitions(), key=_order))


def table_order() -> tuple[str, ...]:
    """Row order of the tables: our methods by their ``order`` (methods without one
    last, by name). Any other method (a plug-in) comes after these, by name
    (:mod:`eval.tables`).

    >>> table_order()
    ('ARAP', 'Elastic', 'ARAP-SR', 'Implicit-ARAP', 'SShaDe', 'SShaDe+refine')
    """
    return tuple(sorted(_definitions(), key=_order))


def canonical_name(name) -> str:
    """``"arap"`` -> ``"ARAP"`` etc. (case-insensitive, surrounding spaces ignored).

    Raises
    ------
    SShaDeError on a name that is not one of :func:`builtin_methods`.
    """
    key = str(name).strip().lower()
    names = builtin_methods()
    for m in names:
        if m.lower() == key:
            return m
    raise SShaDeError(f"unknown method {name!r}; choose among {list(names)} or give a plug-in mapping "
                      "{_target_: pkg.Class, ...}")


def method_key(name: str) -> str:
    """Key of our method ``name`` under ``method`` in the config (``SShaDe+refine`` ->
    ``SShaDe_refine``: a ``+`` cannot appear in an override key)."""
    return canonical_name(name).replace("+", "_")


def method_file(name: str) -> Path:
    """``conf/method/<name>.yaml`` of our method ``name`` (any case)."""
    return Path(config_dir("method"), f"{canonical_name(name)}.yaml")


def method_meta(name) -> dict:
    """What the evaluator knows of method ``name`` beside its parameters: the ``harness``
    of its file, each missing key from :data:`META_DEFAULTS`; a name that is none of
    :func:`builtin_methods` (a plug-in) gets the defaults.

    Returns
    -------
    dict with every key of :data:`META_DEFAULTS` (``cost`` a dict with ``scale``).

    Raises
    ------
    SShaDeError naming the file on a ``harness`` that is not a mapping of those keys, a
    value outside its choices (``cost.scale``, ``cases``, ``checks``) or a ``cost.prior``
    or ``cost.paper`` that is not a number >= 0.

    Examples
    --------
    >>> method_meta("SShaDe")["cases"], method_meta("ARAP")["reference"], method_meta("Mine")["cases"]
    ('all', 'spokes', 'baseline')
    """
    from omegaconf import OmegaConf
    try:
        name = canonical_name(name)
    except SShaDeError:
        return {k: (dict(v) if isinstance(v, dict) else v) for k, v in META_DEFAULTS.items()}
    where = f"conf/method/{name}.yaml"
    node = _definitions()[name].get("harness", None)
    node = {} if node is None else OmegaConf.to_container(node) if OmegaConf.is_config(node) else node
    if not isinstance(node, dict) or set(node) - set(META_DEFAULTS):
        raise SShaDeError(f"{where}: harness must be a mapping with keys among {list(META_DEFAULTS)}, got {node!r}")
    out = {k: node.get(k, d) for k, d in META_DEFAULTS.items()}
    cost = out["cost"] = dict(out["cost"] or {})
    cost.setdefault("scale", "vertices")
    for k, choices in [("cases", _META_CHOICES["cases"]), ("checks", _META_CHOICES["checks"])]:
        if out[k] not in choices:
            raise SShaDeError(f"{where}: {k} must be one of {list(choices)}, got {out[k]!r}")
    if cost["scale"] not in ("vertices", "const"):
        raise SShaDeError(f"{where}: cost.scale must be vertices or const, got {cost['scale']!r}")
    for k in ("prior", "paper"):
        v = cost.get(k)
        if v is not None and not (isinstance(v, (int, float)) and not isinstance(v, bool) and v >= 0):
            raise SShaDeError(f"{where}: cost.{k} must be a number >= 0 (seconds), got {v!r}")
    out["iterations"] = str(out["iterations"] or "")
    return out


def strip_meta(spec: Mapping) -> dict:
    """A method definition without its :data:`META_KEYS` (what the class is built with)."""
    return {k: v for k, v in spec.items() if k not in META_KEYS}


def file_spec(name: str, sections: Mapping | None = None) -> dict:
    """The resolved definition (``_target_`` and parameters) of our method ``name``, read
    from its file, its values resolved against the :data:`SECTIONS` of
    ``conf/config.yaml`` with ``sections`` (e.g. ``{"arap": {"tol": 1e-3}}``) merged over
    them.

    Raises
    ------
    SShaDeError on an unknown name or a definition that does not resolve.

    Examples
    --------
    >>> file_spec("elastic", {"arap": {"tol": 1e-3}})["tol"]
    0.001
    """
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException
    name = canonical_name(name)
    try:
        base = OmegaConf.load(Path(config_dir(), "config.yaml"))
        node = OmegaConf.create({k: base.get(k) for k in SECTIONS})
        mine = {k: as_dict(v) for k, v in (sections or {}).items() if k in SECTIONS and v is not None}
        node = OmegaConf.merge(node, OmegaConf.create(mine))
        node["_method"] = _definitions()[name]
        return strip_meta(OmegaConf.to_container(node["_method"], resolve=True))
    except OmegaConfBaseException as e:
        raise SShaDeError(f"method.{method_key(name)}: bad definition ({e})") from None


def build_builtin(name: str, overrides: Mapping | None = None, *, spec: Mapping | None = None,
                  sections: Mapping | None = None):
    """Build our method ``name`` from its definition (``spec``, default
    :func:`file_spec` with ``sections``), with ``overrides`` of its parameters.

    Raises
    ------
    SShaDeError: an override that is not a parameter of the definition (``ARAP has no
    parameter(s) ['n_low']``), and everything :func:`harness.plugins.build_method` raises
    (the classes check their parameter values when built).
    """
    name = canonical_name(name)
    spec = strip_meta(spec if spec is not None else file_spec(name, sections))
    unknown = sorted(set(overrides or {}) - set(spec) - {"name"})
    if unknown:
        raise SShaDeError(f"{name} has no parameter(s) {unknown}; its parameters: "
                          f"{sorted(k for k in spec if k != '_target_')}")
    spec.update(overrides or {})
    return build_method(spec, where=f"method.{method_key(name)}")


def named_or_plugin(method: str, params: Mapping | None = None, sections: Mapping | None = None):
    """One method from a name or a dotted path (the command line's ``--method``).

    Parameters
    ----------
    method : str, one of :func:`builtin_methods` (case-insensitive) or ``pkg.module.Class``
        (a plug-in).
    params : mapping of keyword parameters: for our methods overrides of their
        definition's keys (``n_low``, ``tol``, ...), for a plug-in its constructor's
        arguments.
    sections : optional ``arap`` / ``arap_sr`` / ``sshade`` sections for our methods.

    Returns
    -------
    The built method (:func:`harness.plugins.build_method`).

    Raises
    ------
    SShaDeError on an unknown name that is not a dotted path, a parameter our method
    does not have, and everything :func:`harness.plugins.build_method` raises.
    """
    params = dict(params or {})
    try:
        name = canonical_name(method)
    except SShaDeError:
        if "." not in str(method):
            raise
        return build_method({"_target_": str(method), **params}, where=f"method {method}")
    return build_builtin(name, params, sections=sections)

"""Our built-in methods, by name: one config file each, ``conf/method/<name>.yaml``.

A built-in method is a module (its class implements :class:`sshade.method.Deformer`)
plus one file of the ``method`` config group, found in the config folder of
:func:`sshade.confdir.config_dir` (the repository's ``conf/`` or the installed
``eval/conf/``)::

    # conf/method/Elastic.yaml
    _target_: baselines.Elastic      # the class, imported by its dotted path (importlib)
    order: 20                        # its place in the tables (smaller first)
    protocol: ${arap.protocol}       # parameters, defaulting to the shared sections
    tol: ${arap.tol}                 # (arap, arap_sr, sshade) of conf/config.yaml

The file name is the method's name (the table row label, :func:`sshade.method.check_name`);
its key in the composed config is the name with ``+`` as ``_`` (:func:`method_key`).
Nothing here imports a method's module until it is built (:func:`build_builtin`), so the
bottom layer names the methods of the layers above without a static upward import.

Adding a built-in method therefore takes its module and its config file; the list of
names (:func:`builtin_methods`), the table order (:func:`table_order`) and the command
line's ``--method`` follow. One optional line more, ``- method@method.<key>: <name>`` in
the defaults list of ``conf/config.yaml``, lets Hydra compose the file as
``method.<key>`` so that ``method.<key>.<param>=...`` overrides reach it (Hydra composes
only the group options its defaults list names; without the line the evaluator loads
the file itself, :func:`method_spec`).

Rows of methods that have no config file here keep a slot in the table order:
:data:`RESERVED_ORDER`.
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

from .confdir import config_dir
from .errors import SShaDeError
from .method import as_dict, build_method

__all__ = ["builtin_methods", "table_order", "canonical_name", "method_key", "method_file", "method_spec",
           "strip_meta", "build_builtin", "named_or_plugin", "META_KEYS", "RESERVED_ORDER", "SECTIONS"]

#: Keys of a method file that describe the method instead of being its parameters.
META_KEYS = ("order",)
#: Table slots of methods without a config file in this repository (none since
#: Implicit-ARAP got its file, conf/method/Implicit-ARAP.yaml).
RESERVED_ORDER: dict[str, float] = {}
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
    v = RESERVED_ORDER.get(name) if node is None else node.get("order", None)
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
    """Row order of the tables: our methods and the :data:`RESERVED_ORDER` slots, by
    their ``order`` (methods without one last, by name). Any other method (a plug-in)
    comes after these, by name (:mod:`eval.tables`).

    >>> table_order()
    ('ARAP', 'Elastic', 'ARAP-SR', 'Implicit-ARAP', 'SShaDe', 'SShaDe+refine')
    """
    return tuple(sorted({*_definitions(), *RESERVED_ORDER}, key=_order))


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


def strip_meta(spec: Mapping) -> dict:
    """A method definition without its :data:`META_KEYS` (what the class is built with)."""
    return {k: v for k, v in spec.items() if k not in META_KEYS}


def method_spec(name: str, sections: Mapping | None = None) -> dict:
    """The resolved definition (``_target_`` and parameters) of our method ``name``, read
    from its file, its values resolved against the :data:`SECTIONS` of
    ``conf/config.yaml`` with ``sections`` (e.g. ``{"arap": {"tol": 1e-3}}``) merged over
    them.

    Raises
    ------
    SShaDeError on an unknown name or a definition that does not resolve.

    Examples
    --------
    >>> method_spec("elastic", {"arap": {"tol": 1e-3}})["tol"]
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
    :func:`method_spec` with ``sections``), with ``overrides`` of its parameters.

    Raises
    ------
    SShaDeError: an override that is not a parameter of the definition (``ARAP has no
    parameter(s) ['n_low']``), and everything :func:`sshade.method.build_method` raises
    (the classes check their parameter values when built).
    """
    name = canonical_name(name)
    spec = strip_meta(spec if spec is not None else method_spec(name, sections))
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
    The built method (:func:`sshade.method.build_method`).

    Raises
    ------
    SShaDeError on an unknown name that is not a dotted path, a parameter our method
    does not have, and everything :func:`sshade.method.build_method` raises.
    """
    params = dict(params or {})
    try:
        name = canonical_name(method)
    except SShaDeError:
        if "." not in str(method):
            raise
        return build_method({"_target_": str(method), **params}, where=f"method {method}")
    return build_builtin(name, params, sections=sections)

"""Plug-in loading: a deformation method built from a ``_target_`` mapping.

:func:`build_method` locates the class (or factory) by its dotted path (:func:`locate`),
instantiates it with its parameters through Hydra's ``instantiate``, and checks the
:class:`sshade.method_interface.Deformer` interface and the name rule
(:func:`sshade.method_interface.check_name`). The built-in methods are built by name through
:mod:`harness.method_registry`; the evaluator's configs through :mod:`eval.method_config`.

Example::

    >>> build_method({"_target_": "baselines.Elastic", "tol": 1e-3}).name
    'Elastic'
"""
from __future__ import annotations

import importlib
import inspect
from collections.abc import Mapping

from sshade.errors import SShaDeError
from sshade.method_interface import check_name

__all__ = ["build_method", "locate", "is_mapping", "as_dict"]


def is_mapping(x) -> bool:
    """True for a dict, a DictConfig or any object with ``keys`` and ``get``."""
    return isinstance(x, Mapping) or (hasattr(x, "keys") and hasattr(x, "get"))


def as_dict(x) -> dict:
    """A mapping (DictConfig or dict) as a plain dict, interpolations resolved."""
    from omegaconf import OmegaConf  # Hydra's config library, loaded on use
    if OmegaConf.is_config(x):
        return OmegaConf.to_container(x, resolve=True)
    return dict(x)


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
    :class:`sshade.method_interface.Deformer` interface, or a ``name`` breaking :data:`NAME_RULE`
    (:func:`check_name`; a newline or ``|`` would break a table row).

    Examples
    --------
    >>> build_method({"_target_": "baselines.Elastic", "tol": 1e-3}).name
    'Elastic'
    """
    from hydra.errors import InstantiationException  # Hydra builds nested _target_ mappings too
    from hydra.utils import instantiate
    if not is_mapping(spec):
        raise SShaDeError(f"{where}: a method is the name of one of ours or a mapping with _target_, "
                          f"got {spec!r}")
    spec = as_dict(spec)
    target = spec.get("_target_")
    if not isinstance(target, str) or not target.strip():
        raise SShaDeError(f"{where}: a method mapping needs _target_ (e.g. mypkg.MyMethod), got keys {sorted(spec)}")
    try:
        obj = locate(target)
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
                          "a method needs `name` and deform(V, F, handles, targets) (sshade.method_interface.Deformer)")
    check_name(name, where=f"{where}: {target}")
    if not callable(getattr(m, "deform", None)):
        raise SShaDeError(f"{where}: {target} ({name!r}) has no callable deform(V, F, handles, targets) "
                          "(sshade.method_interface.Deformer)")
    info = getattr(m, "info", None)
    if info is None:
        m.info = {}
    elif not isinstance(info, Mapping):
        raise SShaDeError(f"{where}: {target} ({name!r}) has an `info` that is not a dict: {type(info).__name__}")
    return m


def _one_line(e: BaseException) -> str:
    """``Type: message`` of an exception on one line (whitespace runs collapsed)."""
    return " ".join(f"{type(e).__name__}: {e}".split())


def locate(path: str):
    """The object at the dotted ``path`` (``pkg.module.Class``): the longest importable
    module prefix, then attributes. An ImportError raised inside an existing module (a
    missing dependency of the user's code) is not mistaken for a wrong path."""
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
    try:
        params = inspect.signature(obj).parameters
    except (TypeError, ValueError):
        return True
    return arg in params or any(p.kind is p.VAR_KEYWORD for p in params.values())

"""The one small interface every deformation method implements (SShaDe, the baselines,
anyone's plug-in), so the evaluator and ``python -m sshade deform`` treat them alike,
and the generic way to build one: :func:`build_method` from a ``_target_`` mapping
(locate the class by its dotted path, :func:`locate`; instantiate it with parameters;
check the :class:`Deformer` interface and the name rule, :func:`check_name`).

Our built-in methods are built by name through :mod:`sshade.registry`; the evaluator's
Hydra configs through :mod:`eval.methods`.
"""
from __future__ import annotations

import importlib
import inspect
import re
from collections.abc import Mapping
from typing import Protocol, runtime_checkable

import numpy as np

from .errors import SShaDeError

__all__ = ["Deformer", "build_method", "check_name", "NAME_RULE", "locate", "is_plugin", "is_mapping", "as_dict"]


@runtime_checkable
class Deformer(Protocol):
    """A handle-driven deformation method.

    Attributes
    ----------
    name : str, the row label in tables ("ARAP", "Elastic", "SShaDe", ...).
    info : dict, filled by the last :meth:`deform` call with per-stage timings in
        seconds (keys ending in ``_s``), iteration counts and seeds.

    Methods
    -------
    deform(V, F, handles, targets) -> (n, 3) float64
        ``V`` (n,3) float64 rest positions, ``F`` (m,3) int64, ``handles`` (h,) int64
        vertex indices, ``targets`` (h,3) float64 positions. Returns deformed positions
        with the same connectivity ``F``. Raises ``SShaDeError`` on bad input.
    warmup(n_vertices=None) -> float, optional
        Compile or load whatever the first :meth:`deform` on an ``n_vertices`` mesh
        would (numba kernels, lazy imports), returning the seconds spent (0.0 when
        already warm). The evaluator calls it before the timed call and reports the
        seconds as ``compile_s``, never inside ``time_s`` (:mod:`sshade.warmup`).
    """

    name: str
    info: dict

    def deform(self, V: np.ndarray, F: np.ndarray, handles: np.ndarray,
               targets: np.ndarray) -> np.ndarray: ...


def is_mapping(x) -> bool:
    """True for a dict, a DictConfig or any object with ``keys`` and ``get``."""
    return isinstance(x, Mapping) or (hasattr(x, "keys") and hasattr(x, "get"))


def as_dict(x) -> dict:
    """A mapping (DictConfig or dict) as a plain dict, interpolations resolved."""
    from omegaconf import OmegaConf  # Hydra's config library, loaded on use (import sshade stays light)
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
    :class:`sshade.method.Deformer` interface, or a ``name`` breaking :data:`NAME_RULE`
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


#: A method name: the row label of cases.csv, table.md and table.tex.
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


def is_plugin(method) -> bool:
    """True for a method that is not one of this project's (its class is defined outside
    the ``sshade`` and ``baselines`` packages): the evaluator records any exception such
    a method raises on a case, not only :class:`SShaDeError`."""
    mod = type(method).__module__ or ""
    return mod.split(".")[0] not in ("sshade", "baselines")

"""Checked numbers, flags and integer lists read from an OmegaConf config (or plain mappings).

Each reader raises :class:`~sshade.errors.SShaDeError` naming the key and the value
(``"<key> must be an integer >= 1 (or null), got 'abc'"``), so that a bad value on a
command line gives one ``error: ...`` line and exit status 2 before any work. Used by
the DeFAUST builder's command line (:mod:`defaust.cli`) and by the evaluator's config
check (:func:`eval.config_check.check_config`). OmegaConf is imported only when a value
is read.
"""
from __future__ import annotations

import math

from sshade.errors import SShaDeError
from sshade.pipeline import MAX_SEED

__all__ = ["config_value", "config_number", "config_bool", "config_int_list", "check_numbers", "MAX_INT"]

MAX_INT = 2**31 - 1   # counts and iteration caps: int32 (numba kernels, libigl)
_MISSING = object()  # "no default": an absent key is an error


def config_value(cfg, key: str, default=_MISSING):
    """``cfg``'s value at the dotted ``key`` (``default`` when absent; without a default an
    absent key is an error). ``cfg``: an OmegaConf config or plain mappings and lists.

    Raises
    ------
    SShaDeError naming the key when it is absent (and no default is given) or cannot be read.
    """
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException
    try:
        if not OmegaConf.is_config(cfg):
            cfg = OmegaConf.create(cfg)
        v = OmegaConf.select(cfg, key, default=_MISSING, throw_on_missing=True)
    except OmegaConfBaseException as e:
        raise SShaDeError(f"{key}: {' '.join(str(e).split())}") from None
    if v is _MISSING:
        if default is _MISSING:
            raise SShaDeError(f"{key} is not set")
        return default
    return v


def _describe(kind, lo, hi, allow_none) -> str:
    s = "an integer" if kind is int else "a finite number"
    if lo is not None and hi is not None:
        s += f" in [{lo}, {hi}]"
    elif lo is not None:
        s += f" >= {lo}"
    elif hi is not None:
        s += f" <= {hi}"
    return s + (" (or null)" if allow_none else "")


def config_number(cfg, key: str, *, kind=int, min=None, max=None, allow_none: bool = False,  # noqa: A002
                  default=_MISSING):
    """The number at ``key`` of an OmegaConf config, checked.

    Parameters
    ----------
    cfg : DictConfig (or anything ``OmegaConf.select`` reads).
    key : dotted key, e.g. ``"dataset.limit"``.
    kind : ``int`` or ``float``. An int may be written as an integral float (``1e3``);
        a bool, NaN, inf, a string or a value beyond ``max`` is refused.
    min, max : inclusive bounds (ints default to at most :data:`MAX_INT`).
    allow_none : accept ``null`` (returned as None).
    default : returned when the key is absent (else an absent key is an error).

    Returns
    -------
    int, float or None.

    Raises
    ------
    SShaDeError ``"<key> must be an integer >= 1 (or null), got 'abc'"``.

    Examples
    --------
    >>> from omegaconf import OmegaConf
    >>> config_number(OmegaConf.create({"d": {"limit": 4}}), "d.limit", min=1)
    4
    """
    v = config_value(cfg, key, default)
    if v is None and allow_none:
        return None
    hi = MAX_INT if (kind is int and max is None) else max
    bad = SShaDeError(f"{key} must be {_describe(kind, min, max if kind is float else hi, allow_none)}, got {v!r}")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise bad
    if not math.isfinite(v):
        raise bad
    if kind is int:
        if v != int(v):
            raise bad
        v = int(v)
    else:
        v = float(v)
    if (min is not None and v < min) or (hi is not None and v > hi):
        raise bad
    return v


def config_bool(cfg, key: str, *, default=_MISSING) -> bool:
    """The flag at ``key`` (YAML ``true``/``false`` only; ``maybe`` or ``1`` is refused).

    Raises
    ------
    SShaDeError naming the key and the value.
    """
    v = config_value(cfg, key, default)
    if not isinstance(v, bool):
        raise SShaDeError(f"{key} must be true or false, got {v!r}")
    return v


def config_int_list(cfg, key: str, *, min=0, max=MAX_INT, allow_none: bool = True):  # noqa: A002
    """A list of integers (or one integer) at ``key``, e.g. ``dataset.subjects``; None when
    null and allowed. Raises SShaDeError naming the key and the bad element."""
    from omegaconf import OmegaConf
    v = config_value(cfg, key, None)
    if v is None:
        if allow_none:
            return None
        raise SShaDeError(f"{key} must be a list of integers, got null")
    items = OmegaConf.to_container(v) if OmegaConf.is_config(v) else v
    items = list(items) if isinstance(items, (list, tuple)) else [items]
    out = []
    for x in items:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or x != int(x) \
                or not min <= x <= max:
            raise SShaDeError(f"{key} must be a list of integers in [{min}, {max}], got {x!r} in {items!r}")
        out.append(int(x))
    return out


def check_numbers(cfg, prefix: str, checks) -> None:
    """Check the numbers of config section ``prefix`` (:func:`config_number`); a key that
    is absent is left to its reader's default, a key ending in ``seed`` is at most
    :data:`sshade.pipeline.MAX_SEED`.

    Parameters
    ----------
    cfg : DictConfig (or anything ``OmegaConf.select`` reads).
    prefix : str, the section, e.g. ``"dataset"``.
    checks : iterable of ``(key, kind, min, allow_none)``: ``key`` under ``prefix``
        (dotted for a nested key), ``kind`` int or float, ``min`` the lower bound (None:
        none), ``allow_none`` whether null is accepted.

    Raises
    ------
    SShaDeError naming the first bad key and its value.

    Examples
    --------
    >>> from omegaconf import OmegaConf
    >>> check_numbers(OmegaConf.create({"tosca": {"min_vertices": -1}}), "tosca", [("min_vertices", int, 0, True)])
    Traceback (most recent call last):
    ...
    sshade.errors.SShaDeError: tosca.min_vertices must be an integer in [0, 2147483647] (or null), got -1
    """
    absent = object()
    for key, kind, lo, none in checks:
        k = f"{prefix}.{key}"
        if config_value(cfg, k, absent) is absent:
            continue
        config_number(cfg, k, kind=kind, min=lo, max=MAX_SEED if key.endswith("seed") else None, allow_none=none)

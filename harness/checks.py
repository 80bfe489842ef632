"""Checked numbers, flags and integer lists, each refusal an :class:`~sshade.errors.SShaDeError`
naming the key and the value (``"dataset.limit must be an integer in [1, 2147483647] (or
null), got 'abc'"``): one ``error: ...`` line and exit status 2 before any work.

- A typed record (an options dataclass) declares each field's kind and bounds once,
  beside the field (:func:`checked_field`), and checks them all with one walk in its
  ``__post_init__`` (:func:`check_fields`).
- A command's door that reads keys of the composed config (:mod:`eval.config_check`,
  :mod:`defaust.cli`) reads each key once (:func:`config_value`) and checks the value
  read (:func:`check_number`, :func:`check_bool`, :func:`check_int_list`).

OmegaConf is imported only when a value is read from a config.
"""
from __future__ import annotations

import dataclasses
import math

from sshade.errors import SShaDeError
from sshade.pipeline import MAX_SEED

__all__ = ["config_value", "check_number", "check_bool", "check_int_list", "checked_field", "check_fields",
           "env_positive", "MAX_INT"]

MAX_INT = 2**31 - 1   # counts and iteration caps: int32 (numba kernels, libigl)
_MISSING = object()  # "no default": an absent key is an error
_CHECK = "harness.checks"  # the key of a field's declaration in its metadata


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


def check_number(value, key: str, *, kind=int, min=None, max=None, allow_none: bool = False):  # noqa: A002
    """``value`` checked as a number and coerced to ``kind``.

    Parameters
    ----------
    value : the value as read (a config's or a record's field).
    key : dotted key the message names, e.g. ``"dataset.limit"``.
    kind : ``int`` or ``float``. An int may be written as an integral float (``1e3``);
        a bool, NaN, inf, a string or a value beyond ``max`` is refused.
    min, max : inclusive bounds (ints default to at most :data:`MAX_INT`).
    allow_none : accept ``None`` (returned as None).

    Returns
    -------
    int, float or None.

    Raises
    ------
    SShaDeError ``"<key> must be an integer in [1, 2147483647] (or null), got 'abc'"``.

    Examples
    --------
    >>> check_number(1e3, "dataset.limit", min=1)
    1000
    >>> check_number(True, "dataset.limit", min=1, allow_none=True)
    Traceback (most recent call last):
    ...
    sshade.errors.SShaDeError: dataset.limit must be an integer in [1, 2147483647] (or null), got True
    """
    if value is None and allow_none:
        return None
    hi = MAX_INT if (kind is int and max is None) else max
    bad = SShaDeError(f"{key} must be {_describe(kind, min, max if kind is float else hi, allow_none)}, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise bad
    if not math.isfinite(value):
        raise bad
    if kind is int:
        if value != int(value):
            raise bad
        value = int(value)
    else:
        value = float(value)
    if (min is not None and value < min) or (hi is not None and value > hi):
        raise bad
    return value


def env_positive(name: str, what: str, environ=None) -> float | None:
    """The finite number > 0 that environment variable ``name`` holds in ``environ``
    (default ``os.environ``), None when it is unset or blank.

    Parameters
    ----------
    name : the variable. what : what the number is, for the message (``"a number of
        seconds > 0"``). environ : mapping or None.

    Returns
    -------
    float or None.

    Raises
    ------
    SShaDeError ``"<name> must be <what>, got '<text>'"`` on anything else.

    >>> env_positive("X", "a number > 0", {"X": " 2.5 "}), env_positive("X", "a number > 0", {})
    (2.5, None)
    """
    import os

    text = (os.environ if environ is None else environ).get(name, "")
    if not text.strip():
        return None
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise SShaDeError(f"{name} must be {what}, got {text!r}")
    return v


def check_bool(value, key: str) -> bool:
    """``value`` checked as a flag (YAML ``true``/``false`` only; ``maybe`` or ``1`` is refused).

    Parameters
    ----------
    value : the value as read. key : dotted key the message names.

    Returns
    -------
    bool, ``value`` itself.

    Raises
    ------
    SShaDeError ``"<key> must be true or false, got 1"``.
    """
    if not isinstance(value, bool):
        raise SShaDeError(f"{key} must be true or false, got {value!r}")
    return value


def check_int_list(value, key: str, *, min=0, max=MAX_INT, allow_none: bool = True):  # noqa: A002
    """``value`` checked as a list of integers (or one integer), e.g. ``dataset.subjects``.

    Parameters
    ----------
    value : the value as read: None, a number, a list or tuple, or an OmegaConf list.
    key : dotted key the message names.
    min, max : inclusive bounds of every element. allow_none : accept ``None``.

    Returns
    -------
    list of int (one integer becomes a list of one), or None.

    Raises
    ------
    SShaDeError naming the key and the bad element, or ``null`` where it is not allowed.

    Examples
    --------
    >>> check_int_list(3, "dataset.subjects"), check_int_list([0, 2.0], "dataset.subjects")
    ([3], [0, 2])
    """
    if value is None:
        if allow_none:
            return None
        raise SShaDeError(f"{key} must be a list of integers, got null")
    from omegaconf import OmegaConf
    items = OmegaConf.to_container(value) if OmegaConf.is_config(value) else value
    items = list(items) if isinstance(items, (list, tuple)) else [items]
    out = []
    for x in items:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or x != int(x) \
                or not min <= x <= max:
            raise SShaDeError(f"{key} must be a list of integers in [{min}, {max}], got {x!r} in {items!r}")
        out.append(int(x))
    return out


@dataclasses.dataclass(frozen=True)
class _Declared:
    """A field's declared kind and bounds (:func:`checked_field`)."""

    kind: object
    min: object
    max: object
    allow_none: bool


def checked_field(kind, *, min=None, max=None, allow_none: bool = False,  # noqa: A002
                  default=dataclasses.MISSING, default_factory=dataclasses.MISSING):
    """A dataclass field with its kind and bounds declared beside it, checked by
    :func:`check_fields`.

    Parameters
    ----------
    kind : ``int``, ``float`` (:func:`check_number`), ``bool`` (:func:`check_bool`) or
        ``list[int]`` (:func:`check_int_list`: one integer or a list, a list once checked).
    min, max : inclusive bounds (of every element for ``list[int]``, there 0 and
        :data:`MAX_INT` when not given); ignored for ``bool``.
    allow_none : accept ``None``.
    default, default_factory : as :func:`dataclasses.field` (neither: a required field).

    Returns
    -------
    :class:`dataclasses.Field`, its declaration in its ``metadata``.

    Raises
    ------
    ValueError for a ``kind`` other than those four.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class Opts:
    ...     limit: int = checked_field(int, min=1, allow_none=True, default=None)
    ...     def __post_init__(self):
    ...         check_fields(self, "dataset")
    >>> Opts(limit=1e3).limit
    1000
    """
    if kind not in (int, float, bool, list[int]):
        raise ValueError(f"checked_field: kind must be int, float, bool or list[int], got {kind!r}")
    if kind == list[int]:
        min, max = (0 if min is None else min), (MAX_INT if max is None else max)  # noqa: A001
    return dataclasses.field(default=default, default_factory=default_factory,
                             metadata={_CHECK: _Declared(kind, min, max, allow_none)})


def _checked(d: _Declared, value, key: str, name: str):
    """``value`` of the field ``name`` checked as ``d`` declares, the message naming ``key``."""
    if d.kind is bool:
        return value if (value is None and d.allow_none) else check_bool(value, key)
    if d.kind == list[int]:
        return check_int_list(value, key, min=d.min, max=d.max, allow_none=d.allow_none)
    hi = MAX_SEED if (name.endswith("seed") and d.max is None) else d.max
    return check_number(value, key, kind=d.kind, min=d.min, max=hi, allow_none=d.allow_none)


def check_fields(record, section: str) -> None:
    """Check and coerce every field of the dataclass instance ``record`` declared with
    :func:`checked_field`, in field order; a field holding a dataclass instance is walked
    too, as ``<section>.<field>``.

    A number field whose name ends in ``seed`` (and declares no ``max``) is at most
    :data:`sshade.pipeline.MAX_SEED`. Coerced values are set back (on a frozen
    dataclass too): an int written ``1e3`` becomes ``1000``, a float field's ``0`` ``0.0``.

    Parameters
    ----------
    record : a dataclass instance (frozen or not).
    section : the config section the messages name, e.g. ``"dataset"``.

    Raises
    ------
    SShaDeError naming the first bad field as ``<section>.<field>`` and its value,
    e.g. ``"dataset.limit must be an integer in [1, 2147483647] (or null), got 'abc'"``.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class Tosca:
    ...     min_vertices: int = checked_field(int, min=0, allow_none=True, default=None)
    >>> check_fields(Tosca(min_vertices=-1), "tosca")
    Traceback (most recent call last):
    ...
    sshade.errors.SShaDeError: tosca.min_vertices must be an integer in [0, 2147483647] (or null), got -1
    """
    for f in dataclasses.fields(record):
        value, key = getattr(record, f.name), f"{section}.{f.name}"
        declared = f.metadata.get(_CHECK)
        if declared is not None:
            object.__setattr__(record, f.name, _checked(declared, value, key, f.name))
        elif dataclasses.is_dataclass(value) and not isinstance(value, type):
            check_fields(value, key)

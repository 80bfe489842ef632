"""The one small interface every deformation method implements (SShaDe, the baselines,
plug-ins): :class:`Deformer`, and the rule for a method's name (:func:`check_name`, the
row label of every table). The harness builds methods from their configs.

Example::

    >>> from sshade import SShaDe
    >>> isinstance(SShaDe(), Deformer), check_name("SShaDe-500")
    (True, 'SShaDe-500')
"""
from __future__ import annotations

import re
from typing import Protocol, runtime_checkable

import numpy as np

from .errors import SShaDeError

__all__ = ["Deformer", "check_name", "NAME_RULE", "is_plugin"]


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


def is_plugin(method) -> bool:
    """True for a method that is not one of this project's (its class is defined outside
    the ``sshade`` and ``baselines`` packages): the evaluator records any exception such
    a method raises on a case, not only :class:`SShaDeError`."""
    mod = type(method).__module__ or ""
    return mod.split(".")[0] not in ("sshade", "baselines")

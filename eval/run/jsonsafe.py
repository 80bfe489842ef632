"""Any value as plain JSON data, for the files the evaluator writes.

:func:`json_safe` turns numpy scalars and arrays, NaN and inf, non-text mapping keys and
other objects into what :mod:`json` writes as is: the result store's records and keys
(:mod:`eval.run.result_store`), a method's ``info``, the report's views, the exchange layout.
On the evaluator's ground floor (:mod:`eval.run`), so that every floor above may use it.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["json_safe"]


def json_safe(v, depth: int = 0):
    """``v`` as plain JSON data: numpy scalars/arrays as Python numbers/lists, NaN and
    inf as None, mapping keys as text, anything else by its text (at most 500
    characters); nesting deeper than 8 levels becomes its text.

    >>> json_safe({"a": np.float64("nan"), 1: np.arange(2), "b": (True, 2.5)})
    {'a': None, '1': [0, 1], 'b': [True, 2.5]}
    """
    if isinstance(v, np.generic):
        v = v.item()
    if v is None or isinstance(v, (bool, int, str)):
        return v
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if depth > 8:
        return str(v)[:500]
    if isinstance(v, np.ndarray):
        v = v.tolist()
    if isinstance(v, dict):
        return {str(k): json_safe(x, depth + 1) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_safe(x, depth + 1) for x in v]
    return str(v)[:500]

"""Fast unique over int64 keys (sort-based).

numpy >= 2.3 routes ``np.unique`` on integers through a hash table that is several times
slower than sorting for the million-element edge-key arrays of 100k+ vertex meshes
(about ten times slower at 170k vertices, benchmarks/remesh_speed.py), so the hot paths use
this instead.
"""
from __future__ import annotations

import numpy as np

__all__ = ["unique_int"]


def unique_int(keys: np.ndarray, return_index: bool = False, return_inverse: bool = False,
               return_counts: bool = False):
    """``np.unique`` for a 1-D integer array, by sorting.

    Parameters
    ----------
    keys : (k,) int64.

    Returns
    -------
    uniq : (u,) sorted unique keys, followed (in this order, when asked) by
    index : (u,) first occurrence of each (in sorted, stable order),
    inverse : (k,) index of each key in ``uniq``, counts : (u,).

    Examples
    --------
    >>> u, inv, c = unique_int(np.array([5, 1, 5, 3]), return_inverse=True, return_counts=True)
    >>> u.tolist(), inv.tolist(), c.tolist()
    ([1, 3, 5], [2, 0, 2, 1], [1, 1, 2])
    """
    keys = np.asarray(keys)
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    flag = np.empty(len(sk), bool)
    if len(sk):
        flag[0] = True
        np.not_equal(sk[1:], sk[:-1], out=flag[1:])
    uniq = sk[flag]
    out = [uniq]
    if return_index:
        out.append(order[flag])
    if return_inverse:
        inv = np.empty(len(keys), np.int64)
        inv[order] = np.cumsum(flag) - 1
        out.append(inv)
    if return_counts:
        idx = np.flatnonzero(flag)
        out.append(np.diff(np.append(idx, len(sk))))
    return out[0] if len(out) == 1 else tuple(out)

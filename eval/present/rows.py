"""Which rows of a per-case frame count, and in which order the methods go: the
helpers every table, breakdown and stopping record of :mod:`eval.tables` and
:mod:`eval.present` share."""
from __future__ import annotations

from typing import TYPE_CHECKING

from harness.method_registry import table_order

if TYPE_CHECKING:  # pandas is imported where a table is built
    import pandas as pd

__all__ = ["method_order_key", "methods_in", "ok_mask"]


def method_order_key(m: str) -> tuple:
    """Sort key of a method's rows: its place in :func:`harness.method_registry.table_order`,
    any other method after those, by name."""
    order = table_order()
    return (order.index(m), "") if m in order else (len(order), m)


def methods_in(df: pd.DataFrame) -> list:
    """The frame's methods in table order (ARAP, Elastic, ..., SShaDe, others by name)."""
    return sorted(df["method"].unique(), key=method_order_key)


def ok_mask(df: pd.DataFrame) -> pd.Series:
    """Which rows are successful runs.

    Parameters
    ----------
    df : per-case rows; the ``error`` column (optional) holds the failure message, empty
        or missing (NaN, e.g. an all-empty column read back from ``cases.csv``) on success.

    Returns
    -------
    bool Series aligned with ``df.index``; all True without an ``error`` column.
    (No ``fillna("")``: on the float64 column that ``pd.read_csv`` makes of an all-empty
    ``error`` column, that is deprecated in pandas and will raise.)
    """
    import pandas as pd
    if "error" not in df.columns:
        return pd.Series(True, index=df.index)
    err = df["error"]
    return err.isna() | (err.astype(str).str.len() == 0)

"""benchmarks/table_change.py: which non-time columns of a cases.csv changed between two
versions, paired by case and method."""
from __future__ import annotations

import importlib.util

import numpy as np
import pandas as pd

from tests.conftest import ROOT

_spec = importlib.util.spec_from_file_location("table_change", ROOT / "benchmarks" / "table_change.py")
table_change = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(table_change)


def _cases() -> pd.DataFrame:
    return pd.DataFrame({"case": ["s0_p1", "s0_p1", "s0_p2", "s0_p2"], "method": ["ARAP", "SShaDe"] * 2,
                         "volume_err_pct": [1.25, 2.5, 3.0, 4.0], "time_s": [1.0, 2.0, 3.0, 4.0],
                         "s_per_iter": [0.1, 0.2, 0.3, 0.4], "status": ["converged"] * 4,
                         "alpha": [np.nan] * 4})


def test_a_table_against_itself_reordered_and_retimed_has_no_change():
    a = _cases()
    b = a.iloc[::-1].copy()
    b["time_s"] *= 3
    b["s_per_iter"] += 1
    changes, unpaired = table_change.table_change(a, b)
    assert changes == [] and unpaired == []


def test_a_changed_cell_is_named_with_its_difference_and_the_digits_that_agree():
    a, b = _cases(), _cases()
    b.loc[1, "volume_err_pct"] = 2.5001  # SShaDe s0_p1: relative change 4e-5, four digits agree
    b.loc[2, "status"] = "stalled"
    changes, _ = table_change.table_change(a, b)
    by = {(c["method"], c["column"]): c for c in changes}
    assert set(by) == {("SShaDe", "volume_err_pct"), ("ARAP", "status")}
    vol = by["SShaDe", "volume_err_pct"]
    assert vol["differ"] == 1 and vol["paired"] == 2 and vol["digits"] == "4"
    assert np.isclose(vol["max_abs"], 1e-4) and np.isclose(vol["max_rel"], 1e-4 / 2.5001)
    assert by["ARAP", "status"]["values"] == "converged -> stalled"


def test_a_value_that_appears_or_vanishes_counts_as_a_change_and_unpaired_rows_are_listed():
    a, b = _cases(), _cases()
    b.loc[0, "alpha"] = 0.01
    b = b.drop(index=3)
    changes, unpaired = table_change.table_change(a, b)
    assert [(c["method"], c["column"], c["differ"]) for c in changes] == [("ARAP", "alpha", 1)]
    assert unpaired == ["s0_p2 SShaDe: before only"]

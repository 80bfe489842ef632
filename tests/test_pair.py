"""eval/experiments/cases/pair.py: a stored pair logs its one summary line; a pair run again
for a figure (case_outputs.rerun_output: nothing stored) logs none."""
from __future__ import annotations

import logging

import numpy as np

from eval.experiments.cases.case_outputs import rerun_output
from eval.experiments.cases.pair import run_and_store
from tests.test_metric_meshes import _Case, _deformed, _NoRefs, _Shift, _sphere

GUARD = {"timeout_s": None, "handle_error_max_pct": None}


class _Store:
    def __init__(self):
        self.saved = []

    def save(self, case, method, key, fields, row, info, U):
        self.saved.append((case, method))


def _summaries(caplog):
    return [r.getMessage() for r in caplog.records if r.name.startswith("eval") and " vol " in r.getMessage()]


def test_a_stored_pair_logs_its_summary_and_a_figures_rerun_logs_none(caplog):
    V, F = _sphere(2)
    case = _Case(V, F, _deformed(V, 3), "c0")
    store = _Store()
    with caplog.at_level(logging.INFO, logger="eval"):
        rec, U, _, _ = run_and_store(_Shift(), "Shift", case, _NoRefs(), GUARD, None, store, "k", {})
    lines = _summaries(caplog)
    assert store.saved == [("c0", "Shift")] and len(lines) == 1 and lines[0].startswith("c0 Shift")
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="eval"):
        again = rerun_output(_Shift(), "Shift", case, GUARD)
    assert _summaries(caplog) == [] and np.array_equal(again, U)

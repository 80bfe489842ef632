"""eval.run.row_check: a table says whether its rows are the result store's."""
from __future__ import annotations

import json
import os

import pandas as pd
import pytest

from eval.run.result_store import record_digest
from eval.run.row_check import check_rows
from eval.tables import retabulate
from sshade.errors import SShaDeError

from .test_fuzz_store import _stored


def _folder(tmp_path):
    """A run folder: a store of two records and the cases.csv made from them."""
    st, _ = _stored(tmp_path)
    rows = [json.loads(p.read_text())["row"] for p in sorted(st.root.glob("*/*.json"))]
    pd.DataFrame(rows).to_csv(tmp_path / "cases.csv", index=False)
    return st


def test_rows_read_back_from_cases_csv_match_their_records(tmp_path):
    _folder(tmp_path)
    c = check_rows(pd.read_csv(tmp_path / "cases.csv"), tmp_path)
    assert c.ok and c.n_checked == 2 and c.line().startswith("Rows checked: all 2 rows")


def test_a_cell_edited_in_cases_csv_is_named_with_both_values(tmp_path):
    _folder(tmp_path)
    df = pd.read_csv(tmp_path / "cases.csv")
    df.loc[df["method"] == "B", "volume_err_pct"] = 0.75
    c = check_rows(df, tmp_path)
    assert not c.ok and c.n_checked == 1
    assert c.problems == ["s0_p2 / B: volume_err_pct 0.75 in cases.csv, 1.5 in the record"]
    assert "**Rows disagree with the result store:** 1 of 2 rows" in c.line()


def test_a_record_edited_by_hand_or_missing_or_linked_makes_its_row_unchecked(tmp_path):
    st = _folder(tmp_path)
    df = pd.read_csv(tmp_path / "cases.csv")
    p = st.path("s0_p1", "A")
    rec = json.loads(p.read_text())
    rec["row"]["volume_err_pct"] = 0.75
    p.write_text(json.dumps(rec))
    st.path("s0_p2", "B").unlink()
    c = check_rows(df, tmp_path)
    assert c.n_checked == 0
    assert c.problems == ["s0_p1 / A: record invalid: edited (its digest does not match)"]
    assert c.absent == ["s0_p2 / B"] and not c.ok  # no record (a killed worker): said apart, not as a disagreement
    line = c.line()
    assert "1 of 2 rows of cases.csv do not match" in line and "**Rows without a record:** 1 of 2" in line
    assert "resume=true" in line
    outside = tmp_path.parent / (tmp_path.name + "_outside")
    outside.mkdir()
    os.rename(p.parent, outside / "s0_p1")
    os.symlink(outside / "s0_p1", p.parent)
    assert "link" in check_rows(df, tmp_path).problems[0]


def test_a_re_signed_record_passes_as_the_docs_say(tmp_path):
    """The digest is unkeyed: a record edited and given a new digest is not caught (and
    the row made from it matches). docs/protocols.md says so."""
    st = _folder(tmp_path)
    p = st.path("s0_p1", "A")
    rec = json.loads(p.read_text())
    rec["row"]["volume_err_pct"] = 0.75
    rec["digest"] = record_digest(rec)
    p.write_text(json.dumps(rec))
    df = pd.read_csv(tmp_path / "cases.csv")
    df.loc[df["method"] == "A", "volume_err_pct"] = 0.75
    assert check_rows(df, tmp_path).ok


def test_retabulated_table_says_checked_or_disagreeing_or_unchecked(tmp_path):
    _folder(tmp_path)
    retabulate(tmp_path)
    assert "Rows checked: all 2 rows" in (tmp_path / "table.md").read_text()
    df = pd.read_csv(tmp_path / "cases.csv")
    df.loc[0, "time_s"] = 0.01
    df.to_csv(tmp_path / "cases.csv", index=False)
    table = (tmp_path / "table.md").read_text()
    with pytest.raises(SShaDeError, match="cases.csv: s0_p1 / A: time_s 0.01 in cases.csv, 0.25 in the record; its "
                                          "rows disagree with their records: nothing is made from them"):
        retabulate(tmp_path)  # no table from rows the store does not hold
    assert (tmp_path / "table.md").read_text() == table
    assert "Rows disagree with the result store" in check_rows(df, tmp_path).line()
    bare = tmp_path / "bare"
    bare.mkdir()
    df.to_csv(bare / "cases.csv", index=False)
    retabulate(bare)
    assert "Rows not checked: this folder has no result store" in (bare / "table.md").read_text()


@pytest.mark.parametrize("column", ["case", "method"])
def test_rows_without_case_or_method_columns_disagree_with_the_store(tmp_path, column):
    _folder(tmp_path)
    df = pd.read_csv(tmp_path / "cases.csv").drop(columns=[column])
    c = check_rows(df, tmp_path)
    assert not c.ok and "2 of 2 rows" in c.line() and "no case and method columns" in c.line()

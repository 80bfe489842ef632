"""Whether a table's rows are the result store's: every row of ``cases.csv`` held against
the record of its (case, method) in ``runs/`` (:mod:`eval.run.result_store`).
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

:func:`check_rows` reads each row's record as untrusted input (:meth:`ResultStore.read`:
whole, of this store version, naming that pair, its digest holding, a valid row) and
compares the row's cells with the record's (numbers equal to float64 rounding, text
equal, empty equal to null). :class:`RowCheck.line` is the sentence ``table.md`` carries
under its title: checked, not checked (no store), or which rows disagree and how."""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from eval.run.result_store import STORE_DIR, ResultStore
from sshade.errors import SShaDeError
from sshade.json_file import read_bounded

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["RowCheck", "check_rows", "checked_cases", "read_cases", "cell_differs", "shown_cell", "MAX_LISTED",
           "MAX_CASES_BYTES"]

MAX_LISTED = 3  #: rows named in the line when more disagree
OLDER = "older"  # _row_problem: a record of another store version
#: The largest ``cases.csv`` read (bytes): a row is well under 2 KiB, a run a few thousand rows.
MAX_CASES_BYTES = 256 * 2**20


def read_cases(path) -> pd.DataFrame:
    """A run's ``cases.csv`` (or another table of rows) read as untrusted input: a regular
    file of at most :data:`MAX_CASES_BYTES` (:func:`sshade.json_file.read_bounded`: a FIFO,
    a device or a sparse giant is refused before it is read). Raises OSError (missing, not
    a regular file, too large) or ValueError (no CSV)."""
    import io

    import pandas as pd

    return pd.read_csv(io.BytesIO(read_bounded(path, MAX_CASES_BYTES)))


class RowCheck(NamedTuple):
    """The outcome of :func:`check_rows`: ``n_rows`` rows, ``n_checked`` of them matching
    a valid record, ``problems`` one text per row whose record is invalid or says other
    numbers ("<case> / <method>: why"), ``has_store`` whether the folder has a ``runs/``
    store at all, ``absent`` the rows ("<case> / <method>") that have no record (their run
    ended before storing it: a killed worker, an interrupted run), ``older`` those whose
    record is of another store version (not comparable here; the tables mark them as made
    by older code, :mod:`eval.run.stale_rows`)."""
    n_rows: int
    n_checked: int
    problems: list
    has_store: bool
    absent: list = []
    older: list = []

    @property
    def ok(self) -> bool:
        """Every row matches its record."""
        return self.has_store and not self.problems and not self.absent and not self.older

    def line(self) -> str:
        """One sentence for ``table.md`` (Markdown)."""
        if not self.has_store:
            return (f"Rows not checked: this folder has no result store ({STORE_DIR}/), so nothing says that "
                    "cases.csv holds what the methods computed.")
        if not self.problems and not self.absent and not self.older:
            return (f"Rows checked: all {self.n_rows} rows of cases.csv match their records in {STORE_DIR}/ "
                    "(digests hold; a digest catches a record edited by hand, not one re-signed).")
        out = []
        if self.older:
            out.append(f"{len(self.older)} of {self.n_rows} rows have a record of an older store version "
                       f"({_listed(self.older)}): not checked here.")
        if self.problems:
            n_bad = self.n_rows - self.n_checked - len(self.absent) - len(self.older)
            out.append(f"**Rows disagree with the result store:** {n_bad} of {self.n_rows} rows of "
                       f"cases.csv do not match a valid record in {STORE_DIR}/ ({_listed(self.problems)}); the table "
                       "is not what the store holds.")
        if self.absent:
            out.append(f"**Rows without a record:** {len(self.absent)} of {self.n_rows} rows of cases.csv have no "
                       f"record in {STORE_DIR}/ ({_listed(self.absent)}): their run ended before storing it (a "
                       "killed worker, an interrupted run); python -m eval with resume=true computes them again.")
        return " ".join(out)


def _listed(items: list) -> str:
    return "; ".join(items[:MAX_LISTED]) + (" ..." if len(items) > MAX_LISTED else "")


def _missing(v) -> bool:
    return v is None or (isinstance(v, float) and math.isnan(v)) or (isinstance(v, str) and v == "")


def cell_differs(a, b) -> bool:
    """Whether a cell read back from ``cases.csv`` (``a``) differs from the record's (``b``):
    numbers unequal beyond float64 rounding, text unequal, one empty and not the other."""
    if _missing(a) or _missing(b):
        return not (_missing(a) and _missing(b))
    if isinstance(b, bool) or isinstance(a, bool):
        return str(a).lower() != str(b).lower()
    if isinstance(b, (int, float)):
        try:
            fa, fb = float(a), float(b)
        except (TypeError, ValueError):
            return True
        return not (fa == fb or math.isclose(fa, fb, rel_tol=1e-12, abs_tol=0.0))
    return str(a) != str(b)


def shown_cell(v) -> str:
    """A cell as a message shows it: a number as Python writes it (a NumPy scalar too),
    text quoted."""
    v = v.item() if hasattr(v, "item") and not isinstance(v, (str, bytes)) else v
    return repr(v)


def _row_problem(store: ResultStore, row: dict) -> tuple[bool, str | None]:
    """``(absent, problem)`` of one row: whether its record is absent, else the text of
    what is wrong with it or its cells (None when it matches)."""
    case, method = str(row.get("case")), str(row.get("method"))
    try:
        found = store.read(case, method)
    except SShaDeError as e:
        return False, f"{case} / {method}: {e}"
    if found.record is None:
        if found.why == "absent":
            return True, None
        if str(found.why).startswith("other code: store version"):
            return False, OLDER
        return False, f"{case} / {method}: record {found.why}"
    stored = found.record["row"]
    diff = [k for k in sorted(set(stored) | set(row)) if cell_differs(row.get(k), stored.get(k))]
    if diff:
        k = diff[0]
        return False, (f"{case} / {method}: {k} {shown_cell(row.get(k))} in cases.csv, {shown_cell(stored.get(k))} "
                       "in the record"
                       + (f" (+{len(diff) - 1} more cells)" if len(diff) > 1 else ""))
    return False, None


def check_rows(df: pd.DataFrame, out_dir) -> RowCheck:
    """Hold every row of ``df`` (the rows of ``cases.csv``, with ``case`` and ``method``
    columns) against the result store of ``out_dir`` (module docstring).

    Parameters
    ----------
    df : pandas DataFrame, one row per (case, method).
    out_dir : str or Path, the run's folder (its store is ``out_dir/runs``).

    Returns
    -------
    :class:`RowCheck`. Never raises on a bad record or a link: each is a problem of its row.
    """
    store = ResultStore(Path(out_dir))
    if not (Path(out_dir) / STORE_DIR).is_dir():
        return RowCheck(len(df), 0, [], False)
    if "case" not in df.columns or "method" not in df.columns:
        return RowCheck(len(df), 0, ["cases.csv has no case and method columns to find records by"], True)
    problems, absent, older = [], [], []
    for r in df.to_dict("records"):
        gone, problem = _row_problem(store, r)
        if gone:
            absent.append(f"{r.get('case')} / {r.get('method')}")
        elif problem is OLDER:
            older.append(f"{r.get('case')} / {r.get('method')}")
        elif problem:
            problems.append(problem)
    return RowCheck(len(df), len(df) - len(problems) - len(absent) - len(older), problems, True, absent, older)


def checked_cases(run_dir) -> pd.DataFrame:
    """A run's ``cases.csv`` (:func:`read_cases`) when every row of it is its record's
    (:func:`check_rows`; a folder without a store is taken as it is): what a reader of the
    folder (a table, a report, a board) may show. Raises SShaDeError naming the file and
    the first row that disagrees, or that it cannot be read (missing, not a regular file,
    too large, no CSV)."""
    p = Path(run_dir) / "cases.csv"
    try:
        df = read_cases(p)
    except (OSError, ValueError) as e:
        raise SShaDeError(f"{p}: cannot be read ({getattr(e, 'strerror', None) or e})") from None
    bad = check_rows(df, run_dir).problems
    if bad:  # a table is made from the store's rows, never from rows that disagree with it
        raise SShaDeError(f"{p}: {bad[0]}" + (f" (and {len(bad) - 1} more rows)" if len(bad) > 1 else "")
                          + "; its rows disagree with their records: nothing is made from them")
    return df

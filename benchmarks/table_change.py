"""Which non-time columns of a results folder's per-case table changed between two commits.

The rows of ``<folder>/cases.csv`` at two git revisions (the second: the file on disk by
default) are paired by case and method; every column that is not a time or a figure of
the machine (``*_s``, ``s_per_iter``, ``workers``, ``threads``) is compared. Prints, per
method and changed column, how many paired cases differ, the largest absolute and relative
difference and the significant digits the two agree to in the worst case (a text column:
the differing values); then the rows found on one side only. Exit 0 also when columns
differ: it reports, it does not judge.

    python benchmarks/table_change.py results/faust --before 6ddad2e
    python benchmarks/table_change.py results/defaust --before 6ddad2e --after 3e79476 --columns gt_vertex_mean_pct
"""
import argparse
import io
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository, as the other benchmarks

from harness.command import run_command  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
KEY = ("case", "method")
MACHINE = ("s_per_iter", "workers", "threads")


def read_cases(folder: str, rev: str | None) -> pd.DataFrame:
    """``folder``/cases.csv at git revision ``rev`` of this repository (None: on disk).

    Raises
    ------
    OSError: the file is missing at that revision or on disk.
    """
    path = Path(folder) / "cases.csv"
    if rev is None:
        text = path.read_text()
    else:
        rel = (ROOT / path).resolve().relative_to(ROOT) if path.is_absolute() else path
        p = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{rel.as_posix()}"], capture_output=True, text=True)
        if p.returncode != 0:
            raise OSError(f"{rel} at {rev}: {p.stderr.strip() or 'not found'}")
        text = p.stdout
    return pd.read_csv(io.StringIO(text), keep_default_na=False, na_values=[""], dtype={"case": str})


def compared_columns(a: pd.DataFrame, b: pd.DataFrame, only=None) -> list[str]:
    """The columns of both tables that a change of code, not of machine, would move."""
    cols = [c for c in a.columns if c in b.columns and c not in KEY]
    cols = [c for c in cols if not c.endswith("_s") and c not in MACHINE]
    return [c for c in cols if c in only] if only else cols


def _numeric_change(x: pd.Series, y: pd.Series) -> dict | None:
    both = x.notna() & y.notna()
    nan_flip = int((x.isna() != y.isna()).sum())
    d = (x[both] - y[both]).abs()
    scale = np.maximum(x[both].abs(), y[both].abs())
    rel = (d / scale.where(scale > 0, 1.0)).fillna(0.0)
    n = int((d > 0).sum()) + nan_flip
    if n == 0:
        return None
    worst = float(rel.max()) if len(rel) else 0.0
    digits = "all" if worst == 0 else f"{max(0, math.floor(-math.log10(worst)))}"
    if nan_flip:  # a value that appears or vanishes agrees to no digit
        digits = f"{digits}; {nan_flip} appeared or vanished"
    return {"differ": n, "max_abs": float(d.max()) if len(d) else math.nan, "max_rel": worst, "digits": digits}


def _text_change(x: pd.Series, y: pd.Series) -> dict | None:
    diff = ~(x.isna() & y.isna()) & (x.astype(str) != y.astype(str))
    if not diff.any():
        return None
    pairs = sorted({f"{u} -> {v}" for u, v in zip(x[diff], y[diff])})
    return {"differ": int(diff.sum()), "values": "; ".join(pairs[:3]) + (" ..." if len(pairs) > 3 else "")}


def _is_numeric(x: pd.Series) -> bool:
    return pd.api.types.is_numeric_dtype(x) or bool(x.isna().all())


def table_change(a: pd.DataFrame, b: pd.DataFrame, only=None) -> tuple[list[dict], list[str]]:
    """Per method and column, the change from ``a`` to ``b``; and the rows on one side only.

    Returns
    -------
    changes: dicts with ``method``, ``column``, ``paired`` and ``differ`` (cases), and
        ``max_abs``, ``max_rel``, ``digits`` for a numeric column or ``values`` for text.
    unpaired: ``"case method: before only"`` / ``"... after only"`` lines.
    """
    a2, b2 = a.set_index(list(KEY)), b.set_index(list(KEY))
    both = a2.index.intersection(b2.index, sort=False)
    unpaired = ([f"{c} {m}: before only" for c, m in a2.index.difference(b2.index)]
                + [f"{c} {m}: after only" for c, m in b2.index.difference(a2.index)])
    changes = []
    for method in dict.fromkeys(both.get_level_values("method")):
        rows = both[both.get_level_values("method") == method]
        for c in compared_columns(a, b, only):
            x, y = a2.loc[rows, c], b2.loc[rows, c]
            if _is_numeric(x) and _is_numeric(y):
                ch = _numeric_change(x.astype(float), y.astype(float))
            else:
                ch = _text_change(x, y)
            if ch:
                changes.append({"method": method, "column": c, "paired": len(rows), **ch})
    return changes, unpaired


def _print(folder, before, after, changes, unpaired) -> None:
    print(f"### {folder}/cases.csv: {before} -> {after or 'on disk'}\n")
    if not changes:
        print("every compared column equal on every paired row\n")
    else:
        print("| Method | Column | Cases differing | Max abs | Max rel | Digits agreeing |")
        print("|---|---|---:|---:|---:|---|")
        for c in changes:
            if "values" in c:
                print(f"| {c['method']} | {c['column']} | {c['differ']}/{c['paired']} | {c['values']} | | |")
            else:
                print(f"| {c['method']} | {c['column']} | {c['differ']}/{c['paired']} | {c['max_abs']:.3g} | "
                      f"{c['max_rel']:.3g} | {c['digits']} |")
        print()
    for line in unpaired:
        print(f"- {line}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python benchmarks/table_change.py", description=__doc__.split("\n\n")[0])
    p.add_argument("folder", help="a results folder with a cases.csv, e.g. results/faust")
    p.add_argument("--before", required=True, help="git revision of the earlier table")
    p.add_argument("--after", help="git revision of the later table (default: the file on disk)")
    p.add_argument("--columns", nargs="+", help="compare only these columns")
    a = p.parse_args(argv)

    def run() -> int:
        old, new = read_cases(a.folder, a.before), read_cases(a.folder, a.after)
        _print(a.folder, a.before, a.after, *table_change(old, new, a.columns))
        return 0
    return run_command(run, where=a.folder)


if __name__ == "__main__":
    raise SystemExit(main())

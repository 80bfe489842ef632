"""eval.present.measures: each measure's label, decimals and kind written once, and the
tables, breakdown, report and leaderboard taking them from there."""
import ast
from pathlib import Path

from eval.present.breakdown import BREAKDOWN_METRICS
from eval.present.measures import EXTRA, MAIN, MEASURES, label
from eval.present.table_markup import EXTRA_COLUMNS, NO_BOLD, TABLE_COLUMNS

ROOT = Path(__file__).resolve().parents[1]
#: The modules that show measures and take their labels from eval.present.measures.
USERS = ("eval/present/table_markup.py", "eval/present/breakdown.py", "eval/tables.py", "eval/report.py",
         "eval/leaderboard.py")


def _strings(path: Path) -> set[str]:
    """String constants of a module, docstrings left out."""
    tree = ast.parse(path.read_text())
    docs = {id(n.body[0].value) for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and n.body
            and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    return {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)
            and id(n) not in docs}


def test_no_module_that_shows_measures_restates_a_label():
    labels = {m.label for m in MEASURES.values()}
    for rel in USERS:
        again = labels & _strings(ROOT / rel)
        assert not again, f"{rel} restates {sorted(again)}: take them from eval.present.measures"


def test_the_tables_columns_are_the_measures_in_their_order():
    assert [c[0] for c in TABLE_COLUMNS] == list(MAIN) and [c[0] for c in EXTRA_COLUMNS] == list(EXTRA)
    assert all(h == label(k) and d == MEASURES[k].decimals for k, h, _, d, _ in TABLE_COLUMNS)
    assert all(h == label(k) for k, h in BREAKDOWN_METRICS)
    assert set(NO_BOLD) == {"iterations", "converged"}

"""eval.present.measures: each measure's and column's label, decimals and kind written once,
and the tables, breakdown, report, leaderboard and experiments taking them from there; a
new measure is its function and one registry entry."""
import ast
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from eval.present.breakdown import BREAKDOWN_METRICS
from eval.present.measures import COUNTS, EXTRA, MAIN, MEASURES, TABLES, columns, label
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


def _registry_labels() -> set[str]:
    """Every header the registry writes that is not its column's key itself."""
    cols = [*COUNTS, *(c for t in TABLES.values() for c in t)]
    return {m.label for m in MEASURES.values()} | {c.label for c in cols if c.label != c.key}


def test_no_module_that_shows_measures_restates_a_label():
    labels = {m.label for m in MEASURES.values()}
    for rel in USERS:
        again = labels & _strings(ROOT / rel)
        assert not again, f"{rel} restates {sorted(again)}: take them from eval.present.measures"


def test_no_module_of_eval_restates_a_column_label_of_the_registry():
    """Grep level: no string constant (docstrings aside) of any module of eval/ but the
    registry's is one of its headers (a measure's, a count's, an experiment table's)."""
    labels = _registry_labels()
    found = {}
    for path in sorted((ROOT / "eval").rglob("*.py")):
        if path.relative_to(ROOT).as_posix() == "eval/present/measures.py":
            continue
        again = labels & _strings(path)
        if again:
            found[path.relative_to(ROOT).as_posix()] = sorted(again)
    assert not found, f"column labels restated outside eval/present/measures.py: {found}"


def test_no_module_of_eval_spells_a_measure_label_inside_any_text():
    """Substring level, docstrings and f-strings included: a measure's label with its unit
    ("EL (%)", "Time (s)") appears in eval/present/measures.py only, so renaming one
    renames every header, sentence and example."""
    labels = {m.label for m in MEASURES.values() if "(" in m.label}
    found = {p.relative_to(ROOT).as_posix(): sorted(lb for lb in labels if lb in p.read_text())
             for p in sorted((ROOT / "eval").rglob("*.py")) if p.name != "measures.py" or p.parent.name != "present"}
    assert not {k: v for k, v in found.items() if v}, found


def test_each_experiment_table_takes_its_columns_from_the_registry():
    from eval.experiments import animation, pose_transfer, tosca
    from eval.experiments.scaling import scaling_table
    assert tosca.TOSCA_COLUMNS == columns("tosca") and pose_transfer._COLUMNS == columns("pose_transfer")
    assert animation._COLUMNS == columns("animation") and tuple(scaling_table._COLS) == columns("scaling")
    assert [label(c.key) for c in COUNTS] == [c.label for c in COUNTS]
    for table, cols in TABLES.items():
        keys = [c.key for c in cols]
        assert len(keys) == len(set(keys)), table


def test_the_tables_columns_are_the_measures_in_their_order():
    assert [c[0] for c in TABLE_COLUMNS] == list(MAIN) and [c[0] for c in EXTRA_COLUMNS] == list(EXTRA)
    assert all(h == label(k) and d == MEASURES[k].decimals for k, h, _, d, _ in TABLE_COLUMNS)
    assert all(h == label(k) for k, h in BREAKDOWN_METRICS)
    assert set(NO_BOLD) == {"iterations", "converged"}


#: The toy measure: its function's one line (in deformation_metrics' dict of errors) and its
#: registry entry, as a maintainer adding a measure writes them (docs/layout.md).
_TOY_ROW = '        "toy_pct": 100.0 * float(np.abs(Vd - V).max()) / max(float(np.ptp(V, axis=0).max()), 1e-300),\n'
_TOY_MEASURE = '    Measure("toy_pct", "Toy move (%)", 2),\n'


def _copy_tree(dst: Path) -> None:
    """The repository's code and config (no results, data, outputs or history) into ``dst``."""
    skip = {".git", "results", "data", "outputs", "asv_results", "__pycache__", ".pytest_cache", "node_modules"}
    shutil.copytree(ROOT, dst, ignore=lambda d, names: [n for n in names if n in skip or n.endswith(".egg-info")])


@pytest.mark.slow
def test_a_toy_measure_is_its_function_and_one_registry_entry(tmp_path, faust_root):
    """In a copy of the repository, a measure added by one line of
    :func:`eval.metrics.measures.deformation_metrics` and one entry of the registry (its
    :class:`Measure` and its place in ``EXTRA`` and ``BROKEN_DOWN``) reaches table.md, the
    breakdown and the browser page of a run, with no other file touched."""
    repo = tmp_path / "repo"
    _copy_tree(repo)
    metrics = repo / "eval" / "metrics" / "measures.py"
    text = metrics.read_text()
    start = text.index("def deformation_metrics(")
    at = text.index("    out = {\n", start) + len("    out = {\n")
    metrics.write_text(text[:at] + _TOY_ROW + text[at:])
    reg = repo / "eval" / "present" / "measures.py"
    text = reg.read_text()
    text = text.replace('    Measure("converged", ', _TOY_MEASURE + '    Measure("converged", ', 1)
    text = re.sub(r'(EXTRA = \()', r'\1"toy_pct", ', text, count=1)
    text = re.sub(r'(BROKEN_DOWN = \()', r'\1"toy_pct", ', text, count=1)
    reg.write_text(text)
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(repo)}
    r = subprocess.run([sys.executable, "-m", "eval", "experiment=ci", f"dataset.root={faust_root}",
                        "methods=[SShaDe]", "dataset.limit=1", f"out_dir={out}"], cwd=repo, env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    for name in ("table.md", "breakdown.md", "index.html"):
        assert "Toy move (%)" in (out / name).read_text(), name
    value = __import__("pandas").read_csv(out / "cases.csv")["toy_pct"].iloc[0]
    assert 0 < value < 100

"""eval/leaderboard.py: one method x dataset board ranked by the ground-truth error
only (a method best on volume and worst on the true pose is not first), unranked where
there is no ground truth, times relative to SShaDe in the same run; written beside the
index, never over a file it did not write; the committed board is the committed runs'."""
from __future__ import annotations

import csv
import json
import re

import pandas as pd
import pytest

from eval.leaderboard import LEADERBOARD, collect, leaderboard_markdown, leaderboard_rows
from eval.report import write_index
from eval.run.compared import write_compared
from sshade.errors import SShaDeError
from tests.conftest import ROOT
from tests.current_rows import current_copy


def _run(folder, rows, kind="cases", commit="abc123", **info):
    folder.mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps({"config": {"experiment": {"name": folder.name, "kind": kind}},
                                                 "git": {"commit": commit}, "status": "done", **info}))
    with open(folder / "cases.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def _row(case, method, vol, gt, t):
    return {"case": case, "method": method, "error": "", "volume_err_pct": vol, "edge_err_pct": 1.0,
            "angle_err_deg": 1.0, "gt_vertex_mean_pct": gt, "time_s": t}


CASES = "abcdefgh"  # eight cases: enough for the paired test to separate consistent differences


def test_the_ground_truth_ranks_not_the_best_volume(tmp_path):
    rows = [_row(c, "Toy", 0.1, 9.0 + i / 10, 0.01) for i, c in enumerate(CASES)]
    rows += [_row(c, "SShaDe", 2.0, 1.5 + i / 100, 2.0) for i, c in enumerate(CASES)]
    rows += [_row(c, "ARAP", 3.0, 1.7 + i / 50, 6.0) for i, c in enumerate(CASES)]
    _run(tmp_path / "faust", rows)
    boards, _ = collect(tmp_path)
    (b,) = boards
    ranks = {r["method"]: r["rank"] for r in b.rows}
    assert ranks == {"SShaDe": 1, "ARAP": 2, "Toy": 3} and b.ranked
    times = {r["method"]: r["time_rel"] for r in b.rows}
    assert times["ARAP"] == 3.0 and times["SShaDe"] == 1.0  # x SShaDe in the same run
    head, matrix = leaderboard_rows(boards)
    assert head == ["Method", "FAUST"] and ["Toy", "9.35 (3)"] in matrix
    md = leaderboard_markdown(tmp_path)
    assert "The ranking column is GT mean" in md and "no other column ranks" in md
    assert "Wilcoxon signed-rank test" in md and "percentile bootstrap over its cases (2000 resamples, seed 0)" in md
    ci = {r["method"]: r["ci"] for r in b.rows}
    assert ci["SShaDe"][0] < 1.5 + 3.5 / 100 < ci["SShaDe"][1]  # the mean inside its interval
    assert ci == {r["method"]: r["ci"] for r in collect(tmp_path)[0][0].rows}  # seeded: the same again


@pytest.mark.parametrize("build,tag", [
    ({"canonical": True, "name": "anny-default", "mark": ""}, ""),
    ({"canonical": False, "mark": "not on the canonical DeFAUST (x differs)"}, " (not the canonical build)"),
    (None, " (build unchecked)"),  # a DeFAUST run that recorded no check of its build
    ({"canonical": True, "name": "anny-default", "rows_on_other_data": 3,  # a resumed run stopped early
      "mark": "3 pending row(s) made on other case data than this build's"}, " (3 rows on another build)"),
])
def test_a_board_on_data_other_than_the_canonical_build_says_so(tmp_path, build, tag):
    rows = [_row(c, m, 1.0, g + i / 10, 1.0) for i, c in enumerate(CASES) for m, g in (("SShaDe", 1), ("ARAP", 2))]
    config = {"experiment": {"name": "defaust", "kind": "cases"}, "dataset": {"name": "defaust"}}
    _run(tmp_path / "defaust", rows, config=config, **({"dataset_build": build} if build else {}))
    _run(tmp_path / "faust", rows)  # FAUST registrations: no canonical build, no mark
    boards, _ = collect(tmp_path)
    assert leaderboard_rows(boards)[0] == ["Method", "FAUST", "DeFAUST" + tag]
    md = leaderboard_markdown(tmp_path)
    legend = "comparable with rows of the same build only"
    assert ("Data: " in md) == bool(tag) and md.count("Data: ") <= 1 and (legend in md) == bool(tag)
    if build and tag:
        assert build["mark"] in md


def test_ranks_follow_the_paired_test_and_no_column_is_a_folder_name(tmp_path):
    """ARAP and Elastic at 1.81 on average, neither nearer case by case: one rank; SShaDe
    nearer on every case: its own; on one case no test separates anybody."""
    rng = [0.02, -0.03, 0.01, -0.01, 0.03, -0.02, 0.0, 0.01]
    rows = [_row(c, "ARAP", 1.0, 1.81 + rng[i], 1.0) for i, c in enumerate(CASES)]
    rows += [_row(c, "Elastic", 1.0, 1.81 - rng[i], 1.0) for i, c in enumerate(CASES)]
    rows += [_row(c, "SShaDe", 1.0, 1.64 + rng[i] / 2, 1.0) for i, c in enumerate(CASES)]
    _run(tmp_path / "my_defaust_run", rows)
    info = json.loads((tmp_path / "my_defaust_run" / "run.json").read_text())
    info["config"].update(dataset={"name": "defaust"}, arap={"protocol": "paper"})
    (tmp_path / "my_defaust_run" / "run.json").write_text(json.dumps(info))
    (b,) = collect(tmp_path)[0]
    assert {r["method"]: r["rank"] for r in b.rows} == {"SShaDe": 1, "ARAP": 2, "Elastic": 2}  # 1.81 and 1.81
    assert b.label == "DeFAUST (paper protocol) (my_defaust_run/)"
    assert "paper protocol's stopping rule" in b.rank_column
    md = leaderboard_markdown(tmp_path)
    assert "| ARAP | 1.81 (2) |" in md and "| Elastic | 1.81 (2) |" in md
    one = tmp_path / "one"
    one.mkdir()
    _run(one / "faust", [_row("a", "SShaDe", 1.0, 1.5, 1.0), _row("a", "ARAP", 1.0, 1.9, 1.0)])
    (b1,) = collect(one)[0]
    assert {r["rank"] for r in b1.rows} == {1} and "on one case only" in b1.rank_column


@pytest.mark.slow
def test_the_committed_board_shares_a_rank_where_the_paired_test_does_not_separate():
    boards = {b.folder: b for b in collect(ROOT / "results")[0]}
    if "defaust" not in boards:
        pytest.skip("no committed results/defaust")
    r = {x["method"]: x["rank"] for x in boards["defaust"].rows}
    assert r["ARAP"] == r["Elastic"]  # both 1.81


def test_a_dataset_without_ground_truth_ranks_nobody(tmp_path):
    rows = [_row("bunny", m, v, "", 1.0) for m, v in (("SShaDe", 0.3), ("ARAP", 3.1))]
    _run(tmp_path / "shapes", rows)
    (b,) = collect(tmp_path)[0]
    assert not b.ranked and "no ground truth" in b.why_not and all(r["rank"] is None for r in b.rows)
    assert ["ARAP", "3.10 / 1.00 / 1.00"] in leaderboard_rows([b])[1]


def test_the_index_carries_the_board_and_a_foreign_leaderboard_is_kept(tmp_path):
    _run(tmp_path / "faust", [_row("a", "SShaDe", 1.0, 1.5, 1.0), _row("a", "ARAP", 1.0, 1.6, 2.0)])
    page = write_index(tmp_path)
    text = page.read_text()
    assert text.index("Leaderboard") < text.index("run folder(s)") and "1.50 (1)" in text
    assert (tmp_path / LEADERBOARD).read_text() == leaderboard_markdown(tmp_path)
    (tmp_path / LEADERBOARD).write_text("my notes\n")
    write_index(tmp_path)
    assert (tmp_path / LEADERBOARD).read_text() == "my notes\n"


def test_the_committed_leaderboard_is_the_committed_runs_board():
    committed = ROOT / "results" / LEADERBOARD
    assert committed.is_file(), "results/leaderboard.md: python -m eval.reproduce --only report writes it"
    assert committed.read_text() == leaderboard_markdown(ROOT / "results")


def test_a_method_whose_rows_are_stale_is_marked_stale(tmp_path):
    """results/faust copied with SShaDe's records replaced by those of the earlier key layout
    (git's history): the board marks SShaDe's cell and row stale, 8 of 8, and says what
    the mark means; the other methods are unmarked; the index's status says 8 of 40."""
    import subprocess
    current_copy(ROOT / "results" / "faust", tmp_path / "faust")  # every row current, whatever the committed state
    for case in sorted(p.name for p in (tmp_path / "faust" / "runs").iterdir()):
        r = subprocess.run(["git", "-C", str(ROOT), "show", f"8d866e5:results/faust/runs/{case}/SShaDe.json"],
                           capture_output=True, text=True, timeout=60, check=False)
        if r.returncode != 0:
            import pytest
            pytest.skip("git history without 8d866e5 (a shallow clone?)")
        (tmp_path / "faust" / "runs" / case / "SShaDe.json").write_text(r.stdout)
    text = leaderboard_markdown(tmp_path)
    assert "| SShaDe [stale: 8 of 8 rows, made at 3e79476] |" in text and "[stale: k of n rows, made at C]" in text
    assert text.count("[stale:") == 3  # the matrix cell, the dataset's row, the explanation
    assert "done; 8 of 40 rows stale, made at 3e79476" in write_index(tmp_path).read_text()  # the index's status


def test_rows_their_tables_list_as_pending_are_marked_pending_and_the_rest_stale(tmp_path):
    """results/faust copied with SShaDe's records of the earlier key layout (git's history):
    with 3 of the 8 listed pending in its table.md, the mark stays stale and says 3 are
    listed; with all 8 listed, the cell, the row, the legend and the index say pending."""
    import subprocess

    from eval.run.pending_rows import PENDING_HEADING
    current_copy(ROOT / "results" / "faust", tmp_path / "faust")
    cases = sorted(p.name for p in (tmp_path / "faust" / "runs").iterdir())
    for case in cases:
        r = subprocess.run(["git", "-C", str(ROOT), "show", f"8d866e5:results/faust/runs/{case}/SShaDe.json"],
                           capture_output=True, text=True, timeout=60, check=False)
        if r.returncode != 0:
            pytest.skip("git history without 8d866e5 (a shallow clone?)")
        (tmp_path / "faust" / "runs" / case / "SShaDe.json").write_text(r.stdout)
    table = (tmp_path / "faust" / "table.md").read_text()

    def listed(k):
        rows = "".join(f"- `{c}` `SShaDe`: made at 3e79476; the key layout changed\n" for c in cases[:k])
        (tmp_path / "faust" / "table.md").write_text(f"{table}\n#### {PENDING_HEADING}\n\n{rows}")
        return leaderboard_markdown(tmp_path)

    assert "| SShaDe [stale: 8 of 8 rows (3 listed pending), made at 3e79476] |" in listed(3)
    text = listed(8)
    assert "| SShaDe [pending: 8 of 8 rows, made at 3e79476] |" in text and "[stale:" not in text
    assert "[pending: k of n rows, made at C]" in text and text.count("[pending:") == 3
    assert "done; 8 of 40 rows pending (listed in its tables), made at 3e79476" in write_index(tmp_path).read_text()


def test_a_folder_run_whole_marked_pending_has_its_cells_marked_pending(tmp_path):
    """An animation folder (run whole: one row per method in its table.csv) whose table.md
    ``--retabulate`` marked pending: each of its cells and rows carries the mark with the
    commit that made it; unmarked, none does."""
    from eval.run.pending_rows import mark_run_pending
    d = tmp_path / "animation"
    d.mkdir()
    (d / "run.json").write_text(json.dumps({"config": {"experiment": {"name": "animation", "kind": "animation"}},
                                            "git": {"commit": "c449109aaaa"}, "status": "done"}))
    (d / "table.csv").write_text("method,how,n_cases,frame_median_s,gt_mean_pct\nSShaDe,x,1,0.1,1.26\n"
                                 "Elastic,y,1,12.0,1.66\n")
    (d / "table.md").write_text("### animation\n\n| Method |\n|---|\n| SShaDe |\n")
    assert "[pending:" not in leaderboard_markdown(tmp_path)
    assert mark_run_pending(d, "c449109", "sshade.guard changed since c449109")
    text = leaderboard_markdown(tmp_path)
    mark = "[pending: 1 of 1 rows, made at c449109]"
    assert f"| 1.26 {mark} |" in text and f"| 1.66 {mark} |" in text


def test_a_users_run_with_compare_with_is_ranked_beside_the_rows_it_read(tmp_path):
    from eval.leaderboard import run_board_markdown
    run = tmp_path / "mine"
    _run(run, [_row(c, "Mine", 1.0, 1.70 + i / 100, 3.0) for i, c in enumerate(CASES)])
    assert run_board_markdown(run) is None  # no compare_with: no board of its own
    theirs = [_row(c, m, 1.0, gt + i / 100 * k, t) | {"time_other_run": True} for i, c in enumerate(CASES)
              for m, gt, t, k in (("SShaDe", 1.605, 2.0, 1.0), ("ARAP", 1.775, 60.0, 2.0))]
    write_compared(run, pd.DataFrame(theirs))
    md = run_board_markdown(run)
    assert "| 1 | SShaDe | 1.64 |" in md and "| 2 | Mine | 1.74 |" in md and "| 3 | ARAP | 1.84 |" in md
    assert re.search(r"\| 2 \| Mine \| 1.74 \| 1.7\d \.\. 1.7\d \| 1.00 \| 1.00 \| 1.000 \| -- \|", md)  # no SShaDe
    assert re.search(r"\| 3 \| ARAP \| 1.84 \| 1.8\d \.\. 1.8\d \| 1.00 \| 1.00 \| 1.000 \| -- \|", md)  # another run's
    text = (run / "compared.csv").read_text()
    (run / "compared.csv").write_text(text.replace("1.775", "0.775", 1))  # an edited number
    with pytest.raises(SShaDeError, match=r"compared.csv: .*gt_vertex_mean_pct '?0.775'? in compared.csv, 1.775 rec"):
        run_board_markdown(run)
    (run / "compared.csv").write_text(text)
    (run / "compared.json").unlink()  # no record of the rows: nothing says they are the ones read
    with pytest.raises(SShaDeError, match="cannot be checked against compared.json"):
        run_board_markdown(run)


def test_a_stale_mark_names_the_commits_and_at_most_three_modules_changed_since():
    from eval.leaderboard import stale_words
    assert stale_words(None) == "" and stale_words((0, 8, set(), set())) == ""
    assert stale_words((8, 40, {"3e79476"}, set())) == " [stale: 8 of 40 rows, made at 3e79476]"
    assert stale_words((8, 40, {"3e79476", "c449109"}, {"sshade.guard"})) == \
        " [stale: 8 of 40 rows, made at 3e79476, c449109; sshade.guard changed]"
    many = {"a", "b", "c", "d", "e"}
    assert stale_words((1, 2, {"3e79476"}, many)).endswith("; a, b, c and 2 more changed]")
    assert stale_words((8, 40, {"3e79476"}, set(), 8)) == " [pending: 8 of 40 rows, made at 3e79476]"
    assert stale_words((8, 40, {"3e79476"}, set(), 3)) == " [stale: 8 of 40 rows (3 listed pending), made at 3e79476]"

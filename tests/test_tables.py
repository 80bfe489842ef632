"""The evaluator's tables (eval/tables.py): every method on the same cases, the second
"all cases" table, the LaTeX case count, failures, the stop lines, retabulation from
cases.csv. Synthetic frames."""
from __future__ import annotations

import io
import json
import re
import warnings

import numpy as np
import pandas as pd
import pytest

from eval.tables import (
    ALL_CASES_HEADING,
    COMMON_CASES_HEADING,
    all_note,
    common_cases,
    compare,
    ok_mask,
    stop_lines,
    summarize,
    to_markdown,
    write_tables,
)


def _row(case, method, vol, *, edge=0.5, time_s=1.0, error=""):
    return dict(case=case, subject=0, pose=int(case[1:]), method=method, n_vertices=10, n_handles=3,
                volume_err_pct=vol, area_err_pct=0.1, edge_err_pct=edge, angle_err_deg=0.2, time_s=time_s,
                error=error)


def _frame(sshade_error_on: str | None = None) -> pd.DataFrame:
    """ARAP on c0, c1 (the baseline subset); SShaDe on c0..c3.

    On the common cases c0, c1 ARAP has the lower volume error (2.0 vs 3.0); SShaDe is
    perfect on c2, c3, so averaging it over its own 4 cases (1.5) would wrongly beat ARAP.
    """
    rows = []
    for i in range(4):
        c = f"c{i}"
        if i < 2:
            rows.append(_row(c, "ARAP", 2.0, edge=0.4, time_s=50.0))
        err = "SShaDeError: boom" if c == sshade_error_on else ""
        rows.append(_row(c, "SShaDe", 3.0 if i < 2 else 0.0, time_s=2.0, error=err) if not err else
                    dict(case=c, subject=0, pose=i, method="SShaDe", n_vertices=10, n_handles=3, error=err))
    return pd.DataFrame(rows)


def _tables(md: str) -> list[str]:
    """table.md split before each ``### `` heading line (each part: one table)."""
    return [part for part in re.split(r"(?m)^(?=### )", md) if part.strip()]


def _md_row(table: str, method: str) -> list[str]:
    line = next(ln for ln in table.splitlines() if ln.startswith(f"| {method} |"))
    return [c.strip() for c in line.strip("|").split("|")]


# ---------------------------------------------------------------- main table: common cases

def test_main_table_uses_only_the_common_cases(tmp_path):
    df = _frame()
    assert common_cases(df) == ["c0", "c1"]
    paths = write_tables(df, tmp_path, title="demo")
    main = pd.read_csv(paths["table_csv"]).set_index("method")
    assert main.index.tolist() == ["ARAP", "SShaDe"]
    assert main["n_cases"].tolist() == [2, 2] and main["n_failed"].tolist() == [0, 0]
    assert main.loc["ARAP", "volume_err_pct"] == pytest.approx(2.0)
    assert main.loc["SShaDe", "volume_err_pct"] == pytest.approx(3.0)  # not 1.5 (its 4 own cases)

    first, second = _tables(paths["table_md"].read_text())
    assert first.startswith("### demo")
    assert "Mean over the 2 cases on which every method (ARAP, SShaDe) succeeded." in first
    arap, ssh = _md_row(first, "ARAP"), _md_row(first, "SShaDe")
    assert arap[:3] == ["ARAP", "2", "**2.00**"]        # the best volume on the same cases
    assert ssh[:3] == ["SShaDe", "2", "3.00"]
    assert ssh[-1] == "**2.00**" and arap[-1] == "50.00"  # time: SShaDe best
    # legacy per-method means would bold SShaDe's 1.50 instead
    assert "**1.50**" in to_markdown(summarize(df))


def test_second_table_all_cases_each_method_ran_on(tmp_path):
    paths = write_tables(_frame(), tmp_path)
    assert set(paths) == {"cases", "table_csv", "table_all_csv", "table_md", "table_tex"}
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in paths.values())
    assert all(p.is_file() for p in paths.values())
    own = pd.read_csv(paths["table_all_csv"]).set_index("method")
    assert own["n_cases"].to_dict() == {"ARAP": 2, "SShaDe": 4}
    assert own.loc["SShaDe", "volume_err_pct"] == pytest.approx(1.5)
    assert own.loc["ARAP", "volume_err_pct"] == pytest.approx(2.0)

    md = paths["table_md"].read_text()
    tables = _tables(md)
    assert len(tables) == 2 and tables[1].startswith(f"### {ALL_CASES_HEADING}")
    assert tables[0].startswith(f"### {COMMON_CASES_HEADING}")  # no title given: still labelled
    assert "nothing is bold" in tables[1] and "**" not in tables[1]
    assert _md_row(tables[1], "ARAP")[:3] == ["ARAP", "2", "2.00"]
    assert _md_row(tables[1], "SShaDe")[:3] == ["SShaDe", "4", "1.50"]


def test_latex_names_the_case_count(tmp_path):
    tex = write_tables(_frame(), tmp_path)["table_tex"].read_text()
    note = "Mean over the 2 cases on which every method (ARAP, SShaDe) succeeded."
    assert f"% {note}" in tex                                            # comment on top
    assert f"\\multicolumn{{6}}{{p{{0.9\\columnwidth}}}}{{\\footnotesize {note}}} \\\\" in tex  # visible note row
    assert tex.index("\\bottomrule") < tex.index("\\multicolumn") < tex.index("\\end{tabular}")
    assert "ARAP & \\textbf{2.00\\%}" in tex and "SShaDe & 3.00\\%" in tex
    assert "Method & Volume & Area & EL & FA & Time \\\\" in tex          # Table 1 layout kept


def test_a_failed_run_removes_its_case_from_the_common_set(tmp_path):
    df = _frame(sshade_error_on="c1")
    assert common_cases(df) == ["c0"]
    paths = write_tables(df, tmp_path)
    main = pd.read_csv(paths["table_csv"]).set_index("method")
    assert main["n_cases"].to_dict() == {"ARAP": 1, "SShaDe": 1}
    assert main["n_failed"].to_dict() == {"ARAP": 0, "SShaDe": 1}  # over all the cases it ran on
    own = pd.read_csv(paths["table_all_csv"]).set_index("method")
    assert own["n_cases"].to_dict() == {"ARAP": 2, "SShaDe": 3}
    assert own["n_failed"].to_dict() == {"ARAP": 0, "SShaDe": 1}
    first, second = _tables(paths["table_md"].read_text())
    assert "Mean over the 1 case on which every method" in first
    assert "Failed: failed runs over all the cases the method was run on." in first
    assert "| Method | Cases | Failed |" in first
    assert _md_row(first, "SShaDe")[:3] == ["SShaDe", "1", "1"]
    assert _md_row(second, "SShaDe")[:3] == ["SShaDe", "3", "1"]
    assert "Mean over the 1 case on which" in paths["table_tex"].read_text()


def test_empty_common_set_falls_back_to_labelled_per_method_means(tmp_path):
    (tmp_path / "table_all.csv").write_text("stale\n")  # from an earlier run into the same folder
    # each method succeeded somewhere, never on the same case (a method that failed
    # everywhere does not empty the common set: tests/test_guard.py)
    df = pd.DataFrame([_row("c0", "ARAP", 1.0), _row("c1", "ARAP", 9.0, error="SShaDeError: nope"),
                       _row("c0", "SShaDe", 2.0, error="SShaDeError: nope"), _row("c1", "SShaDe", 4.0)])
    assert common_cases(df) == []
    paths = write_tables(df, tmp_path)
    assert "table_all_csv" not in paths and not (tmp_path / "table_all.csv").exists()
    main = pd.read_csv(paths["table_csv"]).set_index("method")
    assert main["n_cases"].to_dict() == {"ARAP": 1, "SShaDe": 1} and main.loc["ARAP", "n_failed"] == 1
    assert main.loc["ARAP", "volume_err_pct"] == 1.0 and main.loc["SShaDe", "volume_err_pct"] == 4.0
    md = paths["table_md"].read_text()
    assert len(_tables(md)) == 1 and "**" not in md
    note = [ln for ln in md.splitlines() if ln.startswith("No case on which every method")]
    assert len(note) == 1 and "(ARAP 1, SShaDe 1)" in note[0]
    tex = paths["table_tex"].read_text()
    assert "No case on which every method" in tex and "\\textbf" not in tex


def test_homogeneous_and_legacy_frames_are_unchanged(tmp_path):
    df = _frame()
    same = df[df["case"].isin(["c0", "c1"])]
    comp = compare(same)
    assert comp.all is None and comp.cases == ["c0", "c1"]
    pd.testing.assert_frame_equal(comp.main, summarize(same))
    # summarize(df) keeps its meaning: each method over its own successful cases
    s = summarize(df).set_index("method")
    assert s["n_cases"].to_dict() == {"ARAP": 2, "SShaDe": 4}
    assert summarize(df, cases=["c0", "c1"]).set_index("method")["n_cases"].to_dict() == {"ARAP": 2, "SShaDe": 2}
    # one method, or no case column: no second table, the plain summary
    paths = write_tables(df[df["method"] == "SShaDe"], tmp_path / "one")
    assert "table_all_csv" not in paths
    assert "Mean over the 4 cases on which the method succeeded." in paths["table_md"].read_text()
    no_case = df.drop(columns=["case"])
    comp = compare(no_case)
    assert comp.cases is None and comp.all is None
    pd.testing.assert_frame_equal(comp.main, summarize(no_case))


def test_reference_subset_is_stated(tmp_path):
    """Reference columns on a subset of the common cases (reference.cases=per_pose): the
    note under the table says over how many cases they average; none when every case has
    them or the column is absent."""
    df = pd.DataFrame([_row(f"c{i}", m, 1.0 + i) for i in range(4) for m in ("ARAP", "SShaDe")])
    df["ref_mean_pct"] = [0.01 if r.case in ("c0", "c2") else np.nan for r in df.itertuples()]
    comp = compare(df)
    assert comp.ref_cases == 2
    write_tables(df, tmp_path)
    text = (tmp_path / "table.md").read_text()
    assert "Ref mean, Ref max and E gap: over the 2 of them with a reference solution" in text
    assert "over the 2 of them" in (tmp_path / "table.tex").read_text()
    df["ref_mean_pct"] = 0.01
    assert compare(df).ref_cases == 4
    write_tables(df, tmp_path)
    assert "with a reference solution" not in (tmp_path / "table.md").read_text()
    assert compare(df.drop(columns="ref_mean_pct")).ref_cases is None


def test_reference_subset_of_the_all_cases_table_is_stated(tmp_path):
    """The all-cases table (a method ran on more cases than the common set) says over how
    many of its cases the reference columns average, when fewer than all (results/defaust:
    4 per_pose references, 40 cases)."""
    rows = [_row(f"c{i}", m, 1.0 + i) for i in range(4) for m in ("ARAP", "SShaDe")]
    rows += [_row("c0", "Mine", 2.0)]
    df = pd.DataFrame(rows)
    df["ref_mean_pct"] = [0.01 if r.case == "c0" else np.nan for r in df.itertuples()]
    comp = compare(df)
    assert comp.cases == ["c0"] and comp.all is not None
    assert (comp.ref_cases_all, comp.n_cases_all) == (1, 4)
    write_tables(df, tmp_path)
    all_part = (tmp_path / "table.md").read_text().split("All cases each method ran on")[1]
    assert "over the 1 of the 4 cases with a reference solution" in all_part
    df["ref_mean_pct"] = 0.01
    assert "reference solution" not in all_note(compare(df))


def test_sweep_reads_the_main_table(tmp_path):
    from eval.sweeps.files import STATUS_FILE
    from eval.sweeps.sweep_table import aggregate_sweep
    job = tmp_path / "sweep" / "0"
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "overrides.yaml").write_text("- sshade.n_low=500\n")
    (job / STATUS_FILE).write_text(json.dumps({"job_num": 0, "overrides": ["sshade.n_low=500"], "status": "done"}))
    write_tables(_frame(), job)
    agg = aggregate_sweep(tmp_path / "sweep", write=False)
    assert agg.loc[0, "SShaDe/n_cases"] == 2 and agg.loc[0, "SShaDe/volume_err_pct"] == pytest.approx(3.0)
    assert not any(c.startswith("table_all") for c in agg.columns)


def test_a_sweep_table_shows_the_rows_its_jobs_mark_pending(tmp_path):
    """Job 1's table marks two rows made at an older commit pending: the sweep table counts
    them per job (with the commit) and in its title; job 0, all current, shows none."""
    from eval.run.stale_rows import RowState
    from eval.sweeps.files import STATUS_FILE
    from eval.sweeps.sweep_table import aggregate_sweep
    for n in (0, 1):
        job = tmp_path / "sweep" / str(n)
        job.mkdir(parents=True)
        ov = [f"sshade.n_low={500 * (n + 1)}"]
        (job / STATUS_FILE).write_text(json.dumps({"job_num": n, "overrides": ov, "status": "done"}))
        old = [RowState(job, c, "SShaDe", n == 1 and c in ("c0", "c1"), "sshade.guard changed since 3e79476",
                        commit="3e79476" + "0" * 33) for c in ("c0", "c1", "c2", "c3")]
        write_tables(_frame(), job, pending=old)
    agg = aggregate_sweep(tmp_path / "sweep")
    assert list(agg["pending"]) == [0, 2] and list(agg["pending_from"].fillna("")) == ["", "3e79476"]
    md = (tmp_path / "sweep" / "sweep_table.md").read_text()
    assert "2 done; 2 row(s) pending from 3e79476" in md.splitlines()[0]
    assert "| Pending rows |" in md and "| done | 2 from 3e79476 |" in md and "| done |  |" in md


# ---------------------------------------------------------------- read-back CSV, pandas warnings

def test_ok_mask_on_an_error_column_read_back_from_csv():
    csv = "case,method,error,volume_err_pct\nc0,ARAP,,1.0\nc0,SShaDe,,2.0\nc1,SShaDe,boom,\n"
    df = pd.read_csv(io.StringIO(csv))
    assert df["error"].dtype != np.float64
    empty = pd.read_csv(io.StringIO("case,method,error,volume_err_pct\nc0,ARAP,,1.0\nc0,SShaDe,,2.0\n"))
    assert empty["error"].dtype == np.float64  # all-empty column: NaN float64
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # pandas' fillna("") on float64 warns (and will raise)
        assert ok_mask(df).tolist() == [True, True, False]
        assert ok_mask(empty).tolist() == [True, True]
        assert compare(empty).main["n_cases"].tolist() == [1, 1]
        assert summarize(empty)["n_failed"].tolist() == [0, 0]


def test_retabulate_rebuilds_tables_from_cases_csv_only(tmp_path):
    from eval.tables import main as tables_main
    from eval.tables import write_cases
    write_cases(_frame(), tmp_path)
    (tmp_path / "run.json").write_text('{"config": {"experiment": {"name": "demo"}, "dataset": {"name": "x"}}}')
    before = (tmp_path / "cases.csv").read_bytes()
    assert tables_main([str(tmp_path)]) == 0
    assert (tmp_path / "cases.csv").read_bytes() == before  # the input is not rewritten
    md = (tmp_path / "table.md").read_text()
    assert md.startswith("### demo: 4 x case(s)") and (tmp_path / "table_all.csv").is_file()
    assert _md_row(_tables(md)[0], "SShaDe")[1] == "2"  # the common set, as write_tables


def test_retabulate_refuses_an_edited_compared_csv_and_a_fifo_table_md_does_not_block_it(tmp_path, capsys):
    """The compared rows are tabulated only as their run recorded them (``compared.json``):
    a number edited in ``compared.csv`` is one error line naming it; a FIFO where
    ``table.md`` was is not read (the title comes from ``run.json``)."""
    import os

    from eval.run.compared import write_compared
    from eval.tables import main as tables_main
    from eval.tables import write_cases
    write_cases(_frame(), tmp_path)
    (tmp_path / "run.json").write_text('{"config": {"experiment": {"name": "demo"}, "dataset": {"name": "x"}}}')
    theirs = _frame().query("method == 'SShaDe'").assign(method="Theirs", run="elsewhere", run_commit="abc",
                                                         run_machine="Linux, 2 cores", time_other_run=True)
    write_compared(tmp_path, theirs)
    os.mkfifo(tmp_path / "table.md")  # replaced through a rename, never opened
    assert tables_main([str(tmp_path)]) == 0
    assert "| Theirs |" in (tmp_path / "table.md").read_text()
    text = (tmp_path / "compared.csv").read_text()
    v = str(theirs["volume_err_pct"].iloc[0])
    (tmp_path / "compared.csv").write_text(text.replace(v, "9" + v, 1))
    before = (tmp_path / "table.md").read_bytes()
    capsys.readouterr()
    assert tables_main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    errors = [ln for ln in err.splitlines() if ln.startswith("error: ")]  # log lines may come before it
    assert len(errors) == 1 and "compared.csv: " in errors[0] and f"volume_err_pct 9{v}" in errors[0], err
    assert (tmp_path / "table.md").read_bytes() == before


def test_a_preset_method_says_its_preset_and_steps():
    """Implicit-ARAP-like rows (a preset, fixed step counts, an SDF fit inside the time):
    the table's stop line says so (every row says which preset made it)."""
    import pandas as pd
    rows = [{"case": f"c{i}", "method": "Implicit-ARAP", "volume_err_pct": 1.0, "time_s": 60.0, "error": "",
             "preset": "cpu", "sdf_steps": 1000, "deform_steps": 250, "sdf_fit_s": 40.0 + i} for i in range(2)]
    lines = stop_lines(pd.DataFrame(rows))
    assert lines == ["Implicit-ARAP: cpu preset: a fixed 1000 SDF-fit steps + 250 deformation steps, no stopping "
                     "criterion; its Time includes the SDF fit (mean 40.5 s)"]
    assert stop_lines(pd.DataFrame(rows), short=True) == ["Implicit-ARAP: cpu preset"]


def test_stop_lines_count_stalled_runs_and_say_what_handle_and_ref_columns_mean():
    """A paper-protocol method with stalled and capped runs: the line counts each status,
    not "converged"; each method says how its handles are held and which minimiser its
    Ref / E gap columns measure against (its own energy or one it does not minimise)."""
    import pandas as pd
    base = {"volume_err_pct": 1.0, "time_s": 1.0, "error": "", "protocol": "paper", "iterations": 10}
    rows = [dict(base, case="a", method="ARAP", converged=True, status="converged", handles="hard",
                 ref_energy_type="spokes", ref_own_energy=True),
            dict(base, case="b", method="ARAP", converged=False, status="stalled", handles="hard",
                 ref_energy_type="spokes", ref_own_energy=True),
            dict(base, case="c", method="ARAP", converged=False, status="max_iter", handles="hard",
                 ref_energy_type="spokes", ref_own_energy=True),
            dict(base, case="a", method="SShaDe", converged=True, status="converged", handles="overwritten",
                 ref_energy_type="spokes_and_rims", ref_own_energy=False)]
    arap, ours = stop_lines(pd.DataFrame(rows))
    assert "converged on 1/3 runs (stalled (the stop rule fired with the gradient above gtol) on 1, " \
           "hit the iteration cap on 1)" in arap
    assert "handles are hard constraints" in arap and "against the minimiser of its own energy (spokes)" in arap
    assert "converged on 1/1 runs" in ours and "overwritten with their targets" in ours
    assert "distance to the full-resolution spokes_and_rims minimiser, an energy it does not minimise" in ours


def test_a_method_scored_without_times_keeps_an_empty_time_column():
    df = pd.DataFrame([_row("c0", "Theirs", 1.0, time_s=None), _row("c1", "Theirs", 2.0, time_s=None)])
    assert df["time_s"].dtype == object  # as the evaluator's rows hold it: no time at all
    s = summarize(df)
    assert "time_s" in s.columns and np.isnan(s["time_s"].iloc[0])
    md = to_markdown(s)
    assert "Time (s)" in md and _md_row(md, "Theirs")[-1] == "--"


def test_table_md_states_each_means_interval_over_the_common_cases_whatever_the_row_order(tmp_path):
    """Under the main table, each method's 95 % bootstrap interval of its mean over the
    common cases only (ARAP's c0, c1: not SShaDe's c2, c3), the same for the rows shuffled."""
    from eval.present.intervals import bootstrap_ci
    df = _frame()
    df.loc[(df["method"] == "SShaDe") & (df["case"] == "c1"), "volume_err_pct"] = 5.0
    write_tables(df, tmp_path)
    md = (tmp_path / "table.md").read_text()
    assert "interval of the mean over the 2 cases" in md
    lo, hi = bootstrap_ci([3.0, 5.0])
    intervals = md.split("interval of the mean over the 2 cases")[1]
    assert _md_row(intervals, "SShaDe")[1] == f"{lo:.2f} .. {hi:.2f}"
    assert _md_row(intervals, "ARAP")[1] == "2.00 .. 2.00"
    out2 = tmp_path / "shuffled"
    out2.mkdir()
    write_tables(df.sample(frac=1, random_state=5).reset_index(drop=True), out2)
    assert md.split("### ")[0] == (out2 / "table.md").read_text().split("### ")[0]
    assert intervals.split("\n\n")[1] == (out2 / "table.md").read_text().split(
        "interval of the mean over the 2 cases")[1].split("\n\n")[1]


def test_a_table_whose_rows_were_timed_on_two_machines_says_so_with_the_counts(tmp_path):
    """``table.md`` of a folder whose records name one machine says nothing of machines; with
    two of its records re-signed as another machine's, rebuilt, it names both with their
    counts (most first), and only the rows it tabulates count."""
    from eval.run.result_store import record_digest
    from eval.tables import retabulate

    from .conftest import ROOT
    from .current_rows import current_copy
    run = current_copy(ROOT / "results" / "faust", tmp_path / "faust")  # every record this machine's
    retabulate(run)
    assert "Timed on" not in (run / "table.md").read_text()
    other = {"cpu": "Elsewhere CPU", "simd": "avx2", "cores": 2}
    for p in (run / "runs" / "s0_p1" / "ARAP.json", run / "runs" / "s0_p1" / "Elastic.json"):
        rec = json.loads(p.read_text())
        rec["machine"] = other
        rec["digest"] = record_digest(rec)
        p.write_text(json.dumps(rec, indent=1) + "\n")
    retabulate(run)
    text = (run / "table.md").read_text()
    n = sum(1 for _ in (run / "runs").glob("*/*.json"))
    assert f"**Timed on 2 machines**: {n - 2} rows on " in text
    assert "; 2 on Elsewhere CPU, avx2, 2 cores (each row's record names its machine)" in text

"""A table's pairs as a job array (``cluster=slurm``, eval/experiments/cases/case_array.py),
through submitit's LocalExecutor (``cluster.executor=local``: every task a process here,
the same submission, waiting and store as on SLURM; .ci/slurm_table.sh runs it on a real
one): the table equals a local run's in every non-time column, a task killed while it
runs leaves its unstored pair as a failed row (not a stored record, not a valid-looking
row) and ``resume=true`` submits that pair alone; Ctrl-C cancels the tasks; the section's
bad values are refused."""
from __future__ import annotations

import importlib.util
import json
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest

from .conftest import ROOT, subprocess_env

submitit = pytest.importorskip("submitit", reason="submitit (hydra-submitit-launcher's dependency) is not installed")

from harness.slurm_array import cluster_options  # noqa: E402
from sshade.errors import SShaDeError  # noqa: E402

_spec = importlib.util.spec_from_file_location("table_change", ROOT / "benchmarks" / "table_change.py")
table_change = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(table_change)

A = "{_target_:tests.store_methods.Counted,name:A}"
B = "{_target_:tests.store_methods.DiesOnCase,name:B}"
ARRAY = ["cluster=slurm", "cluster.executor=local", "cluster.poll_s=0.2", "cluster.cpus_per_task=1"]


def _eval(tmp_path, out, *extra, env=None, check=True):
    cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path / 'faust'}", "dataset.limit=2",
           "reference.cases=none", "report.view_cases=1", f"methods=[{A},{B}]", f"out_dir={out}", *extra]
    r = subprocess.run(cmd, cwd=ROOT, env={**subprocess_env(), **(env or {})}, capture_output=True, text=True,
                       timeout=300)
    assert not check or r.returncode == 0, r.stdout[-2000:] + r.stderr[-3000:]
    return r


def _same_table(a_dir, b_dir) -> None:
    """cases.csv and table.csv of two runs equal in every non-time column, and the same rows."""
    a, b = pd.read_csv(a_dir / "cases.csv"), pd.read_csv(b_dir / "cases.csv")
    assert set(b.columns) - set(a.columns) == {"cores"} and set(a.columns) <= set(b.columns)
    changes, unpaired = table_change.table_change(a, b)
    assert not changes and not unpaired, (changes, unpaired)
    ta, tb = pd.read_csv(a_dir / "table.csv"), pd.read_csv(b_dir / "table.csv")
    cols = [c for c in ta.columns if not c.endswith("_s")]
    pd.testing.assert_frame_equal(ta[cols], tb[cols])


@pytest.mark.slow
def test_array_table_equals_local_and_a_killed_task_is_missing_then_resumed(tmp_path, faust_root):
    (tmp_path / "faust").symlink_to(faust_root)
    local, arr, calls = tmp_path / "local", tmp_path / "arr", tmp_path / "calls.txt"
    _eval(tmp_path, local, "jobs=1")
    cases = list(pd.read_csv(local / "cases.csv")["case"].unique())
    # the array, B killing its own task (SIGKILL) on the second case, after A stored its pair there
    r = _eval(tmp_path, arr, *ARRAY, env={"SSHADE_TEST_DIE_CASE": cases[1]})
    assert "submitted 2 array task(s)" in r.stdout
    assert f"(case {cases[1]}, job " in r.stdout and "killed: array task died without a result" in r.stdout
    assert "1 pair(s) have no record" in r.stdout and "resume=true" in r.stdout
    got = pd.read_csv(arr / "cases.csv", keep_default_na=False).set_index(["case", "method"])
    dead = got.loc[(cases[1], "B")]
    assert "no record of this pair" in dead["error"] and dead["volume_err_pct"] == "" and dead["time_s"] == ""
    assert all(got.loc[(c, m), "error"] == "" for c, m in got.index if (c, m) != (cases[1], "B"))
    assert not (arr / "runs" / cases[1] / "B.json").exists() and (arr / "runs" / cases[1] / "A.json").is_file()
    assert json.loads((arr / "run.json").read_text())["n_errors"] == 1
    assert "1 failed" in (arr / "table.md").read_text() or "failed" in (arr / "table.md").read_text()
    # resume: the killed pair alone is submitted, and the table is the local one
    r = _eval(tmp_path, arr, *ARRAY, "resume=true", env={"SSHADE_TEST_COUNTER": str(calls)})
    assert "submitted 1 array task(s)" in r.stdout and calls.read_text().split() == ["6890", "B"]
    _same_table(local, arr)
    assert (arr / "report" / f"{cases[0]}.js").is_file()  # the first case's view, from the task's meshes


@pytest.mark.slow
def test_sigterm_cancels_the_array(tmp_path, faust_root):
    """SIGTERM while a task runs: one line ``interrupted``, exit 130, the task process gone."""
    (tmp_path / "faust").symlink_to(faust_root)
    calls = tmp_path / "calls.txt"
    env = {**subprocess_env(), "SSHADE_TEST_COUNTER": str(calls), "SSHADE_TEST_HANG_AFTER": "0"}
    p = subprocess.Popen([sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path / 'faust'}",
                          "dataset.limit=1", "reference.cases=none", f"methods=[{A}]", *ARRAY,
                          f"out_dir={tmp_path / 'out'}"], cwd=ROOT, env=env, text=True, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    try:
        t_end = time.monotonic() + 120
        while not calls.is_file() and p.poll() is None and time.monotonic() < t_end:
            time.sleep(0.1)
        assert p.poll() is None, p.communicate()
        kids = subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
        assert kids  # the local task's process
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130 and err.strip().splitlines()[-1] == "interrupted", err[-3000:]
    assert "cancelled 1 array task(s)" in out
    t_end = time.monotonic() + 30
    while any(subprocess.run(["kill", "-0", k], capture_output=True).returncode == 0 for k in kids):
        assert time.monotonic() < t_end, f"task process(es) {kids} still alive"
        time.sleep(0.2)


GOOD = {"executor": "slurm", "partition": None, "account": None, "qos": None, "timeout_min": 60, "cpus_per_task": 2,
        "mem_gb": 4, "array_parallelism": 8, "setup": None, "additional_parameters": {}, "folder": "slurm",
        "poll_s": 10, "grace_polls": 2, "unreachable_s": 1800}


def test_cluster_section_checked():
    assert cluster_options(None) is None
    got = cluster_options(GOOD)
    assert got.setup == () and got.mem_gb == 4.0 and got.folder == "slurm" and got.executor == "slurm"
    inside = "inside the output folder"
    for key, bad, words in [("folder", "../up", inside), ("folder", "/abs", inside),
                            ("executor", "pbs", "cluster.executor"), ("cpus_per_task", 0, "cluster.cpus_per_task"),
                            ("poll_s", float("nan"), "cluster.poll_s"), ("setup", "echo hi", "cluster.setup"),
                            ("partition", "", "cluster.partition")]:
        with pytest.raises(SShaDeError, match=words):
            cluster_options({**GOOD, key: bad})
    with pytest.raises(SShaDeError, match="cluster.qos is not set"):
        cluster_options({k: v for k, v in GOOD.items() if k != "qos"})

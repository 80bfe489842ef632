"""The evaluator's runs side by side (``jobs``, eval/experiments/cases/case_jobs.py):
the same rows as one process, every pair run once and stored, the workers' log lines in
eval.log, the rule of ``jobs=auto``, a bad value refused before any work, the plan's
wall time on several workers (eval/run/plan.py)."""
from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

import pandas as pd
import pytest

from eval.experiments.cases.case_jobs import AUTO_MIN_S, describe, job_count
from eval.run.plan import make_plan, render_plan
from eval.run.progress import CostModel
from harness.jobs import thread_limit
from sshade.cores import available_cores
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env

PLUGIN = "{_target_:tests.store_methods.Counted,name:%s}"


def _eval(tmp_path, out, *extra, counter=None):
    cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path / 'faust'}", "dataset.limit=3",
           "reference.cases=none", f"methods=[{PLUGIN % 'A'},{PLUGIN % 'B'}]", f"out_dir={out}", *extra]
    env = dict(subprocess_env(), SSHADE_TEST_COUNTER=str(counter)) if counter else subprocess_env()
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


@pytest.mark.slow
def test_two_jobs_give_the_rows_of_one_process(tmp_path, faust_root):
    (tmp_path / "faust").symlink_to(faust_root)
    one, two, counter = tmp_path / "one", tmp_path / "two", tmp_path / "calls.txt"
    _eval(tmp_path, one, "jobs=1")
    _eval(tmp_path, two, "jobs=2", counter=counter)
    # every pair ran exactly once, in a worker, and is stored
    calls = counter.read_text().split("\n")[:-1]
    assert sorted(c.split()[1] for c in calls) == ["A"] * 3 + ["B"] * 3
    assert len(list((two / "runs").rglob("*.json"))) == 6
    a, b = pd.read_csv(one / "cases.csv"), pd.read_csv(two / "cases.csv")
    assert "cores" not in a and (b["cores"] == thread_limit(2)).all()
    drop = ["time_s", "compile_s"]
    pd.testing.assert_frame_equal(a.drop(columns=drop), b.drop(columns=[*drop, "cores"]))
    title = (two / "table.md").read_text().splitlines()[0]
    cores = thread_limit(2)
    assert f"6 of 6 runs side by side, {cores} core{'s' if cores != 1 else ''} each" in title
    assert "side by side" not in (one / "table.md").read_text().splitlines()[0]
    assert json.loads((two / "run.json").read_text())["jobs"] == 2
    log = (two / "eval.log").read_text()
    assert "in 2 worker processes" in log
    for case in a["case"].unique():  # the workers' per-pair lines reach eval.log
        assert f"{case} A " in log and f"{case} B " in log
    # the first cases' 3D views, written from the workers' meshes
    views = [sorted(p.name for p in (d / "report").glob("*.js")) for d in (one, two)]
    assert views[0] == views[1] and len(views[0]) == 2


def test_job_count_rule():
    assert job_count("auto", cases=40, estimate_s=AUTO_MIN_S / 2) == 1  # a short run: no worker to start
    assert job_count("auto", cases=40, estimate_s=AUTO_MIN_S) == min(available_cores(), 40)
    assert job_count("auto", cases=1, estimate_s=1e6) == 1  # one case: nothing to share
    assert job_count(None, cases=3, estimate_s=0) == 1
    assert job_count(8, cases=3, estimate_s=0) == 3 and job_count(1, cases=10, estimate_s=1e6) == 1
    for bad in (0, -1, True, 2.5, "two", 2000):
        with pytest.raises(SShaDeError, match="jobs must be"):
            job_count(bad, cases=3, estimate_s=0)
    assert describe(1) == "" and describe(2).startswith("2 runs at a time")


def test_bad_jobs_refused_before_any_work(tmp_path):
    r = subprocess.run([sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path}", "jobs=zero",
                        "out_dir=out"], cwd=tmp_path, env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith("error: jobs must be")
    assert "Traceback" not in r.stderr and not (tmp_path / "out").exists()


def test_plan_wall_time_on_workers():
    cases = [SimpleNamespace(n_vertices=1000)] * 4
    cost = CostModel({"A": "const", "S": "const"}, prior_const_s=10.0)
    pairs = [(ci, mi) for ci in range(4) for mi in (0, 1)]  # 8 runs x 10 s, 20 s per case
    one = make_plan(cases, ["A", "S"], pairs, cost)
    two = make_plan(cases, ["A", "S"], pairs, cost, jobs=2)
    assert one["total_s"] == 80.0 and two["total_s"] == 40.0
    assert "8 run(s), 2 at a time:" in render_plan(two) and "at a time" not in render_plan(one)
    # the costliest case bounds it from below: one case of 8 runs on 4 workers
    assert make_plan(cases, ["A", "S"], [(0, 0), (0, 1)], cost, jobs=4)["total_s"] == 20.0


@pytest.mark.slow
def test_ctrl_c_stops_the_workers(tmp_path, faust_root):
    """Ctrl-C while two workers run (each sleeping in a plug-in's deform): one line
    ``interrupted``, exit 130, no worker process left behind."""
    import os
    import signal
    import time
    (tmp_path / "faust").symlink_to(faust_root)
    calls = tmp_path / "calls.txt"
    env = dict(subprocess_env(), SSHADE_TEST_COUNTER=str(calls), SSHADE_TEST_HANG_AFTER="0")
    p = subprocess.Popen([sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={tmp_path / 'faust'}",
                          "dataset.limit=2", "reference.cases=none", f"methods=[{PLUGIN % 'A'}]", "jobs=2",
                          f"out_dir={tmp_path / 'out'}"], cwd=ROOT, env=env, text=True, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    try:
        t_end = time.monotonic() + 120
        while not (calls.is_file() and len(calls.read_text().splitlines()) >= 2) and p.poll() is None \
                and time.monotonic() < t_end:
            time.sleep(0.1)
        assert p.poll() is None, p.communicate()
        kids = [int(x) for x in subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True,
                                               text=True).stdout.split()]
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 130 and err.strip().splitlines()[-1] == "interrupted", err[-3000:]
    assert "Traceback" not in err
    time.sleep(0.5)
    alive = [k for k in kids if os.path.exists(f"/proc/{k}") and "Z" not in open(f"/proc/{k}/stat").read().split()[2]]
    assert not alive, alive

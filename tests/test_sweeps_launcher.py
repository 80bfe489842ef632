"""Sweeps that end with an outcome for every job (eval/sweeps/launcher.py, eval/sweeps/sweep_command.py):
SLURM state queries with and without accounting, the wait loop (killed jobs, never
hanging), the SLURM launcher's launch with fake jobs, missing and killed rows of the
table, and resume. The real one-node SLURM run is .ci/slurm_sweep.sh."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest

import eval.sweeps.launcher as sl
import eval.sweeps.sweep_command as sw
from eval.sweeps.files import (
    MANIFEST,
    RESUME_ENV,
    STATUS_FILE,
    now_iso,
    read_manifest,
    read_status,
    write_manifest,
    write_status,
)
from eval.sweeps.launcher import ACTIVE_STATES, SlurmQueryError, expand_job_ids, slurm_states, wait_for_jobs
from eval.sweeps.sweep_table import aggregate_sweep

from .conftest import subprocess_env  # noqa: E402

# ---------------------------------------------------------------- SLURM state queries

def test_expand_job_ids():
    assert expand_job_ids("16_[1-3,5%2]") == ["16_1", "16_2", "16_3", "16_5"]
    assert expand_job_ids("16_4") == ["16_4"] and expand_job_ids("17") == ["17"]


class FakeSlurm:
    """subprocess.run stand-in answering sacct / squeue / scontrol from a table."""

    def __init__(self, *, sacct=None, queue=None, ended=None, squeue_error=None):
        self.sacct, self.queue, self.ended, self.squeue_error = sacct, queue or {}, ended or {}, squeue_error
        self.calls = []

    def __call__(self, cmd, **kw):
        self.calls.append(cmd[0])
        if cmd[0] == "sacct":
            if self.sacct is None:  # no accounting: what slurm-wlm prints without slurmdbd
                return SimpleNamespace(returncode=1, stdout="",
                                       stderr="sacct: error: Slurm accounting storage is disabled\n")
            return SimpleNamespace(returncode=0, stdout="".join(f"{k}|{v}\n" for k, v in self.sacct.items()),
                                   stderr="")
        if cmd[0] == "squeue":
            if self.squeue_error:
                return SimpleNamespace(returncode=1, stdout="", stderr=self.squeue_error)
            parents = cmd[-1].split(",")
            rows = {k: v for k, v in self.queue.items() if k.split("_")[0] in parents}
            if not rows:
                return SimpleNamespace(returncode=1, stdout="",
                                       stderr="slurm_load_jobs error: Invalid job id specified\n")
            return SimpleNamespace(returncode=0, stdout="".join(f"{k}|{v}\n" for k, v in rows.items()), stderr="")
        if cmd[0] == "scontrol":
            j = cmd[-1]
            if j in self.ended:
                return SimpleNamespace(returncode=0, stdout=f"JobId=9 ArrayJobId=16 JobState={self.ended[j]} "
                                                            "Reason=NonZeroExitCode\n", stderr="")
            return SimpleNamespace(returncode=1, stdout="", stderr="slurm_load_jobs error: Invalid job id specified\n")
        raise FileNotFoundError(cmd[0])


def test_states_from_sacct_when_accounting_works():
    fake = FakeSlurm(sacct={"16_0": "COMPLETED", "16_1": "CANCELLED by 0", "16_[2-3]": "PENDING"})
    st = slurm_states(["16_0", "16_1", "16_2", "16_3"], runner=fake)
    assert st == {"16_0": "COMPLETED", "16_1": "CANCELLED", "16_2": "PENDING", "16_3": "PENDING"}
    assert fake.calls == ["sacct"]


def test_states_without_accounting_fall_back_to_squeue_and_scontrol():
    fake = FakeSlurm(queue={"16_0": "RUNNING", "16_2": "PENDING"}, ended={"16_1": "FAILED"})
    st = slurm_states(["16_0", "16_1", "16_2", "16_3"], runner=fake)
    assert st == {"16_0": "RUNNING", "16_1": "FAILED", "16_2": "PENDING", "16_3": None}
    assert fake.calls[:2] == ["sacct", "squeue"]
    # every job gone from the queue: squeue's "Invalid job id" is an answer, not an error
    st = slurm_states(["16_1"], runner=FakeSlurm(ended={"16_1": "OUT_OF_MEMORY"}))
    assert st == {"16_1": "OUT_OF_MEMORY"}
    with pytest.raises(SlurmQueryError, match="Unable to contact"):
        slurm_states(["16_1"],
                     runner=FakeSlurm(squeue_error="slurm_load_jobs error: Unable to contact slurm controller"))


# ---------------------------------------------------------------- the wait loop

class FakeJob:
    def __init__(self, folder: Path, job_id: str):
        self.job_id = job_id
        self.paths = SimpleNamespace(result_pickle=folder / f"{job_id}_result.pkl")

    def finish(self, tag, value):
        from submitit.core.utils import cloudpickle_dump
        cloudpickle_dump((tag, value), self.paths.result_pickle)


def _no_sleep(jobs_after=None):
    calls = []

    def sleep(s):
        calls.append(s)
        if jobs_after and len(calls) in jobs_after:
            jobs_after[len(calls)]()
    return sleep, calls


def test_wait_collects_results_errors_and_killed_jobs(tmp_path):
    jobs = [FakeJob(tmp_path, f"5_{i}") for i in range(4)]
    jobs[0].finish("success", {"status": "done"})
    jobs[1].finish("error", "Traceback ...\nValueError: bad")
    # job 2 runs, then finishes after two polls; job 3 vanishes from the queue without result
    sleep, calls = _no_sleep({2: lambda: jobs[2].finish("success", 42)})
    queue = {"5_2": "RUNNING", "5_3": "RUNNING"}

    def states(ids):
        if len(calls) >= 1:
            queue.pop("5_3", None)
        return {j: queue.get(j) for j in ids}
    seen = []
    out = wait_for_jobs(jobs, states=states, poll_s=0.0, grace_polls=2, sleep=sleep,
                        report=lambda i, o: seen.append((i, o.kind)))
    assert [o.kind for o in out] == ["result", "error", "result", "killed"]
    assert out[0].value == {"status": "done"} and "ValueError: bad" in out[1].value and out[2].value == 42
    assert out[3].state is None
    assert sorted(seen) == [(0, "result"), (1, "error"), (2, "result"), (3, "killed")]


def test_wait_never_hangs_on_a_dead_job_or_an_unreachable_controller(tmp_path):
    """A job neither queued nor running without result is killed after the grace polls,
    whatever SLURM says of it (FAILED, or nothing at all)."""
    job = FakeJob(tmp_path, "7")
    sleep, calls = _no_sleep()
    out = wait_for_jobs([job], states=lambda ids: {"7": "FAILED"}, poll_s=0.0, grace_polls=3, sleep=sleep)
    assert out[0].kind == "killed" and out[0].state == "FAILED" and len(calls) == 2
    assert "FAILED" not in ACTIVE_STATES and "PENDING" in ACTIVE_STATES
    now = [0.0]

    def down(ids):
        raise SlurmQueryError("squeue failed: Unable to contact slurm controller")

    def tick(s):
        now[0] += 100.0
    out = wait_for_jobs([job], states=down, poll_s=100.0, unreachable_s=450.0, sleep=tick, clock=lambda: now[0])
    assert out[0].kind == "killed" and out[0].state == "UNREACHABLE" and now[0] == 500.0


# ---------------------------------------------------------------- the launcher, with fake jobs

@pytest.fixture()
def launcher(tmp_path, monkeypatch):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    from omegaconf import OmegaConf

    from hydra_plugins.sshade_sweep_launcher import SweepSlurmLauncher
    ln = SweepSlurmLauncher(submitit_folder=str(tmp_path / "sw" / ".submitit" / "%j"), poll_s=0.0, grace_polls=1,
                            timeout_min=5)
    assert ln.wait_params == {"poll_s": 0.0, "grace_polls": 1, "unreachable_s": 1800.0}
    assert "poll_s" not in ln.params  # not passed on to sbatch
    ln.config = OmegaConf.create({"hydra": {"sweep": {"dir": str(tmp_path / "sw")}}})
    return ln


def _fake_submit(monkeypatch, ln, folder: Path, behaviour: dict):
    """Replace the executor: each submitted job number gets ``behaviour[num]``:
    ('done' | 'raise' | 'killed' | 'never', ...)."""
    from hydra.core.utils import JobReturn, JobStatus
    submitted = []

    class Executor:
        def map_array(self, fn, overrides, keys, nums, ids, states):
            jobs = []
            for ov, num in zip(overrides, nums):
                job = FakeJob(folder, f"30_{num}")
                submitted.append(num)
                kind = behaviour[num]
                d = folder / str(num)
                if kind != "never":  # the job started: sweep_job wrote status running
                    write_status(d, {"status": "running", "job_num": num, "overrides": ov,
                                        "started": now_iso()})
                if kind == "done":
                    write_status(d, {"status": "done", "job_num": num, "overrides": ov})
                    job.finish("success", JobReturn(overrides=ov, status=JobStatus.COMPLETED,
                                                    _return_value={"status": "done"}))
                elif kind == "raise":
                    job.finish("error", "Traceback (most recent call last):\nKeyError: 'x'")
                jobs.append(job)
            return jobs
    monkeypatch.setattr(ln, "_executor", lambda: Executor())
    monkeypatch.setattr(sl, "slurm_states", lambda ids: {j: None for j in ids})  # all gone from the queue
    return submitted


def test_launcher_returns_every_job_and_records_the_dead(launcher, tmp_path, monkeypatch):
    from hydra.core.utils import JobStatus
    d = tmp_path / "sw"
    grid = [[f"sshade.n_low={n}"] for n in (300, 500, 800, 900)]
    write_manifest(d, {"argv": ["-m"], "points": grid, "runs": [{"started": now_iso()}]})
    submitted = _fake_submit(monkeypatch, launcher, d, {0: "done", 1: "killed", 2: "raise", 3: "never"})
    rets = launcher.launch(grid, initial_job_idx=0)
    assert submitted == [0, 1, 2, 3]
    assert all(r.status == JobStatus.COMPLETED for r in rets)  # Hydra's sweeper will not raise
    assert [r.return_value["status"] for r in rets] == ["done", "killed", "failed", "missing"]
    st = read_status(d / "1")
    assert st["status"] == "killed" and "died without a result" in st["error"] and st["slurm_job_id"] == "30_1"
    man = read_manifest(d)
    assert man["jobs"]["2"]["outcome"] == "failed" and "KeyError" in man["jobs"]["2"]["error"]
    assert man["jobs"]["3"]["outcome"] == "missing" and not (d / "3").exists()
    sw.finish_manifest(d)
    df = aggregate_sweep(d).set_index("job")
    assert list(df["status"]) == ["done", "killed", "failed", "missing"]
    assert df.loc[3, "error"] == "never started (no longer known to SLURM, job 30_3)"  # the launcher's note
    assert "1 done, 1 failed, 1 killed, 1 missing" in (d / "sweep_table.md").read_text()


def test_launcher_resume_submits_only_jobs_without_result(launcher, tmp_path, monkeypatch):
    d = tmp_path / "sw"
    grid = [[f"sshade.n_low={n}"] for n in (300, 500, 800)]
    write_status(d / "0", {"status": "done", "job_num": 0, "overrides": grid[0]})
    write_status(d / "1", {"status": "partial", "job_num": 1, "overrides": grid[1]})
    write_status(d / "2", {"status": "killed", "job_num": 2, "overrides": grid[2]})
    monkeypatch.setenv(RESUME_ENV, "1")
    submitted = _fake_submit(monkeypatch, launcher, d, {2: "done"})
    rets = launcher.launch(grid, initial_job_idx=0)
    assert submitted == [2]
    assert [r.return_value["status"] for r in rets] == ["done", "partial", "done"]


# ---------------------------------------------------------------- table: missing / killed rows

def test_table_lists_missing_points_and_killed_jobs(tmp_path, capsys):
    d = tmp_path / "sweep"
    grid = [["a=1", "b=x"], ["a=2", "b=x"], ["a=3", "b=x"]]
    write_manifest(d, {"argv": ["-m", "a=1,2,3", "b=x"], "points": grid,
                           "runs": [{"started": "2026-01-01T10:00:00+00:00"}]})
    write_status(d / "0", {"status": "done", "job_num": 0, "overrides": grid[0]})
    write_status(d / "1", {"status": "running", "job_num": 1, "overrides": grid[1],
                              "started": "2026-01-01T10:00:05+00:00"})
    df = aggregate_sweep(d, write=False)  # the sweep still runs: running, and not started yet
    assert list(df["status"]) == ["done", "running", "missing"] and "not started yet" in df.loc[2, "error"]
    assert list(df["a"]) == [1, 2, 3]
    man = read_manifest(d)
    man["runs"][-1]["finished"] = "2026-01-01T10:05:00+00:00"
    write_manifest(d, man)
    df = aggregate_sweep(d)  # the sweep is over: a job still "running" died
    assert list(df["status"]) == ["done", "killed", "missing"]
    assert "died without a result" in df.loc[1, "error"] and "never started" in df.loc[2, "error"]
    assert "Sweep sweep: 3 job(s), 1 done, 1 killed, 1 missing" in (d / "sweep_table.md").read_text()


def test_sweep_points_expands_like_hydra():
    from omegaconf import OmegaConf
    cfg = OmegaConf.create({"hydra": {"sweeper": {"_target_": "hydra._internal.core_plugins.basic_sweeper.BasicSweeper",
                                                  "max_batch_size": None, "params": {"x": "1,2"}},
                                      "overrides": {"task": ["y=a,b", "z=3"]}}})
    assert sw.sweep_points(cfg) == [["x=1", "y=a", "z=3"], ["x=1", "y=b", "z=3"],
                                    ["x=2", "y=a", "z=3"], ["x=2", "y=b", "z=3"]]
    cfg.hydra.sweeper._target_ = "hydra_plugins.optuna.Sweeper"
    assert sw.sweep_points(cfg) is None  # another sweeper: no grid, no missing rows


# ---------------------------------------------------------------- resume

def test_resume_replays_the_command_for_the_jobs_without_result(tmp_path, monkeypatch, capsys):
    d = tmp_path / "sweep"
    grid = [["a=1"], ["a=2"]]
    run_dir = tmp_path / "where"
    run_dir.mkdir()
    write_manifest(d, {"argv": ["-m", "a=1,2", "hydra.sweep.dir=outputs/x", "hydra/launcher=slurm"],
                           "cwd": str(run_dir), "points": grid,
                           "runs": [{"started": now_iso(), "finished": now_iso()}]})
    write_status(d / "0", {"status": "done", "job_num": 0, "overrides": grid[0]})
    seen = {}

    def fake_main(argv):
        seen.update(argv=argv, cwd=os.getcwd(), env=os.environ.get(RESUME_ENV))
    monkeypatch.setattr(sw, "main", fake_main)
    here = os.getcwd()
    assert sw.resume_sweep(d) == 0
    assert seen["argv"] == ["-m", "a=1,2", "hydra/launcher=slurm", f"hydra.sweep.dir={d.resolve()}"]
    assert seen["cwd"] == str(run_dir) and seen["env"] == "1"
    assert os.getcwd() == here and RESUME_ENV not in os.environ
    assert "running again 1 of 2 job(s): 1 (missing)" in capsys.readouterr().out
    # nothing left: no run
    write_status(d / "1", {"status": "done", "job_num": 1, "overrides": grid[1]})
    seen.clear()
    assert sw.resume_sweep(d) == 0 and not seen
    assert "nothing to run" in capsys.readouterr().out
    # a folder without sweep.json cannot be resumed: one clear error
    (d / MANIFEST).unlink()
    assert sw.resume_sweep(d) == 2
    assert "only sweeps started by python -m eval.sweeps" in capsys.readouterr().err


@pytest.mark.slow
def test_resume_end_to_end_with_the_basic_launcher(faust_root, tmp_path):
    """A real sweep (Hydra's in-process launcher): a failed job, a done job, a job whose
    folder vanished (missing); resume runs the failed and the missing ones only."""
    d = tmp_path / "sweep"
    env = subprocess_env()
    args = [sys.executable, "-m", "eval.sweeps", "-m", "dataset=faust", f"dataset.root={faust_root}", "dataset.limit=1",
            "methods=[SShaDe]", "sshade.n_low=2,200,300", "sshade.n_samplings=1", "sshade.workers=1",
            "reference.cases=none", f"hydra.sweep.dir={d}"]
    r = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    man = read_manifest(d)
    for j in (0, 1, 2):  # the manifest's grid numbers the jobs as Hydra did
        assert read_status(d / str(j))["overrides"] == man["points"][j]
    assert list(aggregate_sweep(d, write=False)["status"]) == ["failed", "done", "done"]
    kept = (d / "1" / STATUS_FILE).read_text()
    import shutil
    shutil.rmtree(d / "2")
    assert list(aggregate_sweep(d, write=False)["status"]) == ["failed", "done", "missing"]
    r = subprocess.run([sys.executable, "-m", "eval.sweeps", "resume", str(d)], cwd=tmp_path / "..", env=env,
                       capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "running again 2 of 3 job(s): 0 (failed), 2 (missing)" in r.stdout
    assert (d / "1" / STATUS_FILE).read_text() == kept  # the done job was not run again
    df = pd.read_csv(d / "sweep_table.csv", keep_default_na=False)
    assert list(df["status"]) == ["failed", "done", "done"]
    assert "n_low must be at least 4" in df.loc[0, "error"]
    runs = read_manifest(d)["runs"]
    assert [x["resume"] for x in runs] == [False, True] and all("finished" in x for x in runs)

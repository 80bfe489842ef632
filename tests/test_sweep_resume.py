"""A sweep run again with ``resume=true`` into its own folder (the sweep steps of
``python -m eval.reproduce``; eval/sweeps/sweep_command.py ``claim_sweep_dir``): each job of
the grid keeps its folder and its current stored rows and computes only its stale or
missing (case, method) pairs, its tables and the sweep's ``sweep_table.*`` are written
again; a job folder no longer in the grid is replaced as any earlier output is (set aside,
then removed, the files a person added put back); ``resume=true`` without a sweep folder
named is refused."""
from __future__ import annotations

import hashlib
import json
import signal
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from omegaconf import OmegaConf

import eval.sweeps.sweep_command as sw
from eval.run.earlier_output import ASIDE
from eval.run.outdir import claim_output_dir, read_marker
from eval.run.result_store import record_digest
from eval.sweeps.files import MANIFEST, read_status, write_manifest, write_status

from .conftest import ROOT, subprocess_env  # noqa: E402
from .store_methods import kill_at_call


def _records(d: Path) -> dict:
    """``job/runs/case/method.json`` -> sha256 of every stored record of the sweep ``d``."""
    return {p.relative_to(d).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(d.glob("*/runs/*/*.json"))}


def _sweep(faust_root: Path, d: Path) -> subprocess.CompletedProcess:
    """Two jobs (SShaDe's n_low 200 and 300) on two FAUST cases each, resumable, into ``d``."""
    args = [sys.executable, "-m", "eval.sweeps", "-m", "dataset=faust", f"dataset.root={faust_root}",
            "dataset.limit=2", "methods=[SShaDe]", "sshade.n_low=200,300", "sshade.n_samplings=1",
            "sshade.workers=1", "reference.cases=none", "figures.enabled=false", "report.enabled=false", "jobs=1",
            "resume=true", f"hydra.sweep.dir={d}"]
    r = subprocess.run(args, cwd=d.parent, env=subprocess_env(), capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


@pytest.mark.slow  # about 15 s: two evaluator sweeps on FAUST
def test_a_rerun_with_resume_recomputes_only_the_stale_row(faust_root, tmp_path):
    d = tmp_path / "sweep"
    _sweep(faust_root, d)
    before = _records(d)
    assert sorted(before) == ["0/runs/s0_p1/SShaDe.json", "0/runs/s0_p2/SShaDe.json",
                              "1/runs/s0_p1/SShaDe.json", "1/runs/s0_p2/SShaDe.json"]
    # one row made stale: its record stored under another key (re-signed: a whole record of other settings)
    stale = "1/runs/s0_p2/SShaDe.json"
    rec = json.loads((d / stale).read_text())
    old_key = rec["key"]
    rec["key"] = "0" * len(old_key)
    rec["digest"] = record_digest(rec)
    (d / stale).write_text(json.dumps(rec, indent=1) + "\n")
    before[stale] = hashlib.sha256((d / stale).read_bytes()).hexdigest()
    table = (d / "sweep_table.csv").stat().st_mtime_ns
    job_tables = {j: (d / j / "table.csv").stat().st_mtime_ns for j in ("0", "1")}

    r = _sweep(faust_root, d)
    after = _records(d)
    assert sorted(after) == sorted(before)
    changed = [p for p in after if after[p] != before[p]]
    assert changed == [stale]  # exactly one row computed again; the three others byte for byte the same
    new = json.loads((d / stale).read_text())
    assert new["key"] == old_key and new["digest"] == record_digest(new) and new["written_utc"] >= rec["written_utc"]
    # each job said so before any work, and recorded it in its run.json
    assert "resume: SShaDe: 2 reused, 0 stale, 0 not stored" in r.stdout
    assert "resume: SShaDe: 1 reused, 1 stale (other settings: key (1)), 0 not stored" in r.stdout
    resumed = {j: json.loads((d / j / "run.json").read_text())["resumed"] for j in ("0", "1")}
    assert resumed["0"]["restored"] == 2 and resumed["0"]["recomputed"] == {}
    assert resumed["1"]["restored"] == 1 and resumed["1"]["recomputed"] == {"other settings: key": 1}
    assert "continuing the earlier sweep output" in r.stderr + r.stdout
    # the jobs' tables and the sweep's table are written again
    assert all((d / j / "table.csv").stat().st_mtime_ns > job_tables[j] for j in job_tables)
    assert (d / "sweep_table.csv").stat().st_mtime_ns > table and not (d / ASIDE).exists()
    df = pd.read_csv(d / "sweep_table.csv")
    assert list(df["job"]) == [0, 1] and list(df["status"]) == ["done", "done"]
    assert list(df["sshade.n_low"]) == [200, 300] and list(df["SShaDe/n_cases"]) == [2, 2]
    assert read_marker(d)["status"] == "done" and read_status(d / "1")["status"] == "done"


# ---------------------------------------------------------------- the claim, no computation

def _config(d: Path, grid: list[str], *, resume: bool = True, named: bool = True, sweeper: str = "BasicSweeper"):
    """The parts of a multirun's config that ``claim_sweep_dir`` reads."""
    return OmegaConf.create({
        "resume": resume, "overwrite": False,
        "hydra": {"sweep": {"dir": str(d)},
                  "sweeper": {"_target_": f"hydra._internal.core_plugins.basic_sweeper.{sweeper}",
                              "max_batch_size": None, "params": {}},
                  "overrides": {"task": ["methods=[SShaDe]", f"sshade.n_low={','.join(grid)}", "resume=true"],
                                "hydra": [f"hydra.sweep.dir={d}"] if named else []}}})


def _earlier_sweep(d: Path, n_jobs: int, failed: tuple = ()) -> None:
    """An earlier sweep's folder (claimed and finished as a sweep does) with ``n_jobs`` job
    folders, each an evaluator output with a stored record (those of ``failed``: only the
    ``status.json`` of a job that failed before its first result), its manifest and table."""
    c = claim_output_dir(d, "sweep")
    for j in range(n_jobs):
        if j in failed:
            (d / str(j)).mkdir()
            write_status(d / str(j), {"status": "failed", "job_num": j, "overrides": [f"sshade.n_low={j}"]})
            continue
        with claim_output_dir(d / str(j), "eval"):
            (d / str(j) / "runs" / "s0_p1").mkdir(parents=True)
            (d / str(j) / "runs" / "s0_p1" / "SShaDe.json").write_text(f"record of job {j}\n")
            write_status(d / str(j), {"status": "done", "job_num": j, "overrides": [f"sshade.n_low={j}"]})
    write_manifest(d, {"points": [[f"sshade.n_low={j}"] for j in range(n_jobs)]})
    (d / "sweep_table.csv").write_text("job\n" + "".join(f"{j}\n" for j in range(n_jobs)))
    c.finish("done")


def test_resume_keeps_the_job_folders_of_the_grid_and_replaces_the_others(tmp_path):
    d = tmp_path / "sweep"
    _earlier_sweep(d, 4, failed=(1,))
    (d / "3" / "mine.txt").write_text("a note a person added\n")  # no run wrote it: it survives
    (d / "notes.txt").write_text("the person's own\n")  # not the sweep's: left alone
    # a grid of 3 jobs now: job folder 3 is no longer in it; job 1 failed before any result
    # (nothing to reuse, and its job's claim would refuse a folder holding only status.json)
    assert sw.grid_job_entries(d, 3) == ["0", "2"]
    kept = {j: (d / j / "runs" / "s0_p1" / "SShaDe.json").stat().st_ino for j in ("0", "2")}
    sw.claim_sweep_dir(_config(d, ["100", "200", "300"]))
    try:
        assert {j: (d / j / "runs" / "s0_p1" / "SShaDe.json").stat().st_ino for j in ("0", "2")} == kept
        assert not (d / "1").exists() and not (d / "3").exists() and not (d / MANIFEST).exists()
        assert (d / ASIDE / "3").is_dir()
    finally:
        sw.release_sweep_dir("done")
    assert sorted(p.name for p in d.iterdir() if not p.name.startswith(".")) == ["0", "2", "3", "notes.txt"]
    assert sorted(p.name for p in (d / "3").iterdir()) == ["mine.txt"]  # the job's own files are gone
    assert (d / "0" / "runs" / "s0_p1" / "SShaDe.json").read_text() == "record of job 0\n"
    assert not (d / ASIDE).exists() and read_marker(d)["status"] == "done"


def test_resume_without_a_grid_or_a_named_folder(tmp_path, capsys):
    d = tmp_path / "sweep"
    _earlier_sweep(d, 2)
    # another sweeper: the grid cannot be expanded, so no job folder is continued
    sw.claim_sweep_dir(_config(d, ["100", "200"], sweeper="OtherSweeper"))
    sw.release_sweep_dir("done")
    assert not (d / "0").exists() and not (d / "1").exists()
    # resume=true in a default (new, dated) folder: nothing to continue, refused before anything is made
    fresh = tmp_path / "new" / "2026-01-01_00-00-00"
    with pytest.raises(SystemExit) as e:
        sw.claim_sweep_dir(_config(fresh, ["100"], named=False))
    assert e.value.code == 2 and not fresh.parent.exists()
    assert "resume=true continues a sweep in its folder: pass hydra.sweep.dir=DIR" in capsys.readouterr().err


def _counted_sweep(faust_root: Path, d: Path, limits: str, counter: Path, *extra, hang_after=None):
    """``python -m eval.sweeps`` over ``dataset.limit=<limits>`` with the counted test method
    A into ``d``, started (a Popen) with ``$SSHADE_TEST_HANG_AFTER`` when given."""
    args = [sys.executable, "-m", "eval.sweeps", "-m", "dataset=faust", f"dataset.root={faust_root}",
            f"dataset.limit={limits}", "methods=[{_target_:tests.store_methods.Counted,name:A}]",
            "reference.cases=none", "figures.enabled=false", "report.enabled=false", "jobs=1",
            f"hydra.sweep.dir={d}", *extra]
    env = dict(subprocess_env(), SSHADE_TEST_COUNTER=str(counter))
    if hang_after is not None:
        env["SSHADE_TEST_HANG_AFTER"] = str(hang_after)
    return subprocess.Popen(args, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _tree(d: Path) -> dict:
    return {p.relative_to(d).as_posix(): p.read_bytes() for p in sorted(d.rglob("*"))
            if p.is_file() and not p.name.startswith(".sshade-output")}


@pytest.mark.slow  # about 30 s each: two sweeps on FAUST, the second stopped in its first pair
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL], ids=["SIGTERM", "SIGKILL"])
def test_a_sweep_stopped_before_its_first_result_puts_the_earlier_sweep_back(faust_root, tmp_path, sig):
    """A sweep replacing an earlier one in its folder, stopped while its first pair runs:
    the earlier sweep's files (job folders, sweep.json, sweep_table.*) are back byte for
    byte, and its table is there to read (once lost with the set-aside files): at once
    after SIGTERM, at the next claim of the folder after SIGKILL (here one that fails)."""
    d, counter = tmp_path / "sweep", tmp_path / "calls.txt"
    p = _counted_sweep(faust_root, d, "1", counter)
    assert p.wait(timeout=300) == 0, p.communicate()[1][-3000:]
    before = _tree(d)
    assert "sweep_table.md" in before and "0/runs/s0_p1/A.json" in before
    p = _counted_sweep(faust_root, d, "1", counter, hang_after=1)
    kill_at_call(p, counter, 2, sig=sig)
    assert p.returncode != 0
    if sig == signal.SIGKILL:
        assert (d / ASIDE).is_dir()
        claim_output_dir(d, "sweep", first_result=sw.FIRST_RESULT).finish("failed")
    assert _tree(d) == before


@pytest.mark.slow  # about 20 s: a sweep on FAUST killed (SIGKILL) in its second job
def test_a_sweep_killed_in_its_second_job_leaves_the_first_jobs_files_as_its_own(faust_root, tmp_path):
    """A sweep killed outright in job 1: the next claim of its folder takes job 0's files
    (written before job 0 ended, the sweep's last sign of life) as the killed sweep's own,
    replaced as its output, not as files a person added after it died (kept and named)."""
    d, counter = tmp_path / "sweep", tmp_path / "calls.txt"
    p = _counted_sweep(faust_root, d, "1,2", counter, hang_after=1)
    kill_at_call(p, counter, 2)
    assert (d / "0" / "runs" / "s0_p1" / "A.json").is_file()
    c = claim_output_dir(d, "sweep", first_result=sw.FIRST_RESULT)
    assert "0" in c.replaced
    assert not [r for r in c.aside["user_paths"] if r.startswith("0/")], c.aside["user_paths"]
    c.finish("failed")


@pytest.mark.slow  # about 40 s: two sweeps on FAUST, the second stopped by SIGTERM in its last job
def test_a_resumed_sweep_stopped_after_a_result_has_its_table_made_again(faust_root, tmp_path):
    """A sweep run again with ``resume=true`` and a grid one job larger, stopped (SIGTERM)
    in the new job's first pair: the jobs it finished keep their results, and the sweep's
    table is made again from its folders (jobs 0 and 1 done, job 2 killed), not lost."""
    d, counter = tmp_path / "sweep", tmp_path / "calls.txt"
    p = _counted_sweep(faust_root, d, "1,2", counter, "resume=true")
    assert p.wait(timeout=300) == 0, p.communicate()[1][-3000:]
    n = len(counter.read_text().splitlines())
    p = _counted_sweep(faust_root, d, "1,2,3", counter, "resume=true", hang_after=n)
    kill_at_call(p, counter, n + 1, sig=signal.SIGTERM)
    df = pd.read_csv(d / "sweep_table.csv", keep_default_na=False)
    assert list(df["status"]) == ["done", "done", "killed"]
    assert "3 job(s)" in (d / "sweep_table.md").read_text().splitlines()[0]

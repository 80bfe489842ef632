"""Hydra multirun sweeps (eval/sweeps/sweep_command.py): a failing job is recorded and the others
finish; the per-sweep table; the launcher configs (joblib, submitit local/SLURM)."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from eval.app import CONF_DIR
from eval.sweeps.files import STATUS_FILE, read_status
from eval.sweeps.sweep_command import main, sweep_job
from eval.sweeps.sweep_table import aggregate_sweep

from .conftest import subprocess_env  # noqa: E402


def _compose(overrides, hydra_cfg=False):
    from hydra import compose, initialize_config_dir
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        ov = list(overrides)
        if not any(o.startswith(("dataset=", "experiment=")) for o in ov):
            ov = ["dataset=faust", *ov]  # default dataset (synthetic DeFAUST) would be built
        return compose(config_name="config", overrides=ov, return_hydra_config=hydra_cfg)


def _job(d: Path, num, overrides, status=None, table=None, run_status=None):
    (d / ".hydra").mkdir(parents=True)
    (d / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))
    if status is not None:
        (d / STATUS_FILE).write_text(json.dumps({"job_num": num, "overrides": overrides, **status}))
    if table is not None:
        pd.DataFrame(table).to_csv(d / "table.csv", index=False)
    if run_status is not None:
        (d / "run.json").write_text(json.dumps({"status": run_status}))


# ---------------------------------------------------------------- no data needed

def test_aggregate_sweep_table(tmp_path, capsys):
    sw = tmp_path / "sweep"
    tab = {"method": ["ARAP", "SShaDe"], "n_cases": [2, 2], "n_failed": [0, 0],
           "edge_err_pct": [0.9, 1.1], "volume_err_pct": [3.0, 2.5], "time_s": [4.0, 0.5]}
    _job(sw / "0", 0, ["sshade.n_low=500", "arap.tol=1e-4"], {"status": "done", "wall_s": 3.0}, tab)
    _job(sw / "1", 1, ["sshade.n_low=2", "arap.tol=1e-4"],
         {"status": "failed", "error": "SShaDe: n_low must be at least 4, got 2 (2 case(s))"})
    _job(sw / "2", 2, ["sshade.n_low=1000", "arap.tol=1e-4"], {"status": "running"})   # killed
    _job(sw / "10", 10, ["sshade.n_low=4000", "arap.tol=1e-4"], run_status="running")  # no status.json
    (sw / ".submitit" / "123").mkdir(parents=True)
    df = aggregate_sweep(sw)
    assert list(df["job"]) == [0, 1, 2, 10]
    assert list(df["status"]) == ["done", "failed", "running", "running"]
    assert list(df["sshade.n_low"]) == [500, 2, 1000, 4000]
    assert "n_low must be at least 4" in df.loc[1, "error"]
    assert "killed" in df.loc[2, "error"] and STATUS_FILE in df.loc[3, "error"]
    assert df.loc[0, "SShaDe/edge_err_pct"] == pytest.approx(1.1)
    assert df.loc[0, "ARAP/time_s"] == pytest.approx(4.0)
    assert math.isnan(df.loc[1, "SShaDe/edge_err_pct"])
    back = pd.read_csv(sw / "sweep_table.csv")
    assert len(back) == 4 and list(back["status"]) == list(df["status"])
    md = (sw / "sweep_table.md").read_text()
    assert "| sshade.n_low |" in md.splitlines()[2] and "arap.tol" not in md  # only varying keys
    assert "SShaDe EL (%)" in md and "1.10" in md and "failed" in md
    # the CLI rebuilds the same files
    (sw / "sweep_table.csv").unlink()
    with pytest.raises(SystemExit) as e:
        main(["aggregate", str(sw)])
    assert e.value.code == 0 and (sw / "sweep_table.csv").is_file()
    assert "Sweep sweep: 4 job(s), 1 done, 1 failed, 2 running" in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:
        main(["aggregate", str(tmp_path / "nope")])
    assert e.value.code == 2


def test_a_sweeps_records_with_nested_aliases_a_fifo_or_a_giant_are_refused_in_bounded_memory(tmp_path):
    """``multirun.yaml`` as a 600-byte "billion laughs" (nested aliases that print as
    gigabytes), a job's ``overrides.yaml`` that is a FIFO, and a sparse 2 GB ``table.csv``:
    the table is made at once (the multirun's overrides left out of its title, that job's
    table an error of its row), nothing blocks and nothing is expanded."""
    import os
    sw = tmp_path / "sweep"
    _job(sw / "0", 0, ["sshade.n_low=500"], {"status": "done", "wall_s": 3.0}, {"method": ["SShaDe"], "n_cases": [1]})
    _job(sw / "1", 1, ["sshade.n_low=600"], {"status": "done", "wall_s": 3.0})
    laughs = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    laughs += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)]
    (sw / "multirun.yaml").write_text("\n".join(laughs) + "\nhydra:\n  overrides:\n    task: *a8\n")
    (sw / "0" / ".hydra" / "overrides.yaml").unlink()
    os.mkfifo(sw / "0" / ".hydra" / "overrides.yaml")
    with open(sw / "1" / "table.csv", "wb") as fh:
        fh.truncate(2 * 2**30)
    import tracemalloc
    tracemalloc.start()
    try:
        df = aggregate_sweep(sw)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20, peak  # the aliases print as 300 MB, the table.csv reads as 2 GB
    assert list(df["status"]) == ["done", "done"] and "unreadable table.csv" in df.loc[1, "error"]
    assert (sw / "sweep_table.md").read_text().startswith("### Sweep sweep: 2 job(s), 2 done\n")


def test_sweep_job_records_an_exception(tmp_path):
    """A job whose experiment raises writes status failed and returns normally."""
    cfg = _compose([f"out_dir={tmp_path / 'job'}"])          # dataset.root missing -> SShaDeError
    st = sweep_job(cfg)
    assert st["status"] == "failed" and "dataset.root" in st["error"]
    on_disk = read_status(tmp_path / "job")
    assert on_disk["status"] == "failed" and "dataset.root" in on_disk["error"]
    assert "Traceback" in on_disk["traceback"] and on_disk["wall_s"] >= 0


def test_launcher_and_experiment_configs():
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    pytest.importorskip("hydra_plugins.hydra_joblib_launcher")
    c = _compose(["hydra/launcher=slurm"], hydra_cfg=True)
    ln = c.hydra.launcher
    assert ln._target_.endswith("SlurmLauncher")
    assert ln.partition is None and ln.cpus_per_task == 8 and ln.timeout_min == 240 and ln.mem_gb == 32
    c = _compose(["experiment=sweep_slurm", "hydra.launcher.partition=cpu"], hydra_cfg=True)
    assert c.hydra.launcher._target_.endswith("SlurmLauncher") and c.hydra.launcher.partition == "cpu"
    assert str(c.hydra.mode) == "RunMode.MULTIRUN" and "sshade.n_low" in c.hydra.sweeper.params
    assert c.methods == ["SShaDe"] and c.sshade.workers == 8
    c = _compose(["experiment=sweep", "hydra/launcher=joblib"], hydra_cfg=True)
    assert c.hydra.launcher._target_.endswith("JoblibLauncher")
    assert c.hydra.callbacks.sweep_aggregate._target_ == "eval.sweeps.sweep_command.AggregateSweepCallback"
    assert c.dataset.limit == 4 and c.experiment.name == "sweep"
    c = _compose(["hydra/launcher=submitit_local"], hydra_cfg=True)
    assert c.hydra.launcher._target_.endswith("LocalLauncher")


# ---------------------------------------------------------------- real sweeps (FAUST)

def _sweep(faust_root, sweep_dir, launcher_args, timeout=240):
    env = subprocess_env()
    args = [sys.executable, "-m", "eval.sweeps", "-m", "dataset=faust", f"dataset.root={faust_root}", "dataset.limit=1",
            "methods=[SShaDe]", "sshade.n_low=2,300", "sshade.n_samplings=1", "sshade.workers=1",
            f"hydra.sweep.dir={sweep_dir}", *launcher_args]
    return subprocess.run(args, cwd=sweep_dir.parent, env=env, capture_output=True, text=True, timeout=timeout)


def _check_failed_and_done(r, sweep_dir: Path):
    assert r.returncode == 0, r.stderr[-3000:]
    for j in ("0", "1"):
        assert (sweep_dir / j / STATUS_FILE).is_file()
    # the bad parameter fails when the methods are built, before any case runs: no table
    assert not (sweep_dir / "0" / "table.csv").exists() and (sweep_dir / "1" / "table.csv").is_file()
    # the callback wrote the table at the end of the multirun
    assert (sweep_dir / "sweep_table.csv").is_file() and (sweep_dir / "sweep_table.md").is_file()
    df = pd.read_csv(sweep_dir / "sweep_table.csv", keep_default_na=False, na_values=[""])
    assert len(df) == 2
    df = df.set_index("sshade.n_low")
    assert df.loc[2, "status"] == "failed" and "n_low must be at least 4 (or 'auto'), got 2" in df.loc[2, "error"]
    assert df.loc[300, "status"] == "done"
    assert pd.isna(df.loc[300, "error"]) or df.loc[300, "error"] == ""
    for c in ("SShaDe/edge_err_pct", "SShaDe/volume_err_pct", "SShaDe/angle_err_deg", "SShaDe/time_s"):
        assert math.isfinite(float(df.loc[300, c])), c
    assert math.isnan(float(df.loc[2, "SShaDe/edge_err_pct"]))
    # rebuilding from the folders gives the same rows
    again = aggregate_sweep(sweep_dir, write=False).set_index("sshade.n_low")
    assert list(again["status"].sort_index()) == ["failed", "done"]
    assert "failed" in (sweep_dir / "sweep_table.md").read_text()


@pytest.mark.slow
def test_joblib_sweep_records_failure(faust_root, tmp_path):
    pytest.importorskip("hydra_plugins.hydra_joblib_launcher")
    sw = tmp_path / "sweep_joblib"
    r = _sweep(faust_root, sw, ["hydra/launcher=joblib", "hydra.launcher.n_jobs=2"])
    _check_failed_and_done(r, sw)


@pytest.mark.slow
def test_submitit_local_sweep_records_failure(faust_root, tmp_path):
    pytest.importorskip("hydra_plugins.hydra_submitit_launcher")
    sw = tmp_path / "sweep_submitit"
    r = _sweep(faust_root, sw, ["hydra/launcher=submitit_local", "hydra.launcher.timeout_min=5"])
    _check_failed_and_done(r, sw)
    assert (sw / ".submitit").is_dir()


def test_a_stopped_sweep_keeps_a_record_stored_in_the_file_system_tick_of_its_claim(tmp_path):
    """A record whose modification time is the claim marker's own (a job writing in the
    same tick of a coarse file-system clock) is the stopped sweep's result: it stays, and
    the sweep is closed as interrupted, not undone."""
    import os

    from omegaconf import OmegaConf

    from eval.run.outdir import MARKER, read_marker
    from eval.run.result_store import STORE_DIR
    from eval.sweeps.sweep_command import claim_sweep_dir, end_unfinished_sweep

    d = tmp_path / "sweep"
    config = OmegaConf.create({"hydra": {"sweep": {"dir": str(d)}, "overrides": {"hydra": [f"hydra.sweep.dir={d}"]}}})
    claim_sweep_dir(config)
    job = d / "0"
    (job / STORE_DIR / "s0").mkdir(parents=True)
    (job / STATUS_FILE).write_text(json.dumps({"job_num": 0, "status": "running"}))
    record = job / STORE_DIR / "s0" / "ARAP.json"
    record.write_text("{}")
    tick = (d / MARKER).stat().st_mtime_ns
    os.utime(record, ns=(tick, tick))
    end_unfinished_sweep()
    assert record.read_text() == "{}"
    assert read_marker(d)["status"] == "interrupted"

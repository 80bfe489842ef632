"""The one command that regenerates results/ (eval/reproduce.py): which runs it makes."""
from __future__ import annotations

import json
from unittest import mock

import pytest

from eval import reproduce
from eval.reproduce import main

from .conftest import ROOT
from .optional import found


def _steps(capsys, *argv) -> dict[str, str]:
    """The steps ``--dry-run --any-machine`` lists (every command, on any machine), each as
    ``name -> its arguments``; without the plan of stored rows before them (each step's rows
    held to the commits that made them, seconds per step; test_the_plan_before_any_step...
    tests it)."""
    with mock.patch.object(reproduce, "_print_plan", lambda selected: None):
        assert main(["--dry-run", "--any-machine", *argv]) == 0
    out = capsys.readouterr().out.splitlines()
    return {line.split(":")[0][3:]: line.split(": ", 1)[1] for line in out if line.startswith("== ")}


def test_default_runs_defaust_and_its_sweep(capsys):
    steps = _steps(capsys)
    neural = ["sweep_implicit_arap"] if found("torch") else []
    assert list(steps) == ["defaust", "defaust_paper", "convergence", "animation", "sweep", "sweep_arap_sr_alpha",
                           *neural, "report"]
    assert steps["report"].startswith("-m eval.report --index results")  # results/index.html, last
    assert "arap.protocol=paper" in steps["defaust_paper"]
    assert "reference.cases=per_pose" in steps["defaust_paper"]  # its E gap / Ref columns, as the converged table's
    assert "arap_sr.alpha=0.001,0.003,0.01,0.03,0.06,0.1" in steps["sweep_arap_sr_alpha"]
    assert "methods=[ARAP-SR]" in steps["sweep_arap_sr_alpha"]
    ia = ("methods=[ARAP,Elastic,ARAP-SR,SShaDe,Implicit-ARAP] "
          if found("torch") else "")  # the [neural] extra: Implicit-ARAP on every case too
    assert steps["defaust"] == ("-m eval figures.enabled=true dataset.baseline_cases=all reference.cases=per_pose "
                                "resume=true jobs=1 "
                                f"{ia}out_dir=results/defaust")  # every method on every case, resumable, one at a time
    sweep = steps["sweep"]
    assert sweep.startswith("-m eval.sweeps -m experiment=sweep") and "hydra.sweep.dir=results/sweeps/defaust" in sweep
    assert "sshade.n_low=1000,3000,6000" in sweep  # x k = 1,3,5 from conf/experiment/sweep.yaml


def test_every_experiment_with_folders_and_figures(capsys):
    steps = _steps(capsys, "--faust", "F", "--tosca", "T", "--shapes", "S", "--scaling", "M.obj",
                   "sshade.n_samplings=3")
    neural = found("torch")
    assert list(steps) == ["defaust", "defaust_paper", "convergence", "animation", "sweep", "sweep_arap_sr_alpha",
                           *(["sweep_implicit_arap", "sweep_implicit_arap_faust"] if neural else []),
                           "faust", "pose_transfer", "defaust_faust", "defaust_faust_paper", "tosca", "tosca_factors",
                           "shapes", "scaling", "frames", "cold_start", "report"]
    assert steps["defaust"].endswith("sshade.n_samplings=3")  # extra overrides go to the DeFAUST run
    for name in ("defaust", "faust", "pose_transfer", "defaust_faust", "tosca"):
        assert "figures.enabled=true" in steps[name], name
    for name in ("defaust_faust", "defaust_faust_paper"):  # the FAUST subjects built into a DeFAUST of their own
        assert ('dataset.root=data/defaust_faust dataset.build.enabled=true '
                'dataset.build.overrides=["source=faust","faust.root=F"] dataset.baseline_cases=all') in steps[name]
    assert "arap.protocol=paper" in steps["defaust_faust_paper"] and "Implicit-ARAP" not in steps["defaust_faust_paper"]
    assert "dataset.root=F" in steps["faust"] and "pose_transfer.root=F" in steps["pose_transfer"]
    ia = "methods=[ARAP,Elastic,ARAP-SR,SShaDe,Implicit-ARAP] " if found("torch") else ""
    assert steps["shapes"] == (f"-m eval experiment=shapes dataset.root=S resume=true jobs=1 {ia}"
                               "out_dir=results/shapes")
    for name, cmd in steps.items():  # only this command writes results/: each step names its folder
        if name == "report":
            continue
        sweeps = {"sweep": "defaust", "sweep_arap_sr_alpha": "arap_sr_alpha",
                  "sweep_implicit_arap": "implicit_arap_defaust", "sweep_implicit_arap_faust": "implicit_arap_faust"}
        want = (f"hydra.sweep.dir=results/sweeps/{sweeps[name]}" if name in sweeps else
                "T --out results/tosca_factors" if name == "tosca_factors" else
                "--mesh M=M.obj --out results/frames" if name == "frames" else
                "cold_start.py --out results/cold_start" if name == "cold_start" else f"out_dir=results/{name}")
        assert want in cmd, name
        if name in sweeps:  # a sweep step resumes: each job reuses its current rows (eval/sweeps/sweep_command.py)
            assert f"resume=true {want}" in cmd, name
    assert "tosca.root=T" in steps["tosca"] and "scaling.base_mesh=M.obj" in steps["scaling"]
    assert "scaling.meshes=null" in steps["scaling"]  # one mesh instead of the set
    every = _steps(capsys, "--scaling", "set")
    assert every["scaling"] == "-m eval experiment=scaling out_dir=results/scaling"
    assert every["frames"].endswith("benchmarks/frames.py --out results/frames")  # its default set
    before = _steps(capsys, "--scaling", "set", "--before", "abc1234")  # that commit's code beside this one's
    assert before["cold_start"].endswith("benchmarks/cold_start.py --before abc1234 --out results/cold_start")


def test_only_runs_the_named_steps(capsys):
    steps = _steps(capsys, "--faust", "F", "--only", "faust,pose_transfer")
    assert list(steps) == ["faust", "pose_transfer"]
    assert main(["--dry-run", "--only", "nope"]) == 2
    assert "nope" in capsys.readouterr().err


def test_a_step_adding_rows_beside_another_machines_is_not_run_and_says_whose(capsys):
    """Without ``--any-machine``, on a machine none of defaust_paper's current rows was timed on
    (its first record taken as stale and the others as current, whatever the committed
    state), the dry run lists the step as not run, naming each machine its kept records
    were timed on with their count, as the stored records say, and the rows it leaves
    marked pending."""
    from dataclasses import replace

    from eval.run.stale_rows import row_machines
    real = reproduce.folder_states
    kept: dict = {}

    def one_stale(folder, trees):
        states = [replace(s, stale=i == 0, why=s.why if i == 0 else "") for i, s in enumerate(real(folder, trees))]
        kept[folder] = {(s.case, s.method) for s in states if not s.stale}
        return states
    elsewhere = {"cpu": "Elsewhere CPU", "simd": "sve", "cores": 64}
    with mock.patch.object(reproduce, "_print_plan", lambda selected: None), \
            mock.patch.object(reproduce, "machine_info", lambda: elsewhere), \
            mock.patch.object(reproduce, "folder_states", one_stale):
        assert main(["--dry-run", "--only", "defaust_paper"]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("== defaust_paper: "))
    assert line.startswith("== defaust_paper: not run (its rows were timed on another machine (")
    assert "and this one is Elsewhere CPU, sve, 64 cores" in line and line.endswith("its stale rows are marked pending")
    (folder, pairs), = kept.items()
    machines = row_machines([folder], pairs=pairs)
    assert machines and sum(machines.values()) == len(pairs)
    made = line[line.index("another machine (") + len("another machine ("):line.index(") and this one is")]
    assert sorted(made.split("; ")) == sorted(f"{n} on {w}" for w, n in machines.items())


def test_a_sweep_step_given_a_sweep_on_its_command_line_asks_for_a_multirun(capsys):
    """Hydra refuses a sweep override (``key=a,b``) without ``-m`` ("Ambiguous value for
    argument"), even where the experiment's config sets ``hydra.mode: MULTIRUN``: each step
    whose overrides hold a sweep passes ``-m``, as Hydra's own parser reads them."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create()
    steps = _steps(capsys, "--faust", "F", "--tosca", "T", "--shapes", "S", "--scaling", "set")
    checked = 0
    for name, cmd in steps.items():
        words = cmd.split()
        if words[:2] not in (["-m", "eval.sweeps"], ["-m", "eval"]):
            continue
        overrides = parser.parse_overrides([w for w in words[2:] if "=" in w])
        if any(o.is_sweep_override() for o in overrides):
            assert "-m" in words[2:], name
            checked += 1
    assert checked == 2 + 2 * found("torch")  # sweep, sweep_arap_sr_alpha (+ the two Implicit-ARAP sweeps)


@pytest.mark.slow
def test_the_plan_before_any_step_names_rows_reused_and_stale_per_step_and_method(capsys):
    """Before the first step: per step and method, the committed rows it reuses and those
    stale (those ``--check`` counts stale or pending); a sweep step resumes as a table
    step does (``resume=true``); a step without stored rows runs whole, and its committed
    output is current at the commit that made it, or stale (:mod:`eval.run.stale_runs`)."""
    assert main(["--check", "--json"]) == 0
    counts = json.loads(capsys.readouterr().out)
    assert main(["--dry-run", "--faust", "F", "--only", "faust,sweep,convergence"]) == 0
    out = capsys.readouterr().out.splitlines()
    first_step = next(i for i, ln in enumerate(out) if ln.startswith("== "))
    plan = [ln.strip() for ln in out[:first_step]]
    assert plan[0].startswith("plan: stored rows reused and stale")
    for m in ("ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "SShaDe"):
        c = counts["results/faust"][m]
        assert c["rows"] == 8 and any(ln.startswith(f"faust: {m}: {8 - c['stale'] - c['pending']} reused, "
                                                    f"{c['stale'] + c['pending']} stale") for ln in plan), (m, c)
    sweep = [ms["SShaDe"] for f, ms in counts.items() if f.startswith("results/sweeps/defaust/")]
    stale = sum(c["stale"] + c["pending"] for c in sweep)
    assert sum(c["rows"] for c in sweep) == 18
    assert any(ln.startswith(f"sweep: SShaDe: {18 - stale} reused, {stale} stale") for ln in plan), plan
    made = json.loads((ROOT / "results" / "convergence" / "run.json").read_text())["git"]["commit"]
    assert any(ln.startswith("convergence: no stored rows; the step runs whole (its output: ")
               and (f"current at {made[:7]})" in ln or "stale" in ln or "pending" in ln) for ln in plan), plan


@pytest.mark.slow  # ~15 s; tests/test_stale_rows.py checks the same rows in the quick suite
def test_check_json_counts_every_committed_row_and_exits_0_at_this_checkout(capsys):
    assert main(["--check", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["results/faust"]["SShaDe"]["rows"] == 8 and got["results/faust"]["SShaDe"]["stale"] == 0
    assert got["results/convergence"]["whole run"]["rows"] == 1  # current or marked pending, never stale
    assert all(v["whole run"]["stale"] == 0 for v in got.values() if "whole run" in v)  # current or marked pending
    assert sum(v["rows"] for ms in got.values() for v in ms.values()) >= 600
    with pytest.raises(SystemExit) as e:
        main(["--json"])  # --json goes with --check
    assert e.value.code == 2 and "--json and --strict go with --check" in capsys.readouterr().err


def test_every_step_runs_this_checkout_first_on_the_python_path(monkeypatch):
    """A step (and a benchmark's fresh-process probes) imports this checkout's packages even
    where another copy is installed (an editable install of another clone)."""
    import os

    from eval.reproduce import step_env
    from eval.run.outdir import REPRODUCE_ENV
    from eval.run.runinfo import REPO_ROOT
    monkeypatch.setenv("PYTHONPATH", "/elsewhere")
    env = step_env()
    assert env["PYTHONPATH"].split(os.pathsep) == [str(REPO_ROOT), "/elsewhere"] and env[REPRODUCE_ENV] == "1"


def test_retabulate_rebuilds_each_run_folders_tables_keeping_the_title_the_run_wrote(monkeypatch, tmp_path):
    """``--retabulate`` rewrites table.md (and the breakdown the run wrote) of every folder
    with a result store and a cases.csv from its rows alone (here: adding the intervals),
    keeping the run's title; a folder without a store (an experiment's own table) is left
    as it is."""
    import pandas as pd

    import eval.reproduce as reproduce
    run = tmp_path / "results" / "demo"
    (run / "runs").mkdir(parents=True)
    pd.DataFrame([dict(case=f"c{i}", subject=0, pose=1, method=m, volume_err_pct=1.0 + i + (m == "B"), error="")
                  for i in range(3) for m in "AB"]).to_csv(run / "cases.csv", index=False)
    (run / "breakdown.csv").write_text("old\n")
    (run / "table.md").write_text("### demo: 3 cases; B: cpu preset\n\nold\n")
    other = tmp_path / "results" / "own_table"
    other.mkdir()
    (other / "cases.csv").write_text("case,method\nc0,A\n")
    (other / "table.md").write_text("an experiment's own table\n")
    monkeypatch.setattr(reproduce, "RESULTS", str(tmp_path / "results"))
    assert reproduce.main(["--retabulate"]) == 0
    md = (run / "table.md").read_text()
    assert md.startswith("### demo: 3 cases; B: cpu preset\n") and "old" not in md
    assert "interval of the mean over the 3 cases" in md
    assert "| 1 | 2 ± 1 (n=3) [" in (run / "breakdown.md").read_text()  # the run's breakdown made again
    assert (other / "table.md").read_text() == "an experiment's own table\n"

"""Every command's ``--help`` prints its own usage and exits 0, writing nothing: the list
below covers every entry point of the repository (a module with
``if __name__ == "__main__"`` or a package's ``__main__.py``), checked by
:func:`test_every_entry_point_is_listed`."""
from __future__ import annotations

import re
import subprocess
import sys

import pytest

from .conftest import ROOT, subprocess_env

#: command (arguments after ``python``) -> texts its --help must print on stdout
HELP = {
    "-m eval": ["usage: python -m eval [KEY=VALUE ...]", "Evaluate deformation methods", "out_dir=DIR",
                "outputs/<experiment>/<date_time>", "== Configuration groups ==", "dataset: defaust, faust, shapes",
                "ci, convergence, export, faust, main,", "== Config ==", "methods:"],
    "-m eval.sweeps": ["usage: python -m eval.sweeps", "resume SWEEP_DIR", "aggregate SWEEP_DIR", "-m dataset=faust",
                      "hydra/launcher=joblib", "outputs/multirun/<date_time>"],
    "-m eval.sweeps resume": ["usage: python -m eval.sweeps resume SWEEP_DIR", "killed, failed and missing"],
    "-m eval.sweeps aggregate": ["usage: python -m eval.sweeps aggregate", "sweep_table"],
    "-m eval.tables": ["usage: python -m eval.tables", "RUN_DIR"],
    "-m eval.report": ["usage: python -m eval.report", "--index", "--screenshot"],
    "-m eval.reproduce": ["usage: python -m eval.reproduce", "--dry-run"],
    "-m eval.present.anny_figures": ["usage: python -m eval.present.anny_figures", "OUT_DIR", "outputs/anny_figures"],
    "-m defaust": ["usage: python -m defaust out=DIR", "Build the DeFAUST dataset", "== Configuration groups ==",
                   "preset: ci, full", "source: anny"],
    "-m defaust.canonical": ["usage: python -m defaust.canonical", "root name"],
    "-m sshade": ["usage: python -m sshade deform MESH -o OUT"],
    "-m sshade deform": ["usage: python -m sshade deform", "--sel", "--force"],
    "-m sshade animate": ["usage: python -m sshade animate", "--frames", "--handles"],
    "-m sshade view": ["usage: python -m sshade view", "--sel", "--handles"],
    "-m sshade warmup": ["usage: python -m sshade warmup"],
    "-m harness": ["usage: python -m harness deform MESH -o OUT", "pkg.module.Class"],
    "-m harness deform": ["usage: python -m harness deform", "--sel", "--force", "ARAP-SR"],
    "-m examples.twisted_bar": ["usage: python -m examples.twisted_bar", "outputs/twisted_bar"],
    "benchmarks/arap_iteration.py": ["usage:", "--mesh"],
    "benchmarks/arap_sr_local.py": ["usage:", "alpha"],
    "benchmarks/arap_sr_iteration.py": ["usage:", "--iters"],
    "benchmarks/defaust_blend.py": ["usage:", "repeats"],
    "benchmarks/checked_once.py": ["usage:", "--repeats"],
    "benchmarks/plan_probe.py": ["usage:", "--copies"],
    "benchmarks/bounds.py": ["usage:", "--repeats"],
    "benchmarks/fullres_defaust.py": ["usage:", "--code"],
    "benchmarks/implicit_arap_weights.py": ["usage:", "trials"],
    "benchmarks/implicit_arap_steps.py": ["usage:", "--steps", "--set"],
    "benchmarks/implicit_arap_step_time.py": ["usage:", "--deform-steps", "--both"],
    "benchmarks/remesh_speed.py": ["usage:", "--mesh"],
    "benchmarks/remesh_hard.py": ["usage:", "--meshes"],
    "benchmarks/tosca_transfer_factors.py": ["usage:", "--classes"],
    "benchmarks/sshade_variants.py": ["usage:", "--energy", "--protocol"],
    "benchmarks/config_flow.py": ["usage:", "--methods"],
    "benchmarks/frames.py": ["usage:", "--frames"],
    "benchmarks/fullres_heldout.py": ["usage:", "--igl-iterations"],
    "benchmarks/cold_start.py": ["usage:", "--before"],
    "-m eval.experiments.scaling.probe": ["usage:", "handles_npz"],
    "benchmarks/arap_coarse_start.py": ["usage:", "--deep"],
    "benchmarks/arap_hierarchy.py": ["usage:", "--chains"],
    "benchmarks/arap_alternatives.py": ["usage:", "--max-cg", "--methods"],
    "benchmarks/arap_gradient_blocks.py": ["usage:", "--restart-only", "--rings"],
    "benchmarks/arap_sliver_local.py": ["usage:", "--diagnose", "--every"],
    "benchmarks/arap_projected_newton.py": ["usage:", "--refresh", "--nc"],
    "benchmarks/arap_trace_energy.py": ["usage:", "--cases", "--root"],
    "benchmarks/arap_trust_region.py": ["usage:", "--eta", "--max-outer"],
    "benchmarks/table_change.py": ["usage:", "--before", "--after"],
    "benchmarks/identity_cost.py": ["usage:", "probes"],
}


def _argv(cmd: str) -> list[str]:
    head, *rest = cmd.split()
    if head.endswith(".py"):
        return [sys.executable, str(ROOT / head), *rest]
    return [sys.executable, head, *rest]


def _entry_points() -> set[str]:
    """Every command of the repository, spelled as in :data:`HELP`."""
    found = set()
    for p in sorted(ROOT.glob("*/**/*.py")):
        rel = p.relative_to(ROOT)
        if rel.parts[0] in ("tests", "results", "outputs", "data", "hydra_plugins") or rel.parts[0].startswith("."):
            continue
        text = p.read_text(errors="replace")
        if p.name == "__main__.py":
            found.add("-m " + ".".join(rel.parts[:-1]))
        elif re.search(r"^if __name__ == .__main__.:", text, re.M):
            found.add(str(rel) if rel.parts[0] == "benchmarks" else "-m " + ".".join(rel.with_suffix("").parts))
    return found


def test_every_entry_point_is_listed():
    """A new command gets its line in HELP."""
    found = _entry_points()
    assert "-m eval.sweeps" in found and "benchmarks/remesh_speed.py" in found  # the search works
    assert found <= set(HELP), sorted(found - set(HELP))


#: the benchmark scripts' help (a process each, 1-2.5 s) runs with the slow tests; the commands' by default
CASES = [pytest.param(c, marks=pytest.mark.slow) if c.startswith("benchmarks/") else c for c in sorted(HELP)]


@pytest.mark.parametrize("cmd", CASES)
def test_help_prints_usage_and_exits_0(cmd, tmp_path):
    r = subprocess.run([*_argv(cmd), "--help"], cwd=tmp_path, env=subprocess_env(), capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, f"{cmd} --help: rc {r.returncode}\n{r.stderr[-3000:]}"
    assert "Traceback" not in r.stderr and "error" not in r.stderr.lower(), r.stderr[-3000:]
    for text in HELP[cmd]:
        assert text in r.stdout, f"{cmd} --help lacks {text!r}:\n{r.stdout[:3000]}"
    assert "powered by Hydra" not in r.stdout
    assert list(tmp_path.iterdir()) == [], f"{cmd} --help wrote {list(tmp_path.iterdir())}"


def test_short_h_is_help_too(tmp_path):
    r = subprocess.run([*_argv("-m eval.sweeps"), "-h"], cwd=tmp_path, env=subprocess_env(), capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0 and r.stdout.startswith("usage: python -m eval.sweeps")


def test_sweep_resume_without_folder_is_one_error_line(tmp_path):
    r = subprocess.run([*_argv("-m eval.sweeps"), "resume"], cwd=tmp_path, env=subprocess_env(),
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == ["error: usage: python -m eval.sweeps resume SWEEP_DIR "
                                             "(python -m eval.sweeps --help)"]

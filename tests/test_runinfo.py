"""eval/run/runinfo.py: what a run records of the code that made it."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

from eval.run.runinfo import git_info
from tests.conftest import ROOT


def _git(repo, *args):
    subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)


def test_a_changed_result_file_is_not_dirty_code_but_a_changed_source_is(tmp_path):
    repo = tmp_path / "repo"
    (repo / "results" / "faust").mkdir(parents=True)
    (repo / "code.py").write_text("x = 1\n")
    (repo / "results" / "faust" / "table.md").write_text("| a |\n")
    _git(repo, "init", "-q")
    _git(repo, "add", ".")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "c")
    assert git_info(repo)["dirty"] is False
    (repo / "results" / "faust" / "table.md").write_text("| b |\n")  # a run rewrote its results
    (repo / "new_output.txt").write_text("untracked\n")
    assert git_info(repo)["dirty"] is False and git_info(repo)["modified"] == []
    (repo / "code.py").write_text("x = 2\n")
    info = git_info(repo)
    assert info["dirty"] is True and info["modified"] == ["code.py"]


def test_every_builtin_method_reports_its_effective_parameters_without_a_null():
    """run.json's method_sources give each built-in method's parameters with every default
    and preset value resolved (no None standing for a preset's or protocol's value)."""
    from baselines import ARAP, ARAPSR, Elastic
    from eval.run.runinfo import effective_params, method_sources
    from sshade import SShaDe
    from sshade.arap import DEFAULT_CRITERION, DEFAULT_MAX_ITER
    from sshade.refine import SShaDeRefine
    methods = [ARAP(), Elastic(protocol="paper"), ARAPSR(), SShaDe(n_low=500), SShaDeRefine(n_low=500)]
    recs = method_sources(methods)
    for m, r in zip(methods, recs):
        assert r["params"] is not None and None not in r["params"].values(), (m.name, r["params"])
    assert recs[0]["params"]["max_iter"] == DEFAULT_MAX_ITER["converged"]
    assert recs[1]["params"]["max_iter"] == DEFAULT_MAX_ITER["paper"]
    assert recs[3]["params"]["gtol"] == DEFAULT_CRITERION.gtol and recs[3]["params"]["n_low"] == 500
    assert effective_params(SShaDe(n_low="auto"))["n_low"].startswith("auto")

    class Plugin:
        name = "P"

        def effective_params(self):
            raise RuntimeError("broken")
    assert effective_params(Plugin()) is None and effective_params(object()) is None


def test_implicit_arap_reports_its_preset_resolved():
    from tests.optional import optional_import
    optional_import("torch")
    from baselines.implicit_arap import PRESETS, ImplicitARAP
    p = ImplicitARAP(preset="cpu", arap_weight=110.0).effective_params()
    assert p["arap_weight"] == 110.0 and p["deform_steps"] == PRESETS["cpu"]["deform_steps"]
    assert None not in p.values() and p["reference_weights"] is False


def test_the_page_shows_the_effective_parameters_of_run_json(tmp_path):
    from eval.report import render_page
    (tmp_path / "run.json").write_text(json.dumps({"status": "done", "method_sources": [
        {"name": "ARAP", "params": {"max_iter": 10000, "gtol": 0.001}}, {"name": "Mine", "params": None}]}))
    page = render_page(tmp_path)
    assert "effective parameters" in page and "&quot;max_iter&quot;: 10000" in page and "Mine" not in page


def test_every_committed_run_json_and_a_fresh_one_validate_against_the_schema():
    import glob

    from eval.run.runinfo import collect_runinfo
    from tests.optional import optional_import
    jsonschema = optional_import("jsonschema")
    v = jsonschema.Draft202012Validator(json.loads((ROOT / "eval" / "run" / "run.schema.json").read_text()))
    files = glob.glob(str(ROOT / "results" / "**" / "run.json"), recursive=True)
    assert files, "no committed run.json"
    bad = [(f, e.message) for f in files for e in v.iter_errors(json.loads(Path(f).read_text()))]
    assert not bad, bad[:3]
    fresh = json.loads(json.dumps(collect_runinfo({"dataset": {"name": "x"}}, extra={"status": "done"}), default=str))
    assert not list(v.iter_errors(fresh))
    assert list(v.iter_errors({**fresh, "status": "finished"}))  # the schema holds something


def test_machine_info_reads_the_first_processor_and_its_widest_simd_set(tmp_path):
    from eval.run.runinfo import machine_info
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text("processor\t: 0\nmodel name\t: Test CPU 9000\nflags\t\t: fpu sse4_2 avx avx2 avx512f\n\n"
                       "processor\t: 1\nmodel name\t: Other CPU\nflags\t\t: fpu sse4_2\n")
    m = machine_info(cpuinfo)
    assert (m["cpu"], m["simd"]) == ("Test CPU 9000", "avx512f")  # the first block, the widest set
    cpuinfo.write_text("processor\t: 0\nmodel name\t: Test CPU\nflags\t\t: fpu sse4_2 avx avx2\n")
    assert machine_info(cpuinfo)["simd"] == "avx2"
    cpuinfo.write_text("processor\t: 0\nFeatures\t: fp asimd evtstrm\nCPU part\t: 0xd0c\n")
    assert machine_info(cpuinfo)["simd"] == "asimd"  # Arm spells its flags Features


def test_machine_info_never_raises_on_an_unreadable_or_binary_cpuinfo(tmp_path):
    from eval.run.runinfo import machine_info
    junk = tmp_path / "junk"
    junk.write_bytes(b"\xff\xfe\x00model name: \x80\n" * 10)
    for path in (tmp_path / "absent", tmp_path, junk):
        m = machine_info(path)
        assert set(m) == {"cpu", "simd", "cores"} and m["simd"] is None

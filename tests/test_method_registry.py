"""harness.method_registry: our methods are the files of conf/method/: names, table
order, specs without their `order`, a new file picked up with no other edit, and no
upward import from the bottom layer."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import harness.method_registry as reg
from eval.config_check import check_config
from sshade.errors import SShaDeError

ROOT = Path(__file__).resolve().parents[1]


def test_names_and_order_come_from_the_files():
    assert reg.builtin_methods() == ("ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "SShaDe", "SShaDe+refine")
    assert reg.table_order() == ("ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "SShaDe", "SShaDe+refine")
    assert reg.canonical_name(" sshade+REFINE ") == "SShaDe+refine"
    assert reg.method_key("SShaDe+refine") == "SShaDe_refine"
    with pytest.raises(SShaDeError, match="unknown method 'Nope'"):
        reg.canonical_name("Nope")


def test_spec_has_no_order_and_resolves_sections():
    spec = reg.file_spec("Elastic", {"arap": {"tol": 1e-3}})
    assert "order" not in spec and spec["_target_"] == "baselines.Elastic" and spec["tol"] == 1e-3
    with pytest.raises(SShaDeError, match=r"ARAP has no parameter\(s\) \['n_low'\]"):
        reg.build_builtin("ARAP", {"n_low": 100})


def test_a_new_method_is_one_file(tmp_path, monkeypatch):
    """A file in conf/method/ (here a copy of Elastic's under another name, with an order)
    is a built-in method: listed, ordered, buildable by name."""
    conf = tmp_path / "conf"
    shutil.copytree(ROOT / "conf", conf)
    text = (conf / "method" / "Elastic.yaml").read_text().replace("order: 20", "order: 45")
    (conf / "method" / "Mine.yaml").write_text(text + "name: Mine\n")
    monkeypatch.setattr(reg, "config_dir", lambda sub="": str(conf / sub) if sub else str(conf))
    assert reg.builtin_methods() == ("ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "Mine", "SShaDe", "SShaDe+refine")
    assert reg.table_order().index("Mine") == 4  # after Implicit-ARAP (40), before SShaDe (50)
    m = reg.named_or_plugin("mine", {"tol": 1e-3})
    assert m.name == "Mine" and m.tol == 1e-3
    from eval.method_config import make_methods
    assert [x.name for x in make_methods(check_config({"methods": ["ARAP", "Mine"]}).methods)] == ["ARAP", "Mine"]


_BOTTOM = "sys, sshade, sshade.deform_command, harness.method_registry, sshade.guard, sshade.mesh, sshade.isometric"


def test_bottom_layer_imports_nothing_above():
    code = (f"import {_BOTTOM};"
            "harness.method_registry.builtin_methods();"
            "print(sorted({k.split('.')[0] for k in sys.modules} & {'eval', 'baselines', 'defaust'}))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


_TOY = """\
_target_: tests.plugin_example.MyMethod
order: 45
harness:
  cost: {scale: const, prior: 7.0}
  reference: spokes
  cases: all
  iterations: Jacobi steps
name: Toy
iterations: 3
"""


def test_a_toy_method_is_its_module_and_its_file(tmp_path, monkeypatch, faust_root, caplog):
    """A built-in method made of a module (tests/plugin_example.py) and one file in
    conf/method/ alone gets its table row (in its order, on every case: ``cases: all``),
    its plan line (its own prior), its reference columns (against its file's energy) and
    its iteration note, with no edit of the harness."""
    from hydra import compose, initialize_config_dir

    from eval.app import run_experiment
    from eval.metrics.reference_scores import method_energy
    conf = tmp_path / "conf"
    shutil.copytree(ROOT / "conf", conf)
    (conf / "method" / "Toy.yaml").write_text(_TOY)
    monkeypatch.setattr(reg, "config_dir", lambda sub="": str(conf / sub) if sub else str(conf))
    assert reg.method_meta("toy") == {"cost": {"scale": "const", "prior": 7.0}, "reference": "spokes",
                                      "cases": "all", "checks": "none", "iterations": "Jacobi steps"}
    out = tmp_path / "run"
    with initialize_config_dir(config_dir=str(conf), version_base=None):
        cfg = compose(config_name="config", overrides=[
            "dataset=faust", f"dataset.root={faust_root}", "dataset.limit=2", "dataset.baseline_cases=1",
            "methods=[Toy,ARAP]", "arap.tol=1e-2", "arap.protocol=paper", "reference.cases=1", "jobs=1",
            f"out_dir={out}"])
    with caplog.at_level("INFO", logger="eval"):
        run_experiment(cfg)
    cases = __import__("pandas").read_csv(out / "cases.csv")
    toy, arap = cases[cases.method == "Toy"], cases[cases.method == "ARAP"]
    assert len(toy) == 2 and len(arap) == 1  # cases: all, beside a baseline on the first case only
    assert method_energy(type("M", (), {"name": "Toy"})) == "spokes"
    assert toy["ref_mean_pct"].notna().sum() == 1 and toy["ref_mean_pct"].dropna().iloc[0] > 0
    table = (out / "table.md").read_text()
    rows = [ln.split("|")[1].strip() for ln in table.splitlines() if ln.startswith("| ") and "---" not in ln]
    assert rows[:3] == ["Method", "ARAP", "Toy"]  # order 45: after ARAP's 10
    assert "3 iterations (Jacobi steps)" in table
    plan = [r.getMessage() for r in caplog.records if r.getMessage().startswith("plan:")]
    assert plan and "Toy 2 x ~7.2 s" in plan[0], plan  # its prior, 7 s, and the metrics at 6,890 vertices

"""sshade.registry: our methods are the files of conf/method/: names, table
order, specs without their `order`, a new file picked up with no other edit, and no
upward import from the bottom layer."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import sshade.registry as reg
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
    spec = reg.method_spec("Elastic", {"arap": {"tol": 1e-3}})
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
    from eval.methods import make_methods
    assert [x.name for x in make_methods({"methods": ["ARAP", "Mine"]})] == ["ARAP", "Mine"]


def test_bottom_layer_imports_nothing_above():
    code = ("import sys, sshade, sshade.cli, sshade.registry, sshade.guard, sshade.mesh, sshade.isometric;"
            "sshade.registry.builtin_methods();"
            "print(sorted({k.split('.')[0] for k in sys.modules} & {'eval', 'baselines', 'defaust'}))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"

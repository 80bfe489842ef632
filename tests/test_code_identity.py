"""eval/run/code_identity.py: a stored row is reused only by the code that computed it.

A resumed run recomputes every pair a plug-in's changed file or a change to the modules
a row's code imports (a commit between two halves of a run) would compute differently,
says how many and why, and never tabulates rows of two codes together; a change to code
no row imports (tables, report, builder) leaves the rows valid.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pandas as pd
import pytest

from eval.run.code_identity import (
    PACKAGES,
    ROW_HARNESS,
    ROW_REFERENCES,
    code_identity,
    identity_roots,
    import_closure,
    project_modules,
    sources_digest,
)
from eval.run.protocol_table import protocol_roots
from eval.run.result_store import describe_change

from .conftest import ROOT, edit_syntax_tree, subprocess_env
from .store_methods import kill_at_call

PLUGIN_SRC = '''
import os
import numpy as np


class Scaled:
    """A toy plug-in: moves every vertex by the handles' mean displacement, times FACTOR."""
    FACTOR = {factor}

    def __init__(self, name="Scaled"):
        self.name = name
        self.info = {{}}

    def deform(self, V, F, handles, targets):
        path = os.environ.get("SSHADE_TEST_COUNTER")
        if path:
            with open(path, "a") as fh:
                fh.write(f"{{len(V)}} {{self.name}}\\n")
        U = V + (targets - V[handles]).mean(0) * self.FACTOR
        U[handles] = targets
        return U
'''


def _counts(path):
    return pd.Series([ln.split()[1] for ln in path.read_text().splitlines()]).value_counts().to_dict() \
        if path.exists() else {}


def _eval(root, out, methods, *extra, env=None, popen=False):
    cmd = [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={out.parent / 'faust'}",
           "dataset.limit=2", "reference.cases=none", "report.enabled=false", f"methods=[{methods}]",
           f"out_dir={out}", "jobs=1", *extra]
    e = dict(subprocess_env(), **(env or {}))
    e["PYTHONPATH"] = os.pathsep.join([str(root), str(out.parent), e.get("PYTHONPATH", "")])
    kw = dict(cwd=root, env=e, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if popen:
        return subprocess.Popen(cmd, **kw)
    r = subprocess.run(cmd, timeout=600, **kw)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def _tree_copy(dst, *extra):
    """A copy of the project's packages (and of the folders ``extra``) under ``dst``."""
    for d in (*PACKAGES, *extra):
        shutil.copytree(ROOT / d, dst / d, ignore=shutil.ignore_patterns("__pycache__"))
    return dst


def test_packages_are_every_floor_of_the_house():
    """The code identity hashes every package the layering test knows (a package left
    out would let an edit of it keep stale rows)."""
    from .test_layering import FLOORS
    assert set(PACKAGES) == set(FLOORS)


def _touch(path):
    """A change to the code (a statement), as a commit would make."""
    with open(path, "a") as fh:
        fh.write("\n_EDITED = 1\n")


def test_a_row_depends_on_the_modules_its_code_imports_and_no_others(tmp_path):
    from baselines import ARAP
    from baselines.implicit_arap import ImplicitARAP
    arap = import_closure(("baselines.fullres_arap", "baselines.fullres_converged"))
    assert {"sshade.arap.solver", "sshade.mesh.validate"} <= set(arap)
    # lazy package inits (SPEC 1): importing sshade.arap.solver does not import the pipeline
    assert not {"baselines", "sshade", "sshade.pipeline", "sshade.smooth_transfer", "baselines.arap_sr"} & set(arap)
    bare = import_closure(ROW_HARNESS)  # a row without reference columns: no reference code, no loader
    assert {"eval.metrics.measures", "sshade.guard", "eval.datasets.deformation_case"} <= set(bare)
    assert not {"eval.metrics.reference", "eval.datasets", "eval.datasets.faust", "sshade.mesh.io",
                "sshade.arap.solver", "eval.experiments"} & set(bare)
    harness = import_closure(ROW_HARNESS + ROW_REFERENCES)
    assert {"eval.metrics.measures", "eval.metrics.reference", "sshade.guard",
            "harness.method_registry", "sshade.files"} <= set(harness)
    assert "sshade.mesh.io" not in harness  # writing a file imports no mesh reader
    presentation = {"eval.tables", "eval.report", "eval.present.meshview", "eval.run.plan", "defaust.build",
                    "defaust.export", "eval.reproduce", "eval.app", "eval.run.result_store", "harness.jobs",
                    "eval.experiments.cases.case_jobs"}  # presentation, commands, the store and the runner
    assert not presentation & (set(arap) | set(harness))
    src = _tree_copy(tmp_path / "src")
    root = str(src)
    ia = object.__new__(ImplicitARAP)  # only its class counts; not built, as building it needs PyTorch
    a0, i0 = code_identity(ARAP(), root=root), code_identity(ia, root=root)
    assert a0["sources"] == code_identity(ARAP())["sources"]  # the same bytes under another folder
    assert "baselines.implicit_arap.field" in i0["modules"] and "baselines.implicit_arap.field" not in a0["modules"]
    for f in (("eval", "tables.py"), ("defaust", "export.py"), ("eval", "run", "result_store.py"),
              ("harness", "jobs.py")):  # presentation, the builder, the record format, the runner: no row
        _touch(src.joinpath(*f))
    assert code_identity(ARAP(), root=root) == a0 and code_identity(ia, root=root) == i0
    _touch(src / "baselines" / "implicit_arap" / "field.py")  # one method's own module: its rows only
    assert code_identity(ARAP(), root=root) == a0 and code_identity(ia, root=root) != i0
    _touch(src / "eval" / "metrics" / "measures.py")  # a metric: every row
    assert code_identity(ARAP(), root=root)["sources"] != a0["sources"]


#: the modules of the converged solvers, which the paper protocol of ARAP, Elastic and ARAP-SR never runs
CONVERGED_ONLY = {"sshade.arap.solver", "sshade.arap.accelerate", "sshade.arap.solver_kernels",
                  "sshade.arap.local_global", "sshade.arap.sr_solver", "baselines.coarse_start", "sshade.warmup"}


@pytest.mark.parametrize("cls, target, modules", [
    ("baselines.fullres_arap.Elastic", "baselines.Elastic", ("baselines.fullres_paper", "baselines.fullres_converged")),
    ("baselines.arap_sr.ARAPSR", "baselines.ARAPSR", ("baselines.arap_sr_paper", "baselines.arap_sr_converged")),
])
def test_a_protocol_row_holds_its_own_protocols_module_and_an_unnamed_protocol_holds_both(cls, target, modules):
    """Elastic's and ARAP-SR's rows hold the module their ``protocol`` runs in (named by
    their module's ``PROTOCOL_MODULES``): under the paper protocol none of the converged
    solvers, under the converged one all of them, and both when the definition names no
    protocol; a class without a table adds nothing."""
    spec = {"class": cls, "_target_": target}
    paper = set(code_identity(None, {**spec, "protocol": "paper"}, references=False)["modules"])
    converged = set(code_identity(None, {**spec, "protocol": "converged"}, references=False)["modules"])
    unnamed = set(code_identity(None, spec, references=False)["modules"])
    assert {modules[0], "sshade.mesh.validate"} <= paper and modules[1] not in paper
    assert not CONVERGED_ONLY & paper
    assert CONVERGED_ONLY | {modules[1]} <= converged and modules[0] not in converged
    assert unnamed == paper | converged
    assert protocol_roots({"class": "sshade.pipeline.SShaDe", "protocol": "paper"}, project_modules()) == ()


def test_a_converged_solver_edit_leaves_the_paper_protocols_identity_as_it_was(tmp_path):
    """An edit of the converged solver (a statement added to sshade/arap/solver.py, in a
    copy of the sources) changes the identity of ARAP under the converged protocol and
    leaves it under the paper protocol."""
    src = _tree_copy(tmp_path / "src")
    spec = {"class": "baselines.fullres_arap.ARAP", "_target_": "baselines.ARAP"}
    before = {p: code_identity(None, {**spec, "protocol": p}, root=str(src))["sources"] for p in ("paper", "converged")}
    _touch(src / "sshade" / "arap" / "solver.py")
    after = {p: code_identity(None, {**spec, "protocol": p}, root=str(src))["sources"] for p in ("paper", "converged")}
    assert after["paper"] == before["paper"] and after["converged"] != before["converged"]


#: the class and definition of each built-in method's rows, as its records store them
BUILTIN = {"ARAP": {"class": "baselines.fullres_arap.ARAP", "_target_": "baselines.ARAP"},
           "Elastic": {"class": "baselines.fullres_arap.Elastic", "_target_": "baselines.Elastic"},
           "ARAP-SR": {"class": "baselines.arap_sr.ARAPSR", "_target_": "baselines.ARAPSR"},
           "Implicit-ARAP": {"class": "baselines.implicit_arap.method.ImplicitARAP",
                             "_target_": "baselines.implicit_arap.ImplicitARAP"},
           "SShaDe": {"class": "sshade.pipeline.SShaDe", "_target_": "sshade.SShaDe"}}


def _identities(root):
    return {m: code_identity(None, spec, root=root)["sources"] for m, spec in BUILTIN.items()}


def test_each_builtin_method_has_its_own_modules_and_an_edit_changes_exactly_its_rows(tmp_path):
    """For each built-in method, the modules its identity is made of (beside the harness's
    own: the pair runner, metrics, references, data loading); edits of (a) SShaDe's
    transfer, (b) the full-resolution ARAP file, (c) a metric, (d) a presentation module,
    each in a temporary copy, change exactly the expected rows' identities."""
    harness = set(import_closure(identity_roots(None)))
    own = {m: set(import_closure(identity_roots(spec))) - harness for m, spec in BUILTIN.items()}
    assert own["ARAP"] == own["Elastic"] >= {"baselines.fullres_arap"}
    assert own["ARAP-SR"] >= {"baselines.arap_sr", "baselines.fullres_arap"}  # it imports the ARAP file's checks
    assert own["Implicit-ARAP"] >= {"baselines.implicit_arap.method", "baselines.implicit_arap.field"}
    assert own["SShaDe"] >= {"sshade.pipeline", "sshade.smooth_transfer", "sshade.lrf", "sshade.projection"}
    assert "sshade.smooth_transfer" not in harness | own["ARAP"] | own["ARAP-SR"] | own["Implicit-ARAP"]
    src = _tree_copy(tmp_path / "src")
    before = _identities(str(src))
    for path, changed in ((("sshade", "smooth_transfer.py"), {"SShaDe"}),
                          (("baselines", "fullres_arap.py"), {"ARAP", "Elastic", "ARAP-SR"}),
                          (("eval", "metrics", "measures.py"), set(BUILTIN)),
                          (("eval", "present", "breakdown.py"), set())):
        edit_syntax_tree(src.joinpath(*path))
        after = _identities(str(src))
        assert {m for m in BUILTIN if after[m] != before[m]} == changed, path
        before = after
def test_comments_docstrings_and_layout_do_not_change_the_identity(tmp_path):
    from baselines import ARAP
    src = _tree_copy(tmp_path / "src")
    a0 = code_identity(ARAP(), root=str(src))
    f = src / "sshade" / "arap" / "solver.py"
    text = f.read_text()
    prose = text.replace('"""', '"""Reworded. ', 1) + "\n# a comment\n\n\n"
    f.write_text(prose.replace("import numpy as np", "import numpy  as np", 1))
    assert code_identity(ARAP(), root=str(src)) == a0
    f.write_text(text.replace("import numpy as np", "import numpy as np\n_X = 2", 1))
    assert code_identity(ARAP(), root=str(src))["sources"] != a0["sources"]


def test_nested_targets_of_a_definition_add_their_modules():
    from baselines import ARAP
    plain = code_identity(ARAP(), {"_target_": "baselines.ARAP"})
    nested = code_identity(ARAP(), {"_target_": "baselines.ARAP", "helper": {"_target_": "defaust.export.export"}})
    assert "defaust.export" in nested["modules"] and "defaust.export" not in plain["modules"]
    assert nested["sources"] != plain["sources"]


def test_identity_names_sources_versions_and_plugin_file(tmp_path, monkeypatch):
    from baselines import Elastic
    ident = code_identity(Elastic())
    assert ident["plugin"] is None and len(ident["sources"]) == 64 and "numpy" in ident["versions"]
    (tmp_path / "myplug.py").write_text(PLUGIN_SRC.format(factor=1.0))
    monkeypatch.syspath_prepend(str(tmp_path))
    import myplug
    a = code_identity(myplug.Scaled())["plugin"]
    (tmp_path / "myplug.py").write_text(PLUGIN_SRC.format(factor=2.0))
    assert code_identity(myplug.Scaled())["plugin"] != a  # the file, not the loaded class, is hashed
    # a copy of the sources with one metric file edited has another digest
    src = _tree_copy(tmp_path / "src")
    d0 = sources_digest(root=str(src))
    assert d0 == sources_digest()  # the same bytes under another folder: the same code
    _touch(src / "eval" / "metrics" / "measures.py")
    sources_digest.cache_clear()
    assert sources_digest(root=str(src)) != d0
    assert describe_change(None, ident).startswith("a record without")
    assert describe_change(ident, dict(ident, versions=dict(ident["versions"], numpy="0.0"))) == \
        f"numpy {ident['versions']['numpy']} -> 0.0"


def test_a_row_holds_the_versions_of_the_libraries_its_code_uses_and_a_plugin_of_all(tmp_path, monkeypatch):
    """PyTorch is Implicit-ARAP's: an upgrade changes its rows' identity, not ARAP's or
    SShaDe's; numpy and scipy are everyone's; a plug-in (whose imports go unseen) holds
    every numerical library's version."""
    import eval.run.code_identity as ci
    from baselines import ARAP
    from eval.run.library_versions import NUMERICAL
    ids = {m: code_identity(None, spec, references=False) for m, spec in BUILTIN.items()}
    assert "torch" in ids["Implicit-ARAP"]["versions"]
    assert all("torch" not in ids[m]["versions"] for m in ("ARAP", "Elastic", "ARAP-SR", "SShaDe"))
    assert all({"numpy", "scipy"} <= set(v["versions"]) for v in ids.values())
    monkeypatch.setattr(ci, "numerical_versions", lambda: {d: "0" for d in NUMERICAL})
    after = {m: code_identity(None, spec, references=False) for m, spec in BUILTIN.items()}
    assert after["ARAP"]["versions"] == dict.fromkeys(ids["ARAP"]["versions"], "0")
    (tmp_path / "myplug.py").write_text(PLUGIN_SRC.format(factor=1.0))
    monkeypatch.syspath_prepend(str(tmp_path))
    import myplug
    assert set(code_identity(myplug.Scaled())["versions"]) == set(NUMERICAL)
    assert set(code_identity(ARAP())["versions"]) < set(NUMERICAL)


@pytest.mark.slow
def test_changed_plugin_file_is_recomputed_on_resume(tmp_path, faust_root):
    (tmp_path / "faust").symlink_to(faust_root)
    plug = tmp_path / "scaledplug.py"
    plug.write_text(PLUGIN_SRC.format(factor=0.0))
    out, counter = tmp_path / "out", tmp_path / "calls.txt"
    method = "{_target_:scaledplug.Scaled,name:Scaled}"
    _eval(ROOT, out, method, env={"SSHADE_TEST_COUNTER": str(counter)})
    before = pd.read_csv(out / "cases.csv")
    plug.write_text(PLUGIN_SRC.format(factor=1.05))
    counter.unlink()
    r = _eval(ROOT, out, method, "resume=true", env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {"Scaled": 2}  # both pairs recomputed, none restored
    assert "2 stored run(s) recomputed, other code: the plug-in's source changed" in r.stdout + r.stderr
    after = pd.read_csv(out / "cases.csv")
    fresh = tmp_path / "fresh"
    _eval(ROOT, fresh, method)
    ref = pd.read_csv(fresh / "cases.csv")
    assert not after["volume_err_pct"].equals(before["volume_err_pct"])
    pd.testing.assert_series_equal(after["volume_err_pct"], ref["volume_err_pct"])
    info = json.loads((out / "run.json").read_text())
    assert info["resumed"]["restored"] == 0 and sum(info["resumed"]["recomputed"].values()) == 2


@pytest.mark.slow
def test_commit_between_two_halves_of_a_run_recomputes_the_first_half(tmp_path, faust_root):
    """A run killed after its first case, the project's sources changed (a metric file
    edited, as a commit would), then resumed: the first case's pairs run again, so the
    table holds rows of one code only."""
    (tmp_path / "faust").symlink_to(faust_root)
    tree = _tree_copy(tmp_path / "tree", "conf", "tests", "hydra_plugins")
    shutil.copy(ROOT / "pyproject.toml", tree / "pyproject.toml")  # marks a source checkout (harness/confdir.py)
    out, counter = tmp_path / "out", tmp_path / "calls.txt"
    methods = "{_target_:tests.store_methods.Counted,name:A},{_target_:tests.store_methods.Counted,name:B}"
    p = _eval(tree, out, methods, env={"SSHADE_TEST_COUNTER": str(counter), "SSHADE_TEST_HANG_AFTER": "2"},
              popen=True)
    kill_at_call(p, counter, 3)
    assert sorted(x.name for x in (out / "runs").rglob("*.json")) == ["A.json", "B.json"]  # the first case
    with open(tree / "eval" / "metrics" / "measures.py", "a") as fh:
        fh.write("\n_A_COMMIT_BETWEEN_THE_TWO_HALVES = 1\n")
    counter.unlink()
    r = _eval(tree, out, methods, "resume=true", env={"SSHADE_TEST_COUNTER": str(counter)})
    assert _counts(counter) == {"A": 2, "B": 2}  # the first half too
    assert "2 stored run(s) recomputed, other code: the project's sources changed" in r.stdout + r.stderr
    keys = {json.loads(p.read_text())["key_fields"]["code"]["sources"] for p in (out / "runs").rglob("*.json")}
    assert len(keys) == 1


def _moved_tree(tmp_path, edit_moved=False, drop_used_import=False):
    """A copy of the checkout where ``sshade.files.atomic_write`` moved (back) into a new
    module ``sshade.files_moved`` and ``defaust/store.py`` imports it from there."""
    tree = _tree_copy(tmp_path / "tree")
    files = (tree / "sshade" / "files.py").read_text()
    head, _, rest = files.partition("@contextlib.contextmanager")
    body, _, tail = rest.partition("def inside_folder(")
    (tree / "sshade" / "files.py").write_text(head + "from .files_moved import atomic_write\n\n\ndef inside_folder("
                                              + tail)
    moved = "import contextlib\nimport os\nimport tempfile\nfrom pathlib import Path\n\n\n@contextlib.contextmanager" \
        + body
    if edit_moved:
        moved = moved.replace("os.replace(tmp, path)", "os.replace(tmp, str(path))")
    (tree / "sshade" / "files_moved.py").write_text(moved)
    store = tree / "defaust" / "store.py"
    store.write_text(store.read_text().replace("from sshade.files import atomic_write",
                                               "from sshade.files_moved import atomic_write"))
    if drop_used_import:
        ref = tree / "eval" / "metrics" / "reference.py"
        ref.write_text(ref.read_text().replace("import hashlib\n", ""))
    return tree


def test_a_definition_moved_to_a_new_module_is_the_same_code(tmp_path):
    """same_code: a function moved into a new module, its old module importing it back and
    another module importing it from its new home, is no change; an edit of the moved
    function, or a removed import its module still uses, is one."""
    from eval.run.code_identity import modules_digest, modules_digest_at, same_code
    here = str(ROOT)
    tree = _moved_tree(tmp_path)
    for m in ("sshade.files", "sshade.files_moved"):
        assert same_code(m, ROOT, str(tree))  # the checkout is the "commit", the copy its future
    mods = ("sshade.files", "sshade.errors")
    assert modules_digest_at(mods, ROOT, here) == modules_digest(mods, here)
    edited = _moved_tree(tmp_path / "e", edit_moved=True)
    assert not same_code("sshade.files_moved", ROOT, str(edited))
    dropped = _moved_tree(tmp_path / "d", drop_used_import=True)
    assert not same_code("eval.metrics.reference", ROOT, str(dropped))
    assert same_code("defaust.store", ROOT, str(tree))  # an import from elsewhere, the same definition

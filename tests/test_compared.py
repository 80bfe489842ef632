"""eval/run/compared.py: ``compare_with=[RUN]`` puts a new method's row beside an earlier
run's rows without recomputing them (nor importing PyTorch for its Implicit-ARAP rows);
the earlier folder is never written; another build of the data, an edited record or a
run on another dataset is refused with one line."""
from __future__ import annotations

import csv
import hashlib
import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT, subprocess_env

PLUGIN = "{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:5}"
NO_TORCH = '''import sys
class _NoTorch:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] == "torch":
            raise ImportError("torch is not installed (simulated)")
        return None
sys.meta_path.insert(0, _NoTorch())
'''


def _snapshot(folder):
    return {str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _eval(args, env=None):
    return subprocess.run([sys.executable, "-m", "eval", *args], cwd=ROOT, env=env or subprocess_env(),
                          capture_output=True, text=True, timeout=600)


def _error(r) -> str:
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2 and lines and lines[-1].startswith("error: ") and "Traceback" not in r.stderr, r.stderr
    return lines[-1]


def _data(name: str, faust_root) -> list[str] | None:
    """The evaluator's dataset arguments for the committed folder ``results/<name>``:
    FAUST from the shared data; DeFAUST from this checkout's git-ignored ANNY build
    (``python -m defaust out=data/defaust``, about 5 min; of the subjects it was built with,
    when it holds some), None where it is not built or lacks subject 0."""
    if name == "faust":
        return ["dataset=faust", f"dataset.root={faust_root}"]
    manifest = ROOT / "data" / "defaust" / "manifest.json"
    if not manifest.is_file():
        return None
    args = ["dataset=defaust", "dataset.root=data/defaust", "dataset.build.enabled=false", "dataset.baseline_cases=all"]
    some = (json.loads(manifest.read_text()).get("parameters") or {}).get("subjects")
    if isinstance(some, list):  # built with subjects=[...] (the README's main job): the cases' subject 0 among them
        return args + [f"dataset.subjects=[{','.join(map(str, some))}]"] if 0 in some else None
    return args


def _both_canonical(folder, root) -> bool:
    """Whether the run ``folder`` recorded the canonical DeFAUST (``dataset_build``) and the
    build at ``root`` is canonical too: only then are its records made on that build's cases."""
    from eval.datasets.defaust_dataset import build_provenance
    made = json.loads((folder / "run.json").read_text()).get("dataset_build") or {}
    return made.get("canonical") is True and build_provenance(root)["canonical"] is True


@pytest.mark.slow
@pytest.mark.parametrize("name, cases", [("faust", ("s0_p1", "s0_p2")), ("defaust", ("s00_p01", "s00_p02"))])
def test_a_plugin_row_beside_a_committed_folder_reads_its_records_without_torch(tmp_path, faust_root, name, cases):
    res = ROOT / "results" / name
    if not (res / "runs").is_dir():
        pytest.skip(f"no committed results/{name}")
    data = _data(name, faust_root)
    if data is None:
        pytest.skip("no DeFAUST build holding subject 0 in data/defaust (python -m defaust out=data/defaust)")
    if name == "defaust" and not _both_canonical(res, ROOT / "data" / "defaust"):
        pytest.skip("results/defaust and data/defaust are not both the canonical DeFAUST: the committed rows stand on "
                    "other meshes (compare_with refuses them) until made again on the canonical build")
    from eval.run.pending_rows import pending_on_other_data
    other = sorted({c for c, _ in pending_on_other_data(res) if c in cases})
    if other:
        pytest.skip(f"results/{name} holds rows of {other[0]} made on an earlier build's meshes (pending in its "
                    "table.md; compare_with refuses them) until made again on this build")
    before = _snapshot(res)
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(NO_TORCH)
    env = subprocess_env()
    env["PYTHONPATH"] = f"{site}:{env['PYTHONPATH']}"
    out = tmp_path / "run"
    r = _eval([*data, "dataset.limit=2", f"methods=[{PLUGIN}]", f"compare_with=[results/{name}]",
               "reference.cases=none", "report.enabled=false", f"out_dir={out}"], env)
    assert r.returncode == 0, r.stderr[-3000:]
    assert _snapshot(res) == before  # read, never written
    stored = sorted(p.name for p in (out / "runs").rglob("*.json"))
    assert stored == ["Mine.json", "Mine.json"]  # only the new method ran
    with open(out / "compared.csv") as f:
        rows = list(csv.DictReader(f))
    assert {(r_["case"], r_["method"]) for r_ in rows} == {(c, m) for c in cases for m in
                                                          ("ARAP", "Elastic", "ARAP-SR", "Implicit-ARAP", "SShaDe")}
    for r_ in rows:  # each row is its committed record's, naming its run
        rec = json.loads((res / "runs" / r_["case"] / f"{r_['method']}.json").read_text())
        assert float(r_["volume_err_pct"]) == pytest.approx(rec["row"]["volume_err_pct"], rel=1e-12)
        assert r_["run"] == f"results/{name}" and r_["run_commit"].startswith(rec["git"]["commit"][:12])
    table = (out / "table.md").read_text()
    assert "Implicit-ARAP" in table and "(other run)" in table and f"read from results/{name}" in table
    line = next(ln for ln in table.splitlines() if ln.startswith("| ARAP |"))
    assert not next(x for x in line.split("|") if "(other run)" in x).strip().startswith("**")


@pytest.mark.slow
def test_another_build_of_the_data_is_refused_in_one_line(tmp_path, faust_root):
    first = tmp_path / "first"
    r = _eval(["dataset=faust", f"dataset.root={faust_root}", "dataset.limit=1", f"methods=[{PLUGIN}]",
               "reference.cases=none", "report.enabled=false", f"out_dir={first}"])
    assert r.returncode == 0, r.stderr[-2000:]
    before = _snapshot(first)
    out = tmp_path / "second"
    msg = _error(_eval(["dataset=faust", f"dataset.root={faust_root}", "dataset.limit=1", "dataset.seed=7",
                        f"methods=[{PLUGIN}]", f"compare_with=[{first}]", "reference.cases=none",
                        "report.enabled=false", f"out_dir={out}"]))
    assert "made on other data" in msg and "handles" in msg and "Mine.json" in msg
    assert _snapshot(first) == before and not (out / "cases.csv").exists()


@pytest.mark.slow
def test_an_edited_record_or_another_dataset_is_refused(tmp_path, faust_root):
    first = tmp_path / "first"
    r = _eval(["dataset=faust", f"dataset.root={faust_root}", "dataset.limit=1", f"methods=[{PLUGIN}]",
               "reference.cases=none", "report.enabled=false", f"out_dir={first}"])
    assert r.returncode == 0, r.stderr[-2000:]
    rec_path = next((first / "runs").rglob("Mine.json"))
    rec = json.loads(rec_path.read_text())
    rec["row"]["volume_err_pct"] = 0.001
    rec_path.write_text(json.dumps(rec))
    common = [f"dataset.root={faust_root}", "dataset.limit=1", "methods=[SShaDe]", "reference.cases=none",
              "report.enabled=false", f"compare_with=[{first}]"]
    msg = _error(_eval(["dataset=faust", *common, f"out_dir={tmp_path / 'a'}"]))
    assert "is not a valid record" in msg and "digest" in msg
    msg = _error(_eval(["dataset=shapes", *common[1:], f"out_dir={tmp_path / 'b'}"]))
    assert "dataset 'faust'" in msg and "'shapes'" in msg
    msg = _error(_eval(["dataset=faust", *common[:-1], f"compare_with=[{tmp_path}]", f"out_dir={tmp_path / 'c'}"]))
    assert "not a python -m eval run folder" in msg


@pytest.mark.slow
def test_a_run_made_under_another_handle_bound_or_reference_setting_is_refused_naming_it(tmp_path, faust_root):
    first = tmp_path / "first"
    base = ["dataset=faust", f"dataset.root={faust_root}", "dataset.limit=1", f"methods=[{PLUGIN}]",
            "reference.cases=none", "report.enabled=false", "figures.enabled=false"]
    r = _eval([*base, "handle_error_max_pct=null", f"out_dir={first}"])
    assert r.returncode == 0, r.stderr[-2000:]
    common = [*base[:3], "methods=[SShaDe]", *base[4:], f"compare_with=[{first}]"]
    msg = _error(_eval([*common, f"out_dir={tmp_path / 'a'}"]))
    assert "handle_error_max_pct=None" in msg and "handle_error_max_pct=1.0" in msg and str(first) in msg
    msg = _error(_eval([*common, "handle_error_max_pct=null", "reference.max_iter=3", f"out_dir={tmp_path / 'b'}"]))
    assert "reference.max_iter=50000" in msg and "reference.max_iter=3" in msg
    r = _eval([*common[:-1], "handle_error_max_pct=null", f"compare_with=[{first},{first}]",
               f"out_dir={tmp_path / 'c'}"])  # named twice: its rows once
    assert r.returncode == 0, r.stderr[-2000:]
    rows = (tmp_path / "c" / "compared.csv").read_text().splitlines()
    assert len(rows) == 2 and "named twice, read once" in r.stderr + r.stdout
    assert "handle_error_max_pct" in (tmp_path / "c" / "table.md").read_text()

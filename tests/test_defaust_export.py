"""defaust.export and ``python -m defaust export``: every format gives back the arrays
defaust.load gives, bit for bit; a folder that holds anything but an earlier export, or
lies inside the build, is refused before anything is written."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from defaust.dataset import load
from defaust.export import MARKER, export
from defaust.store import sha256_file
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh

from .conftest import ROOT, subprocess_env


def test_npz_export_round_trips_every_array(defaust_ci, tmp_path):
    files = export(defaust_ci, tmp_path / "x", fmt="npz", resolution="low")
    cases = load(defaust_ci, resolution="low")
    assert [f.name for f in files] == [f"{c.name}.npz" for c in cases] + [MARKER]
    for c in cases:
        d = np.load(tmp_path / "x" / f"{c.name}.npz")
        for k in ("V", "F", "handles", "targets", "static", "group", "V_gt", "snap_distance"):
            np.testing.assert_array_equal(d[k], getattr(c, k))
            assert d[k].dtype == getattr(c, k).dtype
        assert list(d["landmark_names"]) == list(c.landmark_names)
        assert (int(d["subject"]), int(d["pose"]), str(d["pose_name"]), str(d["resolution"])) == \
            (c.subject, c.pose, c.pose_name, "low")
    m = json.loads((tmp_path / "x" / MARKER).read_text())
    assert m["build_manifest_sha256"] == sha256_file(defaust_ci / "manifest.json")
    assert all(sha256_file(tmp_path / "x" / n) == h for n, h in m["files"].items())


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_mesh_export_round_trips_meshes_and_handles(defaust_ci, tmp_path, fmt):
    export(defaust_ci, tmp_path / fmt, fmt=fmt, resolution="high")
    for c in load(defaust_ci, resolution="high"):
        V, F = read_mesh(tmp_path / fmt / f"{c.name}.{fmt}")
        Vg, Fg = read_mesh(tmp_path / fmt / f"{c.name}_gt.{fmt}", validate=False)
        np.testing.assert_array_equal(V, c.V)
        np.testing.assert_array_equal(F, c.F)
        np.testing.assert_array_equal(Vg, c.V_gt)
        h = json.loads((tmp_path / fmt / f"{c.name}_handles.json").read_text())
        np.testing.assert_array_equal(np.array(h["handles"]), c.handles)
        np.testing.assert_array_equal(np.array(h["targets"]), c.targets)  # JSON keeps float64 exactly
        np.testing.assert_array_equal(np.array(h["static"]), c.static)
        assert h["units"] == "metres" and h["index_base"] == 0 and h["mesh"] == f"{c.name}.{fmt}"


def test_export_replaces_its_own_earlier_output(defaust_ci, tmp_path):
    out = tmp_path / "x"
    export(defaust_ci, out, fmt="npz", resolution="low", subjects=[0])
    first = sha256_file(out / "s00_p01.npz")
    export(defaust_ci, out, fmt="npz", resolution="low")
    assert sha256_file(out / "s00_p01.npz") == first  # deterministic


def _tree(p):
    return {str(f.relative_to(p)): f.read_bytes() for f in p.rglob("*") if f.is_file()}


def test_a_foreign_folder_or_the_build_itself_is_refused_unchanged(defaust_ci, tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("x")
    before = _tree(mine)
    with pytest.raises(SShaDeError, match="not empty and holds no export.json"):
        export(defaust_ci, mine)
    assert _tree(mine) == before
    build_before = _tree(defaust_ci)
    with pytest.raises(SShaDeError, match="inside the DeFAUST build"):
        export(defaust_ci, defaust_ci / "exported")
    assert _tree(defaust_ci) == build_before
    r = subprocess.run([sys.executable, "-m", "defaust", "export", str(defaust_ci), "--to", str(mine)],
                       capture_output=True, text=True, cwd=ROOT, env=subprocess_env(), timeout=300)
    assert r.returncode == 2 and r.stderr.startswith("error: refusing to export into") and r.stdout == ""
    assert _tree(mine) == before


@pytest.mark.parametrize("argv", [["export", "DIR"], ["export", "DIR", "--to", "X", "--format", "stl"], ["verify"]])
def test_cli_usage_errors_are_one_line(argv, tmp_path):
    r = subprocess.run([sys.executable, "-m", "defaust", *argv], capture_output=True, text=True, cwd=tmp_path,
                       env=subprocess_env(), timeout=300)
    assert r.returncode == 2 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith("error: ")
    assert not list(tmp_path.iterdir())  # nothing written


def test_cli_export_writes_and_reports_the_size(defaust_ci, tmp_path):
    r = subprocess.run([sys.executable, "-m", "defaust", "export", str(defaust_ci), "--to", str(tmp_path / "o"),
                        "--format", "obj", "--resolution", "low"], capture_output=True, text=True, cwd=ROOT,
                       env=subprocess_env(), timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("exported 12 file(s)")  # 4 cases x (mesh, ground truth, handles)
    assert len(list((tmp_path / "o").glob("*_handles.json"))) == 4


@pytest.mark.hf
def test_hf_export_loads_with_datasets_equal_to_defaust_load(defaust_ci, tmp_path):
    """``--format hf``: Parquet shards that HuggingFace ``datasets`` loads (whole and
    streamed) row for row equal to ``defaust.load``'s cases; small shards split in case
    order; the same build gives the same bytes."""
    from .conftest import optional_import
    datasets = optional_import("datasets")
    from defaust.hf_export import write_shards
    cases = load(defaust_ci, resolution="high")
    files = export(defaust_ci, tmp_path / "hf", fmt="hf", resolution="high")
    assert [f.relative_to(tmp_path / "hf").as_posix() for f in files] == \
        ["data/train-00000-of-00001.parquet", "croissant.json", MARKER]
    ds = datasets.load_dataset("parquet", data_dir=str(tmp_path / "hf"), split="train",
                               cache_dir=str(tmp_path / "cache"))
    assert ds.num_rows == len(cases)
    for row, c in zip(ds, cases):
        assert (row["name"], row["subject"], row["pose"], row["resolution"]) == (c.name, c.subject, c.pose, "high")
        for k in ("V", "F", "V_gt", "targets", "handles", "static", "group", "snap_distance"):
            a = np.asarray(row[k])
            np.testing.assert_array_equal(a, getattr(c, k))
        assert row["landmark_names"] == list(c.landmark_names) and row["phenotype"] is None  # synthetic bodies
    streamed = datasets.load_dataset("parquet", data_dir=str(tmp_path / "hf"), split="train", streaming=True)
    assert [r["name"] for r in streamed] == [c.name for c in cases]
    again = export(defaust_ci, tmp_path / "hf2", fmt="hf", resolution="high")
    assert again[0].read_bytes() == files[0].read_bytes()
    small = write_shards(cases, tmp_path / "small", {}, shard_mb=1e-6)  # one case per shard
    assert list(small) == [f"data/train-{i:05d}-of-{len(cases):05d}.parquet" for i in range(len(cases))]


def test_hf_export_without_pyarrow_names_the_extra_before_writing(defaust_ci, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import pyarrow raises ImportError
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    with pytest.raises(SShaDeError, match=r"pip install -e \.\[hf\]"):
        export(defaust_ci, tmp_path / "hf", fmt="hf")
    assert not (tmp_path / "hf").exists()


def test_hf_export_never_writes_through_a_linked_data_folder(defaust_ci, tmp_path):
    from defaust.hf_export import arrow_schema
    try:
        arrow_schema()
    except SShaDeError:
        pytest.skip("pyarrow is not importable here (the [hf] extra)")
    export(defaust_ci, tmp_path / "hf", fmt="hf", resolution="low")
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.rmtree(tmp_path / "hf" / "data")
    (tmp_path / "hf" / "data").symlink_to(outside)
    with pytest.raises(SShaDeError, match="a link or a file"):
        export(defaust_ci, tmp_path / "hf", fmt="hf", resolution="low")
    assert list(outside.iterdir()) == []


def test_an_export_of_another_format_into_an_earlier_export_leaves_none_of_its_files(defaust_ci, tmp_path):
    """An npz export into an earlier mesh export: every file the earlier one listed and
    this one does not write is gone, a file someone added stays, and the folder holds
    exactly this export's files besides (it left the old files beside it, unlisted)."""
    out = tmp_path / "x"
    old = export(defaust_ci, out, fmt="obj", resolution="low", subjects=[0])
    assert any(f.suffix == ".obj" for f in old)
    (out / "notes.txt").write_text("mine")
    new = export(defaust_ci, out, fmt="npz", resolution="low", subjects=[0])
    listed = set(json.loads((out / MARKER).read_text())["files"])
    held = {f.relative_to(out).as_posix() for f in out.rglob("*") if f.is_file()}
    assert held == listed | {MARKER, "notes.txt"} and {f.relative_to(out).as_posix() for f in new} == listed | {MARKER}
    assert (out / "notes.txt").read_text() == "mine"

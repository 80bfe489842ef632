"""defaust.describe: the ground truth's volume and area change per case, measured on the
files (checked against a direct sum over the faces), and the command that prints it
writes nothing."""
from __future__ import annotations

import hashlib
import subprocess
import sys

import numpy as np

from defaust.dataset import load
from defaust.describe import COLUMNS, describe, markdown, summary

from .conftest import ROOT, subprocess_env


def _volume(V, F):
    """Signed volume by the divergence theorem, written out: sum of det(v0, v1, v2) / 6."""
    return np.linalg.det(V[F]).sum() / 6.0


def _area(V, F):
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()


def test_ground_truth_changes_equal_a_direct_sum_over_the_faces(defaust_ci):
    rows = describe(defaust_ci, resolution="low")
    cases = load(defaust_ci, resolution="low")
    assert [r["case"] for r in rows] == [c.name for c in cases] and all(set(r) == set(COLUMNS) for r in rows)
    for r, c in zip(rows, cases):
        v0, a0 = _volume(c.V, c.F), _area(c.V, c.F)
        assert v0 > 0  # outward faces
        assert abs(r["gt_volume_change_pct"] - 100 * (_volume(c.V_gt, c.F) - v0) / v0) < 1e-9
        assert abs(r["gt_area_change_pct"] - 100 * (_area(c.V_gt, c.F) - a0) / a0) < 1e-9
        assert r["n_handles"] == len(c.handles) and r["n_static"] == int(c.static.sum())
    # skinning changes the volume: not zero on some case (docs/defaust.md, known limitations)
    assert max(abs(r["gt_volume_change_pct"]) for r in rows) > 0.01
    s = summary(rows)["gt_volume_change_pct"]
    assert s["min"] <= s["median"] <= s["max"] and s["n"] == len(rows)


def test_describe_prints_every_case_and_leaves_the_build_unchanged(defaust_ci):
    before = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(defaust_ci.rglob("*")) if p.is_file()}
    r = subprocess.run([sys.executable, "-m", "defaust", "describe", str(defaust_ci), "--resolution", "low"],
                       capture_output=True, text=True, cwd=ROOT, env=subprocess_env(), timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout == markdown(describe(defaust_ci, resolution="low"))
    assert sum(line.startswith("| s00_p") for line in r.stdout.splitlines()) == 4
    after = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(defaust_ci.rglob("*")) if p.is_file()}
    assert after == before


def test_describe_of_a_missing_folder_is_one_error_line(tmp_path):
    r = subprocess.run([sys.executable, "-m", "defaust", "describe", str(tmp_path / "none")],
                       capture_output=True, text=True, cwd=ROOT, env=subprocess_env(), timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [f"error: DeFAUST folder not found: {tmp_path / 'none'}"]

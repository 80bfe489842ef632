"""Breakdowns per target pose and per subject, the paired SShaDe-Elastic
comparison and the distribution figure (eval/present/breakdown.py), on synthetic cases.csv rows."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from eval.present.breakdown import breakdown_markdown, group_breakdown, paired_comparison, write_breakdown


def _rows(seed=0) -> pd.DataFrame:
    """10 subjects x 4 poses; SShaDe on all 40, Elastic on 8 (one failed); volume error of
    SShaDe = Elastic's - 0.5 on every common case but one (+1)."""
    rng = np.random.default_rng(seed)
    rows = []
    for s in range(10):
        for p in (1, 2, 3, 4):
            base = 2.0 + p + 0.1 * s + rng.normal(0, 0.01)
            case = f"s{s:02d}_p{p:02d}"
            rows.append(dict(case=case, subject=s, pose=p, method="SShaDe", error="", volume_err_pct=base,
                             edge_err_pct=1.0 + 0.01 * p, angle_err_deg=2.0, time_s=1.0))
            if s < 2:
                worse = (s, p) != (1, 4)
                rows.append(dict(case=case, subject=s, pose=p, method="Elastic",
                                 error="handles not reached" if (s, p) == (1, 3) else "",
                                 volume_err_pct=base + 0.5 if worse else base - 1.0,
                                 edge_err_pct=1.0, angle_err_deg=2.5, time_s=100.0))
    return pd.DataFrame(rows)


def test_group_breakdown_per_pose_and_subject():
    df = _rows()
    br = group_breakdown(df)
    assert set(br["by"]) == {"pose", "subject"}
    assert list(br.columns) == ["by", "group", "method", "metric", "n", "mean", "std", "median", "min", "max",
                                "ci_lo", "ci_hi"]
    v = br[(br["by"] == "pose") & (br["metric"] == "volume_err_pct")]
    s1 = v[(v["group"] == 1) & (v["method"] == "SShaDe")].iloc[0]
    x = df[(df.method == "SShaDe") & (df.pose == 1)]["volume_err_pct"]
    assert s1["n"] == 10 and s1["mean"] == pytest.approx(x.mean()) and s1["std"] == pytest.approx(x.std(ddof=1))
    e3 = v[(v["group"] == 3) & (v["method"] == "Elastic")].iloc[0]
    assert e3["n"] == 1 and np.isnan(e3["std"]) and np.isnan(e3["ci_lo"])  # the failed case (s01_p03) is left out
    from eval.present.intervals import bootstrap_ci
    xs = df[(df.method == "SShaDe") & (df.pose == 1)].sort_values("case")["volume_err_pct"]
    assert (s1["ci_lo"], s1["ci_hi"]) == bootstrap_ci(xs.to_numpy(float))  # over the group's cases, in case order
    assert s1["ci_lo"] <= s1["mean"] <= s1["ci_hi"]
    assert list(v["method"][v["group"] == 1]) == ["Elastic", "SShaDe"]  # table order
    subj = br[(br["by"] == "subject") & (br["metric"] == "edge_err_pct") & (br["method"] == "Elastic")]
    assert list(subj["group"]) == [0, 1] and list(subj["n"]) == [4, 3]
    # metrics in the table's order, not alphabetical
    assert list(dict.fromkeys(br[br["by"] == "pose"]["metric"])) == ["volume_err_pct", "edge_err_pct",
                                                                     "angle_err_deg"]


def test_paired_comparison_counts_and_bootstrap():
    df = _rows()
    r = paired_comparison(df)
    assert r["n"] == 7  # 8 Elastic cases, one failed
    assert r["n_a_lower"] == 6 and r["n_ties"] == 0
    assert r["median_diff"] == pytest.approx(-0.5)
    assert r["ci_lo"] <= r["median_diff"] <= r["ci_hi"]
    assert r == paired_comparison(df)  # seeded: reproducible
    assert paired_comparison(df, b="ARAP") is None
    assert paired_comparison(df.drop(columns="volume_err_pct")) is None
    # rows in another order: same answer
    assert paired_comparison(df.sample(frac=1, random_state=3)) == r


def test_breakdown_files_and_figure(tmp_path):
    df = _rows()
    df.to_csv(tmp_path / "cases.csv", index=False)
    df2 = pd.read_csv(tmp_path / "cases.csv")  # as read back: error NaN, ints
    paths = write_breakdown(df2, tmp_path, figure=True)
    assert set(paths) == {"breakdown_csv", "breakdown_md", "breakdown_png"}
    md = (tmp_path / "breakdown.md").read_text()
    assert "## Per pose: Volume (%)" in md and "## Per subject: EL (%)" in md
    assert "## Paired comparison: SShaDe vs Elastic (volume_err_pct)" in md
    assert "On 7 case(s) where both succeeded, SShaDe's volume_err_pct is below Elastic's on 6" in md
    assert "95% bootstrap interval" in md and "seed 0" in md
    assert pd.read_csv(tmp_path / "breakdown.csv")["n"].sum() > 0
    png = (tmp_path / "breakdown.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert md == breakdown_markdown(df2)


def test_breakdown_without_pairs_or_groups(tmp_path):
    df = pd.DataFrame({"case": ["a"], "method": ["SShaDe"], "error": ["boom"], "volume_err_pct": [1.0]})
    write_breakdown(df, tmp_path, figure=True)  # nothing successful: no figure, no exception
    md = (tmp_path / "breakdown.md").read_text()
    assert "no paired comparison" in md and not (tmp_path / "breakdown.png").exists()

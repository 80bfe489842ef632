"""defaust/anny_sampling.py: sampled ANNY bodies and poses (``anny.phenotypes=sampled``,
``anny.poses=sampled``). The draws' properties hold without ANNY; the bodies, the
difficulty, the checks and a build need body-models and the ANNY assets (skipped in one
line without them, as tests/test_defaust_anny.py)."""
from __future__ import annotations

import json

import numpy as np
import pytest

import defaust.anny_sampling as samp
from defaust.anny_poses import FORWARD, POSES
from defaust.anny_sampling import (
    PHENOTYPE_RANGES,
    POSE_ACTIONS,
    draw_phenotype,
    draw_pose,
    mean_displacement_pct,
    sampled_subject,
    scale_pose,
)
from defaust.anny_source import SUBJECTS
from defaust.config import BuildConfig
from defaust.self_intersections import self_intersections
from sshade.errors import SShaDeError

from .test_defaust_anny import _build, _fast_highres

# ----------------------------------------------------------------------------- draws (no ANNY)


def test_a_draw_is_a_function_of_its_seed_subject_pose_and_attempt():
    a = draw_phenotype(0, 7)
    assert a == draw_phenotype(0, 7)
    assert len({draw_phenotype(*k) for k in ((0, 7), (1, 7), (0, 8), (0, 7, 1))}) == 4
    p = draw_pose(0, 7, 2)
    assert p == draw_pose(0, 7, 2) and p.name == "sampled_2"
    assert len({draw_pose(*k).rotations for k in ((0, 7, 2), (1, 7, 2), (0, 8, 2), (0, 7, 3), (0, 7, 2, 1))}) == 5
    # pinned: a NumPy whose SeedSequence drew otherwise would change sampled builds (docs/defaust.md)
    assert (a.gender, a.age, a.muscle) == (0.0, 0.7984, 0.5981)


def test_phenotypes_stay_in_their_ranges_and_the_genders_split_evenly():
    draws = [draw_phenotype(3, s) for s in range(1000)]
    for k, (lo, hi) in PHENOTYPE_RANGES.items():
        v = np.array([getattr(p, k) for p in draws])
        assert lo <= v.min() and v.max() <= hi, k
        assert abs(v.mean() - (lo + hi) / 2) < 5 * (hi - lo) / np.sqrt(12 * 1000), k  # uniform: 5 sd of the mean
    g = np.array([p.gender for p in draws])
    assert set(g) == {0.0, 1.0} and abs(g.mean() - 0.5) < 5 * 0.5 / np.sqrt(1000)


def test_pose_angles_stay_within_the_joint_limits_and_one_foot_is_planted():
    limits = {}
    for _group, kind, joints, _vector, lo, hi in POSE_ACTIONS:
        for j in joints:
            limits.setdefault((j, kind), []).append((lo / len(joints), hi / len(joints)))
    for s in range(200):
        p = draw_pose(1, s, 1)
        moved = {r.joint[:-2] + ".L" if r.joint.endswith(".R") else r.joint for r in p.rotations}
        assert moved <= {j for j, _ in limits}
        for r in p.rotations:
            j = r.joint[:-2] + ".L" if r.joint.endswith(".R") else r.joint
            assert any(lo - 1e-9 <= r.degrees <= hi + 1e-9 for lo, hi in limits[(j, r.kind)]), r
        legs = {r.joint[-1] for r in p.rotations if r.joint.startswith(("upperleg", "lowerleg"))}
        assert len(legs) == 1 and p.planted == (("foot.R",) if legs == {"L"} else ("foot.L",))
        arms = [r for r in p.rotations if r.joint.startswith("upperarm01") and r.kind == "turn"]
        assert [r.joint for r in arms] == ["upperarm01.L", "upperarm01.R"]  # both arms, the right one mirrored
        assert arms[0].vector == FORWARD and arms[1].vector == (0.0, 0.0, -1.0)


def test_scale_pose_scales_every_angle_and_keeps_the_rest():
    p = draw_pose(0, 0, 1)
    q = scale_pose(p, 0.5)
    assert [r.degrees for r in q.rotations] == pytest.approx([0.5 * r.degrees for r in p.rotations], abs=1e-6)
    assert (q.name, q.planted, [r.joint for r in q.rotations]) == (p.name, p.planted, [r.joint for r in p.rotations])


# ----------------------------------------------------------------------------- config (no ANNY)


def test_the_fixed_builds_parameters_are_those_before_sampling():
    """The default build's parameters (and so its items' keys and checksums) hold no
    sampling key; a sampled build's say what was drawn and with which sampler."""
    d = BuildConfig(out="x").parameters()
    assert not {"anny_phenotypes", "anny_difficulty", "anny_n_targets", "sampler"} & set(d)
    assert d["anny_poses"] == ["arms_raised", "squat", "bend_twist", "step"]
    s = BuildConfig(out="x", anny_phenotypes="sampled", anny_poses="sampled", n_subjects=200).parameters()
    assert (s["anny_phenotypes"], s["anny_poses"], s["anny_difficulty"], s["anny_n_targets"], s["sampler"]) == \
        ("sampled", "sampled", 10.0, 4, samp.SAMPLER_VERSION)
    f = BuildConfig(out="x", anny_phenotypes="sampled").parameters()
    assert f["anny_phenotypes"] == "sampled" and "anny_difficulty" not in f and f["anny_poses"][0] == "arms_raised"


@pytest.mark.parametrize("kw,word", [({"anny_phenotypes": "random"}, "anny.phenotypes"),
                                     ({"anny_poses": "random"}, "anny.poses"),
                                     ({"anny_difficulty": 0.0}, "anny.difficulty"),
                                     ({"anny_difficulty": 60.0}, "anny.difficulty"),
                                     ({"anny_n_targets": 0}, "anny.n_targets"),
                                     ({"n_subjects": 10**9, "anny_phenotypes": "sampled"}, "n_subjects")])
def test_a_bad_sampling_parameter_is_refused_naming_it(kw, word):
    with pytest.raises(SShaDeError, match=word):
        BuildConfig(out="x", **kw).validate()


# ----------------------------------------------------------------------------- with ANNY


def test_a_sampled_subject_meets_its_difficulty_without_self_intersection(anny_fixed_assets):
    got = sampled_subject(4, seed=0, model=anny_fixed_assets, n_targets=2, difficulty=8.0)
    sub, rec = got.subject, got.record
    assert sub.phenotype == draw_phenotype(0, 4, rec["body_attempts"] - 1)
    assert [p.name for p in sub.poses] == ["rest", "sampled_1", "sampled_2"] and len(rec["poses"]) == 2
    for i, (p, r) in enumerate(zip(sub.poses[1:], rec["poses"]), 1):
        d = mean_displacement_pct(anny_fixed_assets, sub.phenotype, p)
        assert abs(d - 8.0) <= 0.02 * 8.0 and d == pytest.approx(r["difficulty_pct"], abs=1e-4)
        assert 0 < r["scale"] <= 1 and r["attempts"] >= 1
        assert self_intersections(sub.posed(i), sub.F).size == 0
    again = sampled_subject(4, seed=0, model=anny_fixed_assets, n_targets=2, difficulty=8.0)
    np.testing.assert_array_equal(again.subject.posed(2), sub.posed(2))
    assert json.dumps(again.record) == json.dumps(rec)


def test_a_failed_draw_is_redrawn_with_the_next_attempt_and_counted(anny_fixed_assets, monkeypatch):
    real = samp.self_intersections
    calls = []

    def fails_first(V, F):
        calls.append(1)
        return np.array([0]) if len(calls) == 1 else real(V, F)

    monkeypatch.setattr(samp, "self_intersections", fails_first)
    got = sampled_subject(2, seed=0, model=anny_fixed_assets, phenotypes="fixed", n_targets=1, difficulty=8.0)
    assert got.subject.phenotype == SUBJECTS[2] and got.record["poses"][0]["attempts"] == 2
    assert got.subject.poses[1].description.endswith("attempt 1)")
    monkeypatch.setattr(samp, "self_intersections", lambda V, F: np.array([0]))
    monkeypatch.setattr(samp, "MAX_ATTEMPTS", 2)
    with pytest.raises(SShaDeError, match="smaller anny.difficulty"):
        sampled_subject(2, seed=0, model=anny_fixed_assets, phenotypes="fixed", n_targets=1, difficulty=8.0)


def test_library_poses_on_a_sampled_body(anny_fixed_assets):
    got = sampled_subject(11, seed=5, model=anny_fixed_assets, poses=[POSES["squat"]])
    assert got.subject.subject == 11 and got.subject.pose_names == ["rest", "squat"] and got.record["poses"] == []


@pytest.mark.slow  # a whole build (30-50 s): the slow suite, which .ci/run runs next
def test_a_sampled_build_is_reproducible_and_verifies(anny_fixed_assets, anny_cache, tmp_path, monkeypatch):
    """Two builds with one seed: the same manifest (every checksum); another seed draws
    other bodies; the build verifies and loads; beyond the table's 10 subjects."""
    from defaust.dataset import load, verify

    _fast_highres(monkeypatch)
    extra = ["anny.phenotypes=sampled", "anny.poses=sampled", "anny.n_targets=2", "anny.difficulty=8",
             "subjects=[12]", "workers=1"]
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    _build(a, anny_cache, *extra)
    _build(b, anny_cache, *extra)
    _build(c, anny_cache, *extra, "seed=1")
    assert (a / "manifest.json").read_bytes() == (b / "manifest.json").read_bytes()
    ma, mc = (json.loads((x / "manifest.json").read_text()) for x in (a, c))
    ra, rc = ma["subjects"]["subject_12"], mc["subjects"]["subject_12"]
    assert ra["phenotype"] != rc["phenotype"] and ra["pose_names"] == {"0": "rest", "1": "sampled_1", "2": "sampled_2"}
    assert ra["sampled"]["sampler"] == samp.SAMPLER_VERSION and len(ra["sampled"]["poses"]) == 2
    assert ra["poses"]["1"]["name"] == "sampled_1" and "SeedSequence" in ma["seeds"]["anny"]
    assert verify(a) == []
    cases = load(a, subjects=[12])  # a build of subject 12 only
    assert [c_.name for c_ in cases] == ["s12_p01", "s12_p02"]

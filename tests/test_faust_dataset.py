"""FAUST discovery, landmarks and DeFAUST-style handle extraction (eval/datasets/faust.py,
defaust/handles.py) on the real registrations in ../shared/data/faust_reg."""
from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra

from defaust.build import handle_seed
from defaust.handles import (
    BASE_LANDMARKS,
    edge_length_matrix,
    geodesic_neighbourhood,
    landmark_handles,
    landmarks_for_target,
)
from eval.datasets import FAUST_LANDMARKS, discover_faust, faust_cases, load_cases
from eval.datasets.faust import FaustOptions, case_seed, faust_plan
from sshade.errors import SShaDeError

L = len(FAUST_LANDMARKS)
LM = np.array(list(FAUST_LANDMARKS.values()))


def _lm(*idx):
    """Landmark dict {name: vertex} for landmark_handles."""
    return {f"l{i}": int(v) for i, v in enumerate(idx)}


@pytest.fixture(scope="module")
def faust_root(shared_data):
    root = shared_data / "faust_reg"
    if not root.is_dir() or not list(root.glob("tr_reg_*.ply")):
        pytest.skip(f"no FAUST registrations in {root}")
    return root


@pytest.fixture(scope="module")
def present(faust_root):
    """(subject, pose) of every tr_reg_XYZ.ply in the folder, from the file names."""
    out = set()
    for p in faust_root.iterdir():
        m = re.fullmatch(r"tr_reg_(\d{3})\.ply", p.name)
        if m:
            out.add((int(m.group(1)) // 10, int(m.group(1)) % 10))
    return out


@pytest.fixture(scope="module")
def cases(faust_root):
    """Every non-rest pose with all 11 landmarks (most checks below need every group)."""
    return faust_cases(faust_root, FaustOptions(protocol="all_landmarks"))


@pytest.fixture(scope="module")
def paper_cases(faust_root):
    return faust_cases(faust_root)


# ---------------------------------------------------------------- discovery

def test_discovery_finds_every_registration(faust_root, present):
    found = discover_faust(faust_root)
    assert set(found) == present
    assert list(found) == sorted(found)
    for (s, p), path in found.items():
        assert path.name == f"tr_reg_{10 * s + p:03d}.ply"


def test_discovery_official_layout_and_odd_names(tmp_path, faust_root):
    reg = tmp_path / "training" / "registrations"
    reg.mkdir(parents=True)
    (reg / "tr_reg_010.ply").symlink_to(faust_root / "tr_reg_010.ply")
    (reg / "tr_reg_0100.ply").write_text("not a registration name")
    (tmp_path / "tr_scan_000.ply").write_text("scan, not a registration")
    assert list(discover_faust(tmp_path)) == [(1, 0)]


def test_discovery_empty_folder_names_it(tmp_path):
    with pytest.raises(SShaDeError, match=re.escape(str(tmp_path))):
        discover_faust(tmp_path)
    with pytest.raises(SShaDeError, match="not found"):
        discover_faust(tmp_path / "missing")
    with pytest.raises(SShaDeError):
        load_cases("faust", tmp_path)
    with pytest.raises(SShaDeError, match="unknown dataset"):
        load_cases("tosca", tmp_path)


def test_one_case_per_non_rest_pose(cases, present):
    rest = {s for s, p in present if p == 0}
    expect = sorted((s, p) for s, p in present if p != 0 and s in rest)
    assert [(c.subject, c.pose) for c in cases] == expect
    assert [c.name for c in cases] == [f"s{s}_p{p}" for s, p in expect]


def test_subject_pose_filters_and_limit(faust_root, cases):
    sub = faust_cases(faust_root, FaustOptions(subjects=[cases[0].subject], poses=[cases[0].pose]))
    assert [c.name for c in sub] == [cases[0].name]
    assert [c.name for c in faust_cases(faust_root, FaustOptions(limit=2))] == [c.name for c in cases[:2]]
    with pytest.raises(SShaDeError, match="no FAUST case"):
        faust_cases(faust_root, FaustOptions(subjects=[9999]))
    with pytest.raises(SShaDeError, match="limit"):
        faust_cases(faust_root, FaustOptions(limit=0))


# ---------------------------------------------------------------- protocols

def test_paper_protocol_landmark_counts_per_target(paper_cases, present):
    """Default protocol = the paper's (the DeFAUST builder's rule): per subject the first
    4 non-rest poses, 6 landmarks (BASE_LANDMARKS) for targets 1-3, all 11 for the last."""
    by_subject: dict[int, list] = {}
    for c in paper_cases:
        by_subject.setdefault(c.subject, []).append(c)
    rest = {s for s, p in present if p == 0}
    assert sorted(by_subject) == sorted(s for s in rest if any(q != 0 for s2, q in present if s2 == s))
    for s, cs in by_subject.items():
        expect = sorted(p for s2, p in present if s2 == s and p != 0)[:4]
        assert [c.pose for c in cs] == expect
        n = len(cs)
        for i, c in enumerate(cs):
            names = list(FAUST_LANDMARKS) if i == n - 1 else list(BASE_LANDMARKS)
            assert list(c.landmark_names) == names
            assert c.delta.shape == (len(names),)
            assert np.bincount(c.group, minlength=len(names)).tolist() == [30] * len(names)
            assert len(c.handles) == 30 * len(names)
        if n == 4:
            assert [len(c.landmark_names) for c in cs] == [6, 6, 6, 11]


def test_paper_cases_are_the_builders_low_res_handles(paper_cases):
    """Same rule, same seeds as ``defaust.build`` (landmarks_for_target, handle_seed)."""
    for c in paper_cases[:4]:
        assert c.seed == handle_seed(0, c.subject, c.pose) == case_seed(0, c.subject, c.pose)
        ps = [d.pose for d in paper_cases if d.subject == c.subject]
        lm = landmarks_for_target(dict(FAUST_LANDMARKS), ps.index(c.pose), len(ps))
        H = landmark_handles(c.V, c.F, c.V_gt, lm, seed=handle_seed(0, c.subject, c.pose))
        np.testing.assert_array_equal(H.index, c.handles)
        np.testing.assert_array_equal(H.target, c.targets)


def test_protocol_plans_without_files():
    files = {(s, p): f"tr_reg_{10 * s + p:03d}.ply" for s in (0, 1) for p in range(7)}
    del files[(1, 0)]  # subject 1 has no rest pose
    plan = faust_plan(files)
    assert [(s, p, len(lm)) for s, p, lm in plan] == [(0, 1, 6), (0, 2, 6), (0, 3, 6), (0, 4, 11)]
    plan = faust_plan(files, n_targets=2)
    assert [(p, len(lm)) for _, p, lm in plan] == [(1, 6), (2, 11)]
    # explicit targets, as the builder's faust_target_poses: the last one listed gets all
    assert [(p, len(lm)) for _, p, lm in faust_plan(files, poses=[5, 2])] == [(2, 6), (5, 11)]
    plan = faust_plan(files, protocol="all_landmarks")
    assert [(s, p) for s, p, _ in plan] == [(0, p) for p in range(1, 7)]
    assert all(len(lm) == len(FAUST_LANDMARKS) for _, _, lm in plan)
    for bad in (0, "2", 1.5, True):
        with pytest.raises(SShaDeError, match="n_targets"):
            faust_plan(files, n_targets=bad)
    with pytest.raises(SShaDeError, match="protocol must be one of"):
        faust_plan(files, protocol="nope")
    with pytest.raises(SShaDeError, match="no FAUST case"):
        faust_plan(files, subjects=[1])
    with pytest.raises(SShaDeError, match="no FAUST case"):
        faust_plan(files, subjects=[1], protocol="all_landmarks")


def test_protocol_through_the_registry(faust_root, cases):
    alt = load_cases("faust", faust_root, protocol="all_landmarks", limit=1)[0]
    assert alt.name == cases[0].name and len(alt.landmark_names) == len(FAUST_LANDMARKS)
    with pytest.raises(SShaDeError, match="protocol"):
        load_cases("faust", faust_root, protocol="sideways")


# ---------------------------------------------------------------- landmarks

def test_landmark_list_shape():
    assert 10 <= L <= 12
    assert len(set(LM.tolist())) == L
    assert ((LM >= 0) & (LM < 6890)).all()


def test_landmarks_on_the_expected_body_parts(cases):
    """On every rest pose (upright, y up, subject's left = +x): head top is at the top,
    feet at the bottom, hands and feet are mirrored left/right around the crotch, and
    the vertical order head > chest > crotch > knees > feet holds."""
    seen = set()
    for c in cases:
        if c.subject in seen:
            continue
        seen.add(c.subject)
        P = {k: c.V[v] for k, v in FAUST_LANDMARKS.items()}
        y = c.V[:, 1]
        h = y.max() - y.min()
        assert y.max() - P["head_top"][1] < 0.02 * h
        assert P["left_foot"][1] - y.min() < 0.03 * h and P["right_foot"][1] - y.min() < 0.03 * h
        assert P["head_top"][1] > P["chest"][1] > P["crotch"][1] > P["left_knee"][1] > P["left_foot"][1]
        assert P["crotch"][1] > P["right_knee"][1] > P["right_foot"][1]
        x0 = P["crotch"][0]
        for part in ("hand", "elbow", "knee", "foot"):
            assert P[f"left_{part}"][0] > x0 > P[f"right_{part}"][0], part
        # hands are the lateral extremes of the arms
        assert abs(P["left_hand"][0] - c.V[:, 0].max()) < 0.05 and abs(P["right_hand"][0] - c.V[:, 0].min()) < 0.05


def test_landmarks_keep_intrinsic_distances_across_poses(cases):
    """Registration correspondence: geodesic distances between landmarks change by a few
    percent (median) between the poses of one subject, i.e. the same body parts. The
    worst pair is crotch-knee with a raised leg (inner thigh stretches ~30%)."""
    by_subject: dict[int, list[np.ndarray]] = {}
    for c in cases:
        if c.subject not in by_subject:
            by_subject[c.subject] = [dijkstra(edge_length_matrix(c.V, c.F), directed=False, indices=LM)[:, LM]]
        by_subject[c.subject].append(dijkstra(edge_length_matrix(c.V_gt, c.F), directed=False, indices=LM)[:, LM])
    for s, Ds in by_subject.items():
        ref = Ds[0]
        off = ~np.eye(L, dtype=bool)
        for D in Ds[1:]:
            rel = np.abs(D[off] - ref[off]) / ref[off]
            assert np.median(rel) < 0.05, s
            assert rel.max() < 0.35, s


# ---------------------------------------------------------------- handles

def test_case_arrays(cases):
    for c in cases:
        n = len(c.V)
        assert c.V.shape == c.V_gt.shape == (n, 3) and c.F.shape[1] == 3
        h = len(c.handles)
        assert c.handles.dtype == np.int64 and c.targets.shape == (h, 3) and c.static.shape == (h,)
        assert c.static.dtype == bool and c.group.shape == (h,) and c.delta.shape == (L,)
        assert len(np.unique(c.handles)) == h
        # at most L * 30 after de-duplication; these landmarks are far enough apart
        # (>= 15 cm) that the 90-vertex neighbourhoods never overlap on FAUST
        assert h <= L * 30
        assert h == L * 30
        assert np.bincount(c.group, minlength=L).tolist() == [30] * L


def test_handles_lie_in_their_landmark_neighbourhood(cases):
    c = cases[0]
    N = geodesic_neighbourhood(c.V, c.F, LM, 90)
    assert (N[:, 0] == LM).all()
    for g in range(L):
        assert np.isin(c.handles[c.group == g], N[g]).all()


def test_static_and_dynamic_targets(cases):
    for c in cases:
        st = c.static
        np.testing.assert_array_equal(c.targets[st], c.V[c.handles[st]])
        np.testing.assert_array_equal(c.targets[~st], c.V_gt[c.handles[~st]])
        gs = c.delta / 30 < 0.02
        np.testing.assert_array_equal(st, gs[c.group])
        # delta is the summed displacement of the group between the poses
        for g in range(L):
            hv = c.handles[c.group == g]
            assert c.delta[g] == pytest.approx(np.linalg.norm(c.V_gt[hv] - c.V[hv], axis=1).sum())
    # the default threshold gives both kinds somewhere in the data set
    allst = np.concatenate([c.static for c in cases])
    if len(cases) >= 4:
        assert allst.any() and (~allst).any()


def test_threshold_extremes(cases):
    c = cases[0]
    H = landmark_handles(c.V, c.F, c.V_gt, FAUST_LANDMARKS, static_threshold=1e9, seed=c.seed)
    assert H.static.all() and np.array_equal(H.target, c.V[H.index])
    H = landmark_handles(c.V, c.F, c.V_gt, FAUST_LANDMARKS, static_threshold=0.0, seed=c.seed)
    assert not H.static.any() and np.array_equal(H.target, c.V_gt[H.index])
    np.testing.assert_array_equal(H.index, c.handles)


def test_determinism(faust_root, cases):
    again = faust_cases(faust_root, FaustOptions(protocol="all_landmarks"))
    for a, b in zip(cases, again):
        np.testing.assert_array_equal(a.handles, b.handles)
        np.testing.assert_array_equal(a.targets, b.targets)
        assert a.seed == b.seed == case_seed(0, a.subject, a.pose)
    other = faust_cases(faust_root, FaustOptions(seed=1, limit=1))[0]
    assert other.seed != cases[0].seed
    assert not np.array_equal(other.handles, cases[0].handles)
    # a case's handles do not depend on which other cases are built
    last = cases[-1]
    solo = faust_cases(faust_root, FaustOptions(subjects=[last.subject], poses=[last.pose]))[0]
    np.testing.assert_array_equal(solo.handles, last.handles)
    assert len({c.seed for c in cases}) == len(cases)


def test_geodesic_neighbourhood_matches_full_dijkstra(cases):
    c = cases[0]
    G = edge_length_matrix(c.V, c.F)
    D = dijkstra(G, directed=False, indices=LM[:3])
    N = geodesic_neighbourhood(c.V, c.F, LM[:3], 90, graph=G)
    for i in range(3):
        order = np.lexsort((np.arange(len(c.V)), D[i]))
        np.testing.assert_array_equal(N[i], order[:90])
    # a neighbourhood as large as the mesh (the search radius has to grow)
    assert sorted(geodesic_neighbourhood(c.V, c.F, [0], len(c.V), graph=G)[0]) == list(range(len(c.V)))


def test_landmark_handles_bad_input(cases):
    c = cases[0]
    with pytest.raises(SShaDeError, match="out of range"):
        landmark_handles(c.V, c.F, c.V_gt, _lm(len(c.V)))
    with pytest.raises(SShaDeError, match="share vertices"):
        landmark_handles(c.V, c.F, c.V_gt, _lm(5, 5))
    with pytest.raises(SShaDeError, match="n_per_landmark"):
        landmark_handles(c.V, c.F, c.V_gt, _lm(5), n_per_landmark=91, neighbourhood=90)
    with pytest.raises(SShaDeError, match="V_target"):
        landmark_handles(c.V, c.F, c.V_gt[:-1], _lm(5))
    bad = c.V_gt.copy()
    bad[3] = np.nan
    with pytest.raises(SShaDeError, match="NaN"):
        landmark_handles(c.V, c.F, bad, _lm(5))
    with pytest.raises(SShaDeError, match="static_threshold"):
        landmark_handles(c.V, c.F, c.V_gt, _lm(5), static_threshold=-1)
    with pytest.raises(SShaDeError, match="no landmarks"):
        landmark_handles(c.V, c.F, c.V_gt, {})


def test_overlapping_groups_are_deduplicated(cases):
    c = cases[0]
    # two adjacent landmarks with neighbourhoods of 60 drawn whole: heavy overlap
    a = int(LM[0])
    b = int(edge_length_matrix(c.V, c.F)[a].indices[0])  # a neighbour of a
    H = landmark_handles(c.V, c.F, c.V_gt, _lm(a, b), n_per_landmark=60, neighbourhood=60, seed=0)
    assert len(np.unique(H.index)) == len(H.index) < 120
    assert (H.group[:60] == 0).all()  # first group kept whole
    N = geodesic_neighbourhood(c.V, c.F, [a, b], 60)
    assert set(H.index) == set(N.ravel().tolist())

"""The high-res ground truth of FAUST-built DeFAUST cases (defaust.registration_gt through
FaustSource.target_high), on small FAUST-like registrations written to a temporary folder:
a target equal to the rest gives rest_high, a rigid motion of the target gives the same
motion of the ground truth, and pose_info's volume and area changes equal trimesh's."""
from __future__ import annotations

import igl
import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from defaust.config import BuildConfig
from defaust.highres import subdivide_remesh
from defaust.registration_gt import map_target, surface_map
from defaust.sources import FAUST_HIGH_GT, FaustSource
from defaust.store import write_ply
from sshade.errors import SShaDeError

from .conftest import icosphere

#: Bound of the rigid-motion test, in units of the bounding-box diagonal. Measured: 5e-15
#: here (the LS3 subdivision's least-squares sphere fits of a moved mesh equal the moved
#: fits to rounding); 6e-12 on FAUST subject 0's 168k-vertex ground truth (docs/defaust.md).
RIGID_TOL = 1e-12
ROT = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
SHIFT = np.array([0.4, -0.2, 1.3])


def _body():
    """A FAUST-like closed body: a once-more subdivided icosphere stretched to 1.7 m with bumps."""
    V, F = icosphere()
    V, F = igl.upsample(V, F)
    V = np.asarray(V) / np.linalg.norm(V, axis=1, keepdims=True)
    V = V * [0.25, 0.85, 0.15] * (1 + 0.08 * np.sin(5 * V[:, [1]]) * np.cos(3 * V[:, [0]]))
    return V + [0, 0.85, 0], np.asarray(F, np.int64)


def _bend(V):
    """A smooth non-rigid pose: the upper body leans forward, the legs spread a little."""
    y = V[:, 1]
    out = V.copy()
    out[:, 2] += 0.15 * np.clip(y - 0.9, 0, None) ** 2
    out[:, 0] *= 1 + 0.1 * np.clip(0.8 - y, 0, None)
    return out


@pytest.fixture(scope="module")
def faust_like(tmp_path_factory):
    """A FaustSource over registrations tr_reg_000..002 (rest, bent, bent and moved rigidly),
    with subject 0's rest item done as the build does it (rest_high, ls3_iterations)."""
    root = tmp_path_factory.mktemp("faust_like")
    V0, F0 = _body()
    V1 = _bend(V0)
    for i, V in enumerate([V0, V1, V1 @ ROT.T + SHIFT, V0 @ ROT.T + SHIFT]):
        write_ply(root / f"tr_reg_00{i}.ply", V, F0)
    src = FaustSource(BuildConfig(out=root / "out", source="faust", faust_root=root))
    hr = subdivide_remesh(V0, F0, vertex_range=(2000, 3000), remesh_iterations=3, check_distance=True)
    src.remember(("rest_info", 0), {"ls3_iterations": hr.iterations})
    src.remember(("rest_high", 0), (hr.V, hr.F))
    return src, hr


def _diag(V):
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def test_a_target_equal_to_the_rest_gives_rest_high(faust_like):
    src, hr = faust_like
    Vg = map_target(src.surface_map(0, hr.V), *src.rest_low(0))
    assert np.abs(Vg - hr.V).max() <= 1e-12 * _diag(hr.V)
    # the remesh reprojects onto the subdivided surface: the offsets are rounding-sized
    assert src.surface_map(0, hr.V).offset_max <= 1e-12 * _diag(hr.V)


def test_a_rigid_motion_of_the_target_moves_the_ground_truth_rigidly(faust_like):
    src, hr = faust_like
    tol = RIGID_TOL * _diag(hr.V)
    Vg3 = src.target_high(0, 3, hr.V)  # the rest moved rigidly
    assert np.abs(Vg3 - (hr.V @ ROT.T + SHIFT)).max() <= tol
    Vg1, Vg2 = src.target_high(0, 1, hr.V), src.target_high(0, 2, hr.V)  # bent, bent and moved
    assert np.abs(Vg2 - (Vg1 @ ROT.T + SHIFT)).max() <= tol
    assert np.abs(Vg1 - hr.V).max() > 0.01  # the bend does move the ground truth


def test_the_ground_truth_is_on_rest_high_faces_and_pose_info_agrees_with_trimesh(faust_like):
    src, hr = faust_like
    Vg = src.target_high(0, 1, hr.V)
    assert Vg.shape == hr.V.shape and Vg.dtype == np.float64
    info = src.pose_info(0, 1, Vg, hr.F)

    def tm(V, F):
        m = trimesh.Trimesh(vertices=V, faces=F, process=False, validate=False)
        return m.volume, m.area

    for (V0, F), V1, res in [((hr.V, hr.F), Vg, "high"), (src.rest_low(0), src.target_low(0, 1), "low")]:
        (vol0, a0), (vol1, a1) = tm(V0, F), tm(V1, F)
        assert info[f"gt_volume_change_pct_{res}"] == pytest.approx(100 * (vol1 - vol0) / vol0, abs=1e-9)
        assert info[f"gt_area_change_pct_{res}"] == pytest.approx(100 * (a1 - a0) / a0, abs=1e-9)
    assert abs(info["gt_volume_change_pct_high"]) > 0.1  # a real change, not a zero compared to a zero
    # the ground truth follows the subdivided target: its changes are near the registration's
    assert info["gt_volume_change_pct_high"] == pytest.approx(info["gt_volume_change_pct_low"], abs=0.5)
    assert 0 <= info["rest_high_offset_max_m"] <= 1e-12


def test_faust_pose_keys_name_the_ground_truth_and_other_topologies_are_refused(faust_like):
    src, hr = faust_like
    assert src.has_high_gt and src.pose_inputs(0, 1)["high_ground_truth"] == FAUST_HIGH_GT
    V0, F0 = src.rest_low(0)
    m = surface_map(V0, F0, hr.V, hr.iterations)
    with pytest.raises(SShaDeError, match="another topology"):
        map_target(m, V0, F0[:, [0, 2, 1]])

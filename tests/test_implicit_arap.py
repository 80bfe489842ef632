"""Implicit-ARAP (baselines/implicit_arap/) with PyTorch (extra [neural], mark ``neural``;
each test skips with one line where ``torch`` cannot be imported): the parts on small
inputs: an analytic sphere SDF in place of the fitted one, the identity field when no
handle moves, a rigid motion of every handle, the patch energy (zero for a rigid map, a
hand computation on one triangle), a decreasing loss, and bit-identical output under a
seed. Without PyTorch: tests/test_implicit_arap_without_torch.py."""
from __future__ import annotations

import numpy as np
import pytest

from baselines.implicit_arap import ImplicitARAP, ImplicitARAPParams
from baselines.implicit_arap.field import DeformationField, rodrigues
from baselines.implicit_arap.method import fit_field
from baselines.implicit_arap.patches import disk, edge_structure, mesh_patches, patch_energy
from baselines.implicit_arap.sdf import sphere_sdf
from sshade.errors import SShaDeError

from .optional import optional_import

pytestmark = pytest.mark.neural
torch = None  # the torch module, set by _import_torch


@pytest.fixture(autouse=True, scope="module")
def _import_torch():
    """Import PyTorch for this module's tests (at most 2 threads), or skip each of them
    with one line."""
    global torch
    torch = optional_import("torch")
    torch.set_num_threads(min(2, torch.get_num_threads()))


#: Small settings: seconds per call on 2 cores.
SMALL = dict(layers=3, width=32, skip=0, octaves=2, sdf_steps=0, deform_steps=60, surface_patches=24,
             handle_patches=8, space_patches=8, patch_points=8, projections=2, deform_lr=3e-3)


def _sphere_mesh():
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def _settings(**kw):
    """The cpu preset with :data:`SMALL` and ``kw`` over it, on the CPU."""
    return ImplicitARAPParams(**{**SMALL, "device": "cpu", **kw})


def _field(X, F, handles, targets, steps=60, seed=0, **kw):
    """fit_field on the analytic sphere SDF; (field, loss history)."""
    moving = ~np.all(targets == X[handles], axis=1)
    gen = torch.Generator().manual_seed(seed)
    field, hist, _ = fit_field(sphere_sdf(0.5), X, F, handles, targets, moving, _settings(deform_steps=steps, **kw),
                               generator=gen, rng=np.random.default_rng(seed))
    return field, hist


def _apply(field, X):
    with torch.no_grad():
        return field(torch.as_tensor(X, dtype=torch.float32)).double().numpy()


def test_identity_when_no_handle_moves():
    X, F = _sphere_mesh()
    h = np.arange(0, len(X), 7)
    field, hist = _field(X, F, h, X[h].copy())
    assert max(hist) < 1e-10  # starts at the identity, whose loss is zero: nothing moves
    assert np.abs(_apply(field, X) - X).max() < 1e-6


def test_rigid_motion_of_all_handles_is_near_rigid():
    """Every 5th vertex moved by one rotation and translation: the result is close to
    that motion, closer with a stronger ARAP weight (the soft handle terms and the
    small patches leave the field some freedom between handles at weight 10)."""
    X, F = _sphere_mesh()
    h = np.arange(0, len(X), 5)
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    t = np.array([0.05, -0.02, 0.03])
    goal = X @ R.T + t
    scale = np.linalg.norm(goal - X, axis=1).max()  # the largest displacement, 0.21
    errs = {}
    for w in (10.0, 1000.0):
        field, _ = _field(X, F, h, goal[h], steps=150, arap_weight=w)
        errs[w] = np.linalg.norm(_apply(field, X) - goal, axis=1) / scale
    # measured (150 steps): weight 10 mean 3.6%, max 16%; weight 1000 mean 1.4%, max 5.3%
    assert errs[10.0].mean() < 0.06 and errs[10.0].max() < 0.25, errs[10.0]
    assert errs[1000.0].mean() < 0.03 and errs[1000.0].max() < 0.10, errs[1000.0]
    assert errs[1000.0].mean() < errs[10.0].mean()


def test_patch_energy_zero_for_rigid_and_hand_computed():
    rng = np.random.default_rng(1)
    pts, tris = disk(10, 0.05, rng)
    Xp = mesh_patches(sphere_sdf(0.5), torch.tensor([[0.5, 0.0, 0.0], [0.0, 0.3, 0.0]]), pts, 3)
    assert torch.allclose(Xp.norm(dim=-1)[0], torch.tensor(0.5), atol=1e-5)  # on the centre's level set
    assert torch.allclose(Xp.norm(dim=-1)[1], torch.tensor(0.3), atol=1e-5)
    R = rodrigues(torch.tensor([[0.2, -0.4, 0.7]])).expand(2 * 10, 3, 3).reshape(2, 10, 3, 3)
    TX = (R @ Xp[..., None])[..., 0] + torch.tensor([0.3, 0.1, -0.2])
    for ref in (False, True):
        assert patch_energy(Xp, R, TX, tris, edge_structure(tris, ref)) < 1e-10
    # one right triangle, T = 2x, R = I: residual = -(x_i - x_j); angles 90, 45, 45 deg.
    X1 = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]], dtype=torch.float64)
    t1 = np.array([[0, 1, 2]])
    eye = torch.eye(3, dtype=torch.float64).expand(1, 3, 3, 3)
    # correct: w01 = w02 = cot(45)/2 = 1/2, w12 = cot(90)/2 = 0, both directions:
    # 2 * (1/2 * 1 + 1/2 * 1 + 0 * 2) = 2
    assert patch_energy(X1, eye, 2 * X1, t1, edge_structure(t1)).item() == pytest.approx(2.0)
    # reference: cot at v0 (0) -> (v0,v1), at v1 (1) -> (v1,v2), at v2 (1) -> (v0,v2),
    # symmetrised, over the edge list (0,1), (1,2), (0,2): 0 * 1 + 1 * 2 + 1 * 1 = 3
    assert patch_energy(X1, eye, 2 * X1, t1, edge_structure(t1, True)).item() == pytest.approx(3.0)


def test_reference_weights_overwrite_repeats():
    """Two triangles listing the same directed edge (0, 1): the later one's cotangent stays."""
    X = torch.tensor([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, -2, 0]]], dtype=torch.float64)
    tris = np.array([[0, 1, 2], [0, 1, 3]])
    from baselines.implicit_arap.patches import corner_cotangents, cot_weights
    e = edge_structure(tris, True)
    w = cot_weights(X, tris, e)
    cot = corner_cotangents(X, tris)[0]
    assert w[0, 0].item() == pytest.approx(cot[1, 0].item())  # edge (0, 1): triangle 1's angle at v0, not a sum
    correct = cot_weights(X, tris, edge_structure(tris))
    assert correct.shape == (1, 2 * 5)


def test_loss_decreases():
    X, F = _sphere_mesh()
    h = np.flatnonzero(np.abs(X[:, 2]) > 0.45)
    T = X[h].copy()
    T[X[h, 2] > 0, 2] += 0.1
    _, hist = _field(X, F, h, T, steps=80)
    assert np.mean(hist[-10:]) < 0.1 * np.mean(hist[:5])


def test_same_seed_same_output_and_info():
    X, F = _sphere_mesh()
    h = np.flatnonzero(np.abs(X[:, 2]) > 0.45)
    T = X[h].copy()
    T[X[h, 2] > 0] += [0.05, 0.0, 0.05]
    kw = {**SMALL, "sdf_steps": 20, "sdf_samples": 256, "deform_steps": 15, "device": "cpu"}
    a = ImplicitARAP(**kw).deform(X, F, h, T)
    m = ImplicitARAP(**kw)
    b = m.deform(X, F, h, T)
    c = ImplicitARAP(**kw, seed=1).deform(X, F, h, T)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.dtype == np.float64 and a.shape == X.shape
    i = m.info
    assert (i["preset"], i["sdf_steps"], i["deform_steps"], i["device"]) == ("cpu", 20, 15, "cpu")
    assert i["sdf_fit_s"] > 0 and i["deform_s"] > 0 and i["moving_handles"] + i["static_handles"] == len(h)


def test_units_round_trip_and_parameters_checked():
    """The result is in the input's units: a scaled, shifted input gives the scaled,
    shifted result; bad parameters are refused at construction."""
    X, F = _sphere_mesh()
    h = np.flatnonzero(X[:, 2] > 0.45)
    kw = {**SMALL, "sdf_steps": 5, "sdf_samples": 128, "deform_steps": 3, "device": "cpu"}
    a = ImplicitARAP(**kw).deform(X, F, h, X[h] + 0.01)
    b = ImplicitARAP(**kw).deform(100 * X + 7, F, h, 100 * (X[h] + 0.01) + 7)
    assert np.allclose(100 * a + 7, b, atol=1e-3)
    for bad, match in (({"preset": "gpu"}, "unknown preset"), ({"patch_points": 3}, "patch_points"),
                       ({"sdf_lr": 0}, "sdf_lr"), ({"skip": 5}, "skip"), ({"centres": "box"}, "centres"),
                       ({"device": "tpu"}, "device"), ({"lr_milestones": [5, 3]}, "lr_milestones"),
                       ({"lr_milestones": 7}, "lr_milestones"), ({"lr_gamma": 0}, "lr_gamma")):
        with pytest.raises(SShaDeError, match=match):
            ImplicitARAP(**bad)


def test_params_object_mapping_and_keywords_build_the_same_method_and_bits():
    """ImplicitARAP(params), ImplicitARAP(mapping) and ImplicitARAP(**keywords) hold equal
    parameters and give the same bits; an override over a params object replaces its field."""
    X, F = _sphere_mesh()
    h = np.flatnonzero(X[:, 2] > 0.45)
    kw = {**SMALL, "sdf_steps": 5, "sdf_samples": 128, "deform_steps": 3, "device": "cpu", "arap_weight": 50}
    p = ImplicitARAPParams(**kw)
    ms = [ImplicitARAP(p), ImplicitARAP(dict(kw)), ImplicitARAP(**kw),
          ImplicitARAP(p.replace(arap_weight=7), arap_weight=50)]
    assert all(m.params == p for m in ms) and ms[0].params is p
    outs = [m.deform(X, F, h, X[h] + 0.01) for m in ms]
    assert all(np.array_equal(outs[0], o) for o in outs[1:])
    m = ImplicitARAP(p, seed=4, name="IA-4")
    assert (m.params.seed, m.params.arap_weight, m.seed, m.name) == (4, 50.0, 4, "IA-4")
    assert (m.preset, m.device, m.reference_weights, m.torch_device()) == ("cpu", "cpu", False, "cpu")
    assert m.effective_params() == p.replace(seed=4).as_dict()
    with pytest.raises(SShaDeError, match="no parameter 'arap_wieght'"):
        ImplicitARAP(arap_wieght=1.0)


def test_the_rate_schedule_acts_only_from_its_first_milestone():
    """The reference's MultiStepLR: milestones past the last step leave every float as
    without a schedule (so the cpu_soft preset, 500 steps under milestones from 1000, is
    the earlier default's run), and a milestone inside the run changes the result."""
    X, F = _sphere_mesh()
    h = np.flatnonzero(np.abs(X[:, 2]) > 0.45)
    T = X[h].copy()
    T[X[h, 2] > 0, 2] += 0.1
    a, ha = _field(X, F, h, T, steps=20, lr_milestones=(20, 40))
    b, hb = _field(X, F, h, T, steps=20, lr_milestones=(1000,))
    c, hc = _field(X, F, h, T, steps=20, lr_milestones=(10,), lr_gamma=0.1)
    assert ha == hb and hc[:11] == ha[:11] and hc[11:] != ha[11:]
    assert np.array_equal(_apply(a, X), _apply(b, X))


def test_the_presets_stiffness_and_schedule():
    """cpu: ARAP weight 120 with correct weights (at least the reference's mesh default,
    10 with its own weights, which are at most about 12x stiffer on 16-point disks),
    cpu_soft: the earlier default (10, 500 steps); both share the reference's schedule."""
    from baselines.implicit_arap.params import PRESETS
    cpu, soft, paper = PRESETS["cpu"], PRESETS["cpu_soft"], PRESETS["paper"]
    assert cpu["arap_weight"] >= 10 * 12 and not cpu["reference_weights"] and cpu["deform_steps"] > 1000
    assert (soft["arap_weight"], soft["deform_steps"]) == (10.0, 500)
    assert cpu["lr_milestones"] == soft["lr_milestones"] == paper["lr_milestones"] == (1000, 2000, 5000)
    assert {k for k in cpu if cpu[k] != soft[k]} == {"arap_weight", "deform_steps"}


def test_field_starts_at_identity():
    f = DeformationField(layers=4, width=16, skip=2, octaves=6, generator=torch.Generator().manual_seed(0))
    x = torch.rand(50, 3) * 2 - 1
    R, t = f.rotation_translation(x)
    assert torch.equal(R, torch.eye(3).expand(50, 3, 3)) and torch.equal(t, torch.zeros(50, 3))
    assert torch.allclose(rodrigues(torch.tensor([[0.0, 0.0, np.pi / 2]]))[0] @ torch.tensor([1.0, 0, 0]),
                          torch.tensor([0.0, 1.0, 0.0]), atol=1e-6)


def test_registered_and_ordered():
    from harness.method_registry import builtin_methods, file_spec, table_order
    assert "Implicit-ARAP" in builtin_methods()
    assert table_order().index("Implicit-ARAP") == table_order().index("ARAP-SR") + 1
    spec = file_spec("Implicit-ARAP")
    assert spec["_target_"] == "baselines.implicit_arap.ImplicitARAP" and spec["preset"] == "cpu"


def test_patch_centres_both_samplers_on_the_zero_level_set():
    """The reference's rejection sampling (paper preset) and the cpu preset's mesh draw
    both give zero-level centres after the handles, then points of the box."""
    from baselines.implicit_arap.method import patch_centres
    from baselines.implicit_arap.sdf import SurfaceSampler
    X, F = _sphere_mesh()
    H = torch.as_tensor(X[:5], dtype=torch.float32)
    for centres in ("rejection", "mesh"):
        s = _settings(centres=centres, surface_patches=40, space_patches=7, handle_patches=0)
        C = patch_centres(sphere_sdf(0.5), H, s, SurfaceSampler(X, F), torch.Generator().manual_seed(0))
        assert C.shape == (47, 3) and torch.equal(C[:5], H)
        assert (C[5:40].norm(dim=1) - 0.5).abs().max() < 1e-5, centres
        assert C[40:].abs().max() <= 1.0

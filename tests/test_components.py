"""Meshes with several connected components: the components holding handles
are deformed, the others follow their nearest deformed component rigidly
(sshade/components.py), in the API, through any method and in the evaluator."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from scipy.spatial.distance import pdist

from baselines import Elastic
from eval.config_check import check_config
from sshade import deform
from sshade.arap import rigid_fit
from sshade.arap.problems import bent_cylinder
from sshade.components import ComponentWise, component_labels, deform_components, drop_unreferenced
from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh


def _body_and_sphere():
    """A capped cylinder bent by 90 degrees (2,504 vertices; bottom band fixed, top band
    moved) as the body, and a small separate sphere (162 vertices) beside its top, the
    head. Returns V, F, handles, targets, n_body."""
    V, F, h, t = bent_cylinder(90.0)
    s = trimesh.creation.icosphere(subdivisions=2, radius=0.15)
    S = np.asarray(s.vertices) + [0.75, 0.0, V[:, 2].max() - 0.3]
    return np.vstack([V, S]), np.vstack([F, np.asarray(s.faces) + len(V)]), h, t, len(V)


@pytest.fixture(scope="module")
def two():
    return _body_and_sphere()


def _check_rigid_follow(V, Vd, n_body):
    """The sphere keeps its shape exactly, moves with the deformed top and keeps its
    distance to the body."""
    S, Sd = V[n_body:], Vd[n_body:]
    assert np.abs(pdist(Sd) - pdist(S)).max() < 1e-9
    R, t = rigid_fit(S, Sd)
    assert np.abs(S @ R.T + t - Sd).max() < 1e-9 and np.linalg.det(R) > 0
    assert np.linalg.norm(Sd.mean(0) - S.mean(0)) > 0.5  # carried along by the bend
    gap0 = np.linalg.norm(V[:n_body] - S.mean(0), axis=1).min()
    gap1 = np.linalg.norm(Vd[:n_body] - Sd.mean(0), axis=1).min()
    assert abs(gap1 - gap0) < 0.1 * gap0  # still beside the head


def test_sshade_deforms_two_components(two):
    V, F, h, t, nb = two
    Vd, info = deform(V, F, h, t, n_low=300, n_samplings=2, seed=0, workers=1, return_info=True)
    assert info["n_components"] == 2 and info["n_deformed_components"] == 1 and info["n_rigid_components"] == 1
    assert info["components"][1] == {"n_vertices": len(V) - nb, "mode": "rigid", "follows": 0}
    np.testing.assert_allclose(Vd[h], t, atol=1e-12)
    _check_rigid_follow(V, Vd, nb)
    # the body is deformed exactly as it would be alone
    alone = deform(V[:nb], F[F.max(1) < nb], h, t, n_low=300, n_samplings=2, seed=0, workers=1)
    assert np.abs(Vd[:nb] - alone).max() < 1e-12


def test_any_method_through_deform_components(two):
    V, F, h, t, nb = two
    m = ComponentWise(Elastic(tol=1e-3))
    Vd = m.deform(V, F, h, t)
    assert m.name == "Elastic" and m.info["n_components"] == 2 and m.info["iterations"] > 0
    _check_rigid_follow(V, Vd, nb)
    with pytest.raises(SShaDeError, match="components"):  # the bare baseline stays single-component
        Elastic().deform(V, F, h, t)


def test_handles_on_both_components_and_a_far_free_one():
    """Two handled boxes and a free one near the second: each handled box is deformed on
    its own, the free box follows the nearer (second) box, not the first."""
    from sshade.arap.problems import box_surface
    B, FB = box_surface((1.0, 1.0, 1.0), 0.34)
    n = len(B)
    V = np.vstack([B, B + [3.0, 0, 0], B * 0.3 + [3.2, 2.0, 0.3]])
    F = np.vstack([FB, FB + n, FB[:, :] + 2 * n])
    lab = component_labels(F, len(V))[1]
    assert component_labels(F, len(V))[0] == 3
    h = np.r_[np.flatnonzero(lab == 0)[:4], np.flatnonzero(lab == 1)]
    t = V[h].copy()
    t[4:] = (V[h[4:]] - [3.5, 0.5, 0.5]) @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]]).T + [3.5, 0.5, 0.5]
    Vd, info = deform_components(Elastic(tol=1e-3), V, F, h, t, return_info=True)
    assert info["n_deformed_components"] == 2 and info["components"][2]["follows"] == 1
    np.testing.assert_allclose(Vd[lab == 0], V[lab == 0], atol=1e-9)  # 4 handles kept in place: rigid
    free = lab == 2  # the whole of box 1 turned by 90 degrees about z: the free box turns with it
    R, _ = rigid_fit(V[free], Vd[free])
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-6)


def test_single_component_is_passed_through_unchanged(two):
    V, F, h, t, nb = two
    Fb = F[F.max(1) < nb]
    a = Elastic(tol=1e-3)
    Vd, info = deform_components(a, V[:nb], Fb, h, t, return_info=True)
    b = Elastic(tol=1e-3)
    assert np.array_equal(Vd, b.deform(V[:nb], Fb, h, t)) and "n_components" not in info


def test_unreferenced_vertices_api_is_strict_with_a_fix(two):
    V, F, h, t, nb = two
    V2 = np.vstack([V, [9.0, 9, 9]])
    with pytest.raises(SShaDeError, match="unreferenced.*drop_unreferenced"):
        deform(V2, F, h, t, n_low=300, n_samplings=1)
    V3, F3, kept = drop_unreferenced(V2, F)
    assert np.array_equal(V3, V) and np.array_equal(F3, F) and np.array_equal(kept, np.arange(len(V)))
    V4, F4, kept4 = drop_unreferenced(np.vstack([[7.0, 7, 7], V]), F + 1)
    assert np.array_equal(V4, V) and np.array_equal(F4, F) and kept4[0] == 1


def test_other_bad_input_keeps_its_error(two):
    V, F, h, t, nb = two
    book = np.vstack([F, [F[0, 0], F[0, 1], nb]])  # a third face on an edge of the body
    with pytest.raises(SShaDeError, match="non-manifold edge"):
        deform_components(Elastic(), V, book, h, t)
    with pytest.raises(SShaDeError, match="out of range"):
        deform(V, F, [len(V)], np.zeros((1, 3)))
    validate_mesh(V, F, allow_components=True)
    with pytest.raises(SShaDeError, match="2 connected components"):
        validate_mesh(V, F)


def test_evaluator_deforms_a_case_with_two_components(tmp_path, two, monkeypatch):
    """A dataset case with a separate sphere: the evaluator wraps each method
    (ComponentWise), the row has no error and records n_components."""
    import pandas as pd
    from hydra import compose, initialize_config_dir

    import eval.datasets as ds
    from eval.app import CONF_DIR, run
    V, F, h, t, nb = two
    case = SimpleNamespace(name="bar_sphere", subject=0, pose=1, V=V, F=F, handles=h, targets=t,
                           static=np.zeros(len(h), bool), seed=0, V_gt=None)
    monkeypatch.setattr(ds, "load_cases", lambda *a, **k: [case])
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=["dataset=faust", f"dataset.root={tmp_path}", "methods=[Elastic]",
                                                       "arap.tol=1e-3", "reference.cases=none",
                                                       f"out_dir={tmp_path / 'out'}"])
    res = run(check_config(cfg))
    assert res["n_errors"] == 0
    row = pd.read_csv(tmp_path / "out" / "cases.csv", keep_default_na=False).iloc[0]
    assert row["error"] == "" and int(row["n_components"]) == 2 and int(row["n_rigid_components"]) == 1


def test_read_mesh_refuses_components_unless_allowed(tmp_path, two):
    from sshade.mesh.io import read_mesh, write_mesh
    V, F, _, _, n_body = two
    p = tmp_path / "two.ply"
    write_mesh(p, V, F)
    with pytest.raises(SShaDeError, match="component"):
        read_mesh(p)
    V2, F2 = read_mesh(p, allow_components=True)  # what the shapes loader uses
    assert V2.shape == V.shape and F2.shape == F.shape
    assert component_labels(F2, len(V2))[0] == 2

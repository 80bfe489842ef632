"""The metrics' per-mesh state (eval/metrics/meshes.py): kept rest and ground-truth
meshes give the numbers of the direct computation, bit for bit, and those of the code they
replaced (reimplemented here: np.unique over edge rows, igl.point_mesh_squared_distance,
hausdorff and chamfer each from their own two one-way distances)."""
from __future__ import annotations

import igl
import numpy as np
import pytest
import trimesh

from eval.experiments.cases.pair import run_pair
from eval.metrics import measures as M
from eval.metrics import meshes as MM
from sshade.errors import SShaDeError
from sshade.guard import handle_error
from sshade.mesh.io import read_mesh
from tests.conftest import data_file


def _sphere(sub: int = 3):
    m = trimesh.creation.icosphere(subdivisions=sub)
    return np.asarray(m.vertices, float), np.asarray(m.faces, np.int64)


def _bunny():
    return read_mesh(data_file("classic/bunny.off"))


def _deformed(V, seed: int = 0):
    """A smooth bend plus noise: every error non-zero, no symmetry that could hide an index slip."""
    rng = np.random.default_rng(seed)
    s = V.max() - V.min()
    U = V + 0.1 * s * np.sin(3 * V[:, [1, 2, 0]] / s) + rng.normal(scale=1e-3 * s, size=V.shape)
    return U * [1.1, 0.95, 1.0]


def _old_distances(P, V, F):
    return np.sqrt(np.maximum(np.asarray(igl.point_mesh_squared_distance(P, V, F)[0], np.float64), 0.0))


def _old_metrics(V, Vd, F, Vgt, handles, targets):
    """The bundles as computed without kept state (same formulas)."""
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=0)
    E = np.unique(np.sort(he, axis=1), axis=0)
    l0, l1 = (np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1) for X in (V, Vd))
    a0, a1 = M._angles(V, F), M._angles(Vd, F)
    d = np.abs(a0 - a1)
    out = {"volume_err_pct": 100.0 * abs(M._volume(V, F) - M._volume(Vd, F)) / abs(M._volume(V, F)),
           "area_err_pct": 100.0 * abs(M._face_areas(V, F).sum() - M._face_areas(Vd, F).sum())
           / abs(M._face_areas(V, F).sum()),
           "edge_err_pct": float(100.0 * np.mean(np.abs(l0 - l1)) / float(l0.max())),
           "angle_err_deg": float(np.degrees(d.mean())), "angle_err_rel_pct": float(100.0 * np.mean(d / a0)),
           "handle_err_pct": handle_error(Vd, handles, targets, M._diag(V))}
    c = 0.5 * (Vgt.min(axis=0) + Vgt.max(axis=0))
    s = float(np.linalg.norm(Vgt - c, axis=1).max())
    X, Y = (Vd - c) / s, (Vgt - c) / s
    dxy, dyx = _old_distances(X, Y, F), _old_distances(Y, X, F)
    g = np.linalg.norm(Vd - Vgt, axis=1)
    diag = M._diag(Vgt)
    out.update(gt_vertex_mean_pct=float(100.0 * g.mean() / diag), gt_vertex_max_pct=float(100.0 * g.max() / diag),
               hausdorff=float(max(dxy.max(), dyx.max())), chamfer=float(np.mean(dxy ** 2) + np.mean(dyx ** 2)))
    return out


@pytest.mark.parametrize("mesh", [_sphere, _bunny])
def test_unique_edges_is_numpys_row_unique(mesh):
    _, F = mesh()
    he = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], axis=0)
    E = MM.unique_edges(F, F.max() + 1)
    assert E.dtype == np.int64
    np.testing.assert_array_equal(E, np.unique(np.sort(he, axis=1), axis=0))


@pytest.mark.parametrize("mesh", [_sphere, _bunny])
def test_squared_distances_are_igls_bit_for_bit(mesh):
    V, F = mesh()
    P = _deformed(V, 1)
    want = np.asarray(igl.point_mesh_squared_distance(P, V, F)[0])
    np.testing.assert_array_equal(MM.squared_distances(P, V, F), want)
    tree = igl.AABB()
    tree.init(V, F)
    np.testing.assert_array_equal(MM.squared_distances(P, V, F, tree=tree, order=np.arange(len(P))), want)


@pytest.mark.parametrize("mesh", [_sphere, _bunny])
def test_kept_meshes_give_the_direct_and_the_old_numbers(mesh):
    V, F = mesh()
    Vgt = _deformed(V, 2)
    handles = np.arange(0, len(V), 37)
    targets = Vgt[handles]
    rest, target = MM.RestMesh(V, F), MM.TargetMesh(Vgt, F)
    old = None
    for seed in (3, 4):  # two results scored against the same kept meshes
        Vd = _deformed(V, seed)
        kept = {**M.deformation_metrics(V, Vd, F, handles, targets, rest=rest),
                **M.ground_truth_metrics(Vd, F, Vgt, target=target)}
        direct = {**M.deformation_metrics(V, Vd, F, handles, targets), **M.ground_truth_metrics(Vd, F, Vgt)}
        old = _old_metrics(V, Vd, F, Vgt, handles, targets)
        assert kept == direct == old  # exact float equality, key by key
        assert kept["hausdorff"] == M.hausdorff(Vd, F, Vgt, F) and kept["chamfer"] == M.chamfer(Vd, F, Vgt, F)
        assert all(v > 0 for v in kept.values())


def test_case_meshes_keep_a_mesh_while_it_is_asked_for():
    V, F = _sphere(2)
    cm = MM.CaseMeshes()
    r = cm.rest(V, F)
    assert cm.rest(V, F) is r and cm.rest(V.copy(), F.copy()) is r  # same arrays, or equal ones
    assert cm.rest(2 * V, F) is not r
    t = cm.target(V, F)
    assert cm.target(V, F) is t and cm.target(V + 1, F) is not t


def test_a_kept_mesh_of_another_mesh_is_refused():
    V, F = _sphere(2)
    with pytest.raises(SShaDeError, match="RestMesh of another mesh"):
        M.deformation_metrics(V, V, F, rest=MM.RestMesh(2 * V, F))
    with pytest.raises(SShaDeError, match="TargetMesh of another mesh"):
        M.ground_truth_metrics(V, F, V, target=MM.TargetMesh(2 * V, F))
    with pytest.raises(SShaDeError, match="all coincide"):
        MM.TargetMesh(np.zeros((4, 3)), [[0, 1, 2], [0, 2, 3]])


class _Shift:
    """A method that moves every vertex: a plug-in (any exception is its failure)."""
    name = "Shift"

    def deform(self, V, F, handles, targets):
        return _deformed(np.asarray(V), 5)


class _Case:
    def __init__(self, V, F, Vgt, name):
        self.name, self.subject, self.pose, self.V, self.F, self.V_gt = name, 0, 1, V, F, Vgt
        self.handles = np.array([0, 5, 9])
        self.targets = Vgt[self.handles]
        self.static = np.array([True, False, False])


class _NoRefs:
    def metrics(self, m, U):
        return {}


def test_evaluator_rows_with_kept_meshes_equal_rows_without():
    V, F = _sphere(3)
    cases = [_Case(V, F, _deformed(V, 6), "a"), _Case(V, F, _deformed(V, 7), "b")]  # one rest mesh, two poses
    guard = {"timeout_s": None, "handle_error_max_pct": None}
    meshes = MM.CaseMeshes()
    for case in cases:
        kept = run_pair(_Shift(), "Shift", case, _NoRefs(), guard, meshes)[0]
        direct = run_pair(_Shift(), "Shift", case, _NoRefs(), guard)[0]
        kept.pop("time_s"), direct.pop("time_s")
        assert kept == direct and "hausdorff" in kept and kept["error"] == ""
        assert meshes.rest(V, F).V is V or np.array_equal(meshes.rest(V, F).V, V)

"""Remesher guarantees on meshes above 100k vertices (LS3 Loop subdivisions of real
meshes): manifold, no duplicate/degenerate faces, same Euler characteristic and
boundary-loop count, low-res vertices a subset, every vertex projected into its own fan.
Marked slow (a few seconds each); CI runs them."""
from __future__ import annotations

import igl
import numpy as np
import pytest

from sshade.mesh.halfedge import boundary_loops, halfedges
from sshade.mesh.io import read_mesh
from sshade.mesh.validate import validate_mesh
from sshade.projection import project_to_fans
from sshade.remesh import mesh_topology, remesh

from .conftest import data_file

pytestmark = pytest.mark.slow


def _subdivide(V, F, times):
    import pymeshlab as ml
    ms = ml.MeshSet()
    ms.add_mesh(ml.Mesh(V, F))
    for _ in range(times):
        ms.meshing_surface_subdivision_ls3_loop(iterations=1, threshold=ml.PercentageValue(0))
    m = ms.current_mesh()
    return np.ascontiguousarray(m.vertex_matrix()), np.ascontiguousarray(m.face_matrix(), np.int64)


@pytest.mark.parametrize("rel,times,n_low", [("faust_reg/tr_reg_000.ply", 2, 6000),
                                             ("tosca/cat0.off", 2, 6000),
                                             ("classic/bunny.off", 3, 3000)],
                         ids=["faust-110k", "tosca-cat-446k-open", "bunny-223k"])
def test_remesh_guarantees_above_100k(rel, times, n_low):
    V, F = read_mesh(data_file(rel))
    V, F = _subdivide(V, F, times)
    assert len(V) > 100_000
    V, F, he = validate_mesh(V, F, return_halfedges=True)
    euler = len(V) - len(he.E) + len(F)
    loops = len(boundary_loops(F, he))
    rng = np.random.default_rng(0)
    req = rng.choice(len(V), 300, replace=False)
    rm = remesh(V, F, n_low, seed=0, required=req, topology=mesh_topology(V, F, he))
    VN, FN = V[rm.seeds], rm.F
    validate_mesh(VN, FN)  # manifold, oriented, single component, no duplicate/degenerate faces
    heN = halfedges(FN, len(VN))
    assert len(VN) - len(heN.E) + len(FN) == euler
    assert len(boundary_loops(FN, heN)) == loops
    assert np.isin(req, rm.seeds).all() and len(np.unique(rm.seeds)) == len(rm.seeds)
    assert np.array_equal(np.unique(FN), np.arange(len(VN)))
    P = project_to_fans(V, rm.label, VN, FN)
    assert (FN[P.tri] == rm.label[:, None]).any(axis=1).all()
    # fan projection agrees with the global nearest point wherever that point is in the fan
    d2, I, _ = igl.point_mesh_squared_distance(V, VN, FN)
    infan = (FN[I] == rm.label[:, None]).any(axis=1)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert np.abs(P.dist[infan] - np.sqrt(d2[infan])).max() < 1e-9 * diag

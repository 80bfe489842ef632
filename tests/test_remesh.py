"""Remesh guarantees (paper §3.1) and fan projection on real meshes."""
from __future__ import annotations

import igl
import numpy as np
import pytest

from sshade.mesh.io import read_mesh
from sshade.mesh.validate import validate_mesh
from sshade.projection import project_to_fans
from sshade.remesh import mesh_topology, remesh

from .conftest import data_file

CASES = [("classic/bunny.off", 300), ("classic/armadillo.obj", 2000), ("tosca/cat0.off", 1000),
         ("classic/dragon.obj", 800), ("faust_reg/tr_reg_000.ply", 1000)]


def _euler_loops(F, n):
    E = igl.edges(F)
    return n - len(E) + len(F), len(igl.boundary_loop_all(F))


@pytest.fixture(scope="module", params=CASES, ids=[c[0].split("/")[-1] for c in CASES])
def remeshed(request):
    rel, k = request.param
    V, F = read_mesh(data_file(rel))
    rng = np.random.default_rng(7)
    req = rng.choice(len(V), 40, replace=False)
    rm = remesh(V, F, k, seed=3, required=req)
    return V, F, rm, req


def test_remesh_is_valid_manifold_with_same_topology(remeshed):
    V, F, rm, req = remeshed
    VN, FN = V[rm.seeds], rm.F
    validate_mesh(VN, FN)  # manifold, oriented, one component, no duplicate/degenerate faces
    assert np.array_equal(np.unique(FN), np.arange(len(rm.seeds)))  # every seed used
    assert _euler_loops(FN, len(VN)) == _euler_loops(F, len(V))


def test_low_res_vertices_are_a_subset_and_include_required(remeshed):
    V, F, rm, req = remeshed
    assert len(np.unique(rm.seeds)) == len(rm.seeds)
    assert (rm.seeds >= 0).all() and (rm.seeds < len(V)).all()
    assert np.isin(req, rm.seeds).all()
    assert np.array_equal(rm.label[rm.seeds], np.arange(len(rm.seeds)))  # seed i labels region i


def test_projection_into_own_fan_and_close_to_brute_force(remeshed):
    V, F, rm, _ = remeshed
    VN, FN = V[rm.seeds], rm.F
    P = project_to_fans(V, rm.label, VN, FN)
    # the triangle of every vertex is incident to the vertex's own seed
    assert (FN[P.tri] == rm.label[:, None]).any(axis=1).all()
    assert np.allclose(P.bary.sum(1), 1) and (P.bary >= -1e-12).all()
    Q = np.einsum("ni,nij->nj", P.bary, VN[FN[P.tri]])
    assert np.allclose(np.linalg.norm(Q - V, axis=1), P.dist)
    # where the brute-force nearest triangle is in the vertex's fan, distances agree
    d2, I, _ = igl.point_mesh_squared_distance(V, VN, FN)
    infan = (FN[I] == rm.label[:, None]).any(axis=1)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    assert infan.mean() > 0.7
    assert np.abs(P.dist[infan] - np.sqrt(d2[infan])).max() < 1e-9 * diag
    # and nowhere is the fan projection closer than the global nearest point
    assert (P.dist >= np.sqrt(d2) - 1e-9 * diag).all()


def test_different_seeds_give_different_samplings():
    V, F = read_mesh(data_file("classic/bunny.off"))
    topo = mesh_topology(V, F)
    a = remesh(V, F, 300, seed=0, topology=topo)
    b = remesh(V, F, 300, seed=1, topology=topo)
    c = remesh(V, F, 300, seed=0, topology=topo)
    assert np.array_equal(a.seeds, c.seeds)  # deterministic
    assert len(np.intersect1d(a.seeds, b.seeds)) < 0.5 * len(a.seeds)


def test_repairs_a_coarse_sampling():
    """At very low n_low the raw Voronoi decomposition of the armadillo breaks the
    closed-ball property; the repair adds seeds until the remesh is valid."""
    V, F = read_mesh(data_file("classic/armadillo.obj"))
    rm = remesh(V, F, 40, seed=0)
    assert rm.n_repair > 0
    validate_mesh(V[rm.seeds], rm.F)
    assert _euler_loops(rm.F, len(rm.seeds)) == (2, 0)

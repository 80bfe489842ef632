"""The eight-region edit of benchmarks/frames.py (``--regions 8``): eight disjoint regions,
the four at even places left at rest to the bit, each of the four others moved rigidly
(its own distances kept) with its centroid moved the stated fraction of the diagonal
along the third principal axis, and the same handles and targets from the same seed."""
from __future__ import annotations

import importlib.util

import numpy as np
from scipy.spatial.distance import pdist

from eval.datasets.shapes import principal_axes
from sshade.arap.problems import capped_cylinder

from .conftest import ROOT

_spec = importlib.util.spec_from_file_location("frames_benchmark", ROOT / "benchmarks" / "frames.py")
frames = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(frames)


def test_eight_regions_disjoint_static_and_rigid_moves():
    V, _ = capped_cylinder(h=0.05)
    h, T = frames.eight_regions(V, V, translate=0.05, rotate_deg=20.0)
    assert h.dtype == np.int64 and T.shape == (len(h), 3)
    assert len(h) == 8 * 30 and len(np.unique(h)) == len(h)
    _, (_, _, a3) = principal_axes(V)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    for g, idx in enumerate(np.arange(len(h)).reshape(8, 30)):  # 30 each, in place order
        P, Q = V[h[idx]], T[idx]
        if g % 2 == 0:
            assert np.array_equal(P, Q)
            continue
        np.testing.assert_allclose(pdist(Q), pdist(P), atol=1e-12)
        shift = (Q.mean(0) - P.mean(0)) @ a3
        assert abs(abs(shift) - 0.05 * diag) < 1e-9 * diag
        assert not np.allclose(Q - Q.mean(0), P - P.mean(0))  # turned, not only moved


def test_eight_regions_same_seed_same_edit():
    V, _ = capped_cylinder(h=0.05)
    h1, T1 = frames.eight_regions(V, V, seed=3)
    h2, T2 = frames.eight_regions(V, V, seed=3)
    h3, _ = frames.eight_regions(V, V, seed=4)
    assert np.array_equal(h1, h2) and np.array_equal(T1, T2)
    assert not np.array_equal(h1, h3)

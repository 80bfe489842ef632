"""sshade/mesh/bounds.py: the bounding box per coordinate column equals NumPy's axis-0
reduction bit for bit, NaN included, for any dtype and width."""
from __future__ import annotations

import numpy as np
import pytest

from sshade.mesh.bounds import bbox_diagonal, bounding_box


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64])
def test_the_corners_equal_numpys_axis_0_min_and_max_exactly(dtype):
    P = (np.random.default_rng(0).normal(size=(1001, 3)) * 1e3).astype(dtype)
    lo, hi = bounding_box(P)
    assert lo.dtype == P.dtype and np.array_equal(lo, P.min(axis=0)) and np.array_equal(hi, P.max(axis=0))
    assert bbox_diagonal(P) == float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))


def test_nan_propagates_per_column_as_numpy_does():
    P = np.array([[0.0, 1.0], [np.nan, 2.0], [3.0, -1.0]])
    lo, hi = bounding_box(P)
    assert np.isnan(lo[0]) and np.isnan(hi[0]) and (lo[1], hi[1]) == (-1.0, 2.0)
    assert np.isnan(bbox_diagonal(P))


@pytest.mark.parametrize("P", [np.zeros((0, 3)), np.zeros(3)])
def test_no_point_or_a_flat_array_is_refused(P):
    with pytest.raises(ValueError, match="bounding_box"):
        bounding_box(P)

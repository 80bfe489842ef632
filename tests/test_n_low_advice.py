"""The advice of SShaDe's LowResSkippedWarning (sshade/pipeline.py): an n_low it names is
one check_params accepts and one below the mesh's vertex count; on a mesh too small for
any, it says so instead of asking for a smaller value."""
from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from sshade import deform
from sshade.errors import SShaDeError
from sshade.pipeline import LowResSkippedWarning, check_params

TETRAHEDRON = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float),
               np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
OCTAHEDRON = (np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float),
              np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]))


def _advice(V, F, n_low) -> str:
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        deform(V, F, [0, 1], V[[0, 1]] + 0.05, n_low=n_low, n_samplings=1, workers=1)
    (w,) = [x for x in seen if issubclass(x.category, LowResSkippedWarning)]
    return str(w.message)


def _valid(n_low: int, n: int) -> bool:
    try:
        check_params(n_low=n_low)
    except SShaDeError:
        return False
    return n_low < n


@pytest.mark.parametrize("n_low", ["auto", 4])
def test_a_tetrahedron_is_advised_no_n_low_below_the_minimum(n_low):
    text = _advice(*TETRAHEDRON, n_low)
    assert "smaller n_low" not in text
    assert "no n_low" in text and "at least 4" in text  # none exists: 4 is the minimum, the mesh has 4 vertices


def test_a_small_mesh_is_advised_only_valid_n_low():
    V, F = OCTAHEDRON
    text = _advice(V, F, "auto")
    m = re.search(r"pass n_low between (\d+) and (\d+)", text)
    assert m, text
    lo, hi = int(m.group(1)), int(m.group(2))
    assert _valid(lo, len(V)) and _valid(hi, len(V)) and not _valid(lo - 1, len(V)) and not _valid(hi + 1, len(V))

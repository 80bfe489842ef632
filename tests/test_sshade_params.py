"""SShaDe's parameters are checked before any work; an n_low at or above the vertex
count (no low-resolution step) warns and is recorded."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from sshade import SShaDe, SShaDeError, deform
from sshade.pipeline import LowResSkippedWarning, check_params


@pytest.mark.parametrize("kw, message", [
    ({"n_low": 2}, "n_low must be at least 4"),
    ({"n_low": 3.5}, "n_low must be an integer"),
    ({"n_low": "many"}, "n_low must be an integer"),
    ({"n_samplings": 0}, "n_samplings must be at least 1"),
    ({"workers": 0}, "workers must be at least 1"),
    ({"seed": -1}, "seed must be at least 0"),
    ({"tol": 0}, "tol must be a finite number > 0"),
    ({"tol": float("nan")}, "tol must be a finite number > 0"),
    ({"max_iter": 0}, "max_iter must be at least 1"),
    ({"gradient": "curl"}, "unknown gradient mode"),
])
def test_bad_parameter_is_refused_when_the_method_is_built(kw, message):
    with pytest.raises(SShaDeError, match=message):
        check_params(**kw)
    with pytest.raises(SShaDeError, match=message):
        SShaDe(**kw)  # before any mesh is seen


def test_good_parameters_are_normalised():
    p = check_params(n_low="6000", n_samplings=5.0, workers=None, tol="1e-4")
    assert p["n_low"] == 6000 and p["n_samplings"] == 5 and p["tol"] == 1e-4 and p["workers"] is None
    assert check_params(n_low=None)["n_low"] == "auto" and check_params(n_low="auto")["n_low"] == "auto"


def test_n_low_at_vertex_count_warns_and_is_recorded():
    m = trimesh.creation.icosphere(subdivisions=2)  # 162 vertices
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    handles = np.array([0, 1, 2, 100])
    targets = V[handles] + [0, 0, 0.05]
    with pytest.warns(LowResSkippedWarning, match="not below the mesh's 162 vertices"):
        Vd, info = deform(V, F, handles, targets, n_low=500, n_samplings=1, workers=1, return_info=True)
    assert info["low_res_skipped"] is True and info["n_low_requested"] == 500 and info["n_low"] == 162
    np.testing.assert_allclose(Vd[handles], targets, atol=1e-12)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error", LowResSkippedWarning)  # below the count: no warning
        _, info = deform(V, F, handles, targets, n_low=60, n_samplings=1, workers=1, return_info=True)
    assert info["low_res_skipped"] is False

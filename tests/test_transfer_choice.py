"""SShaDe's transfer and average switches (``transfer``, ``average``) through deform,
prepare/solve and the correspondence transfer: the first prepared solve is deform bit for
bit with each; a rigid motion is reproduced exactly; with exact low-res positions the
proximity average reproduces every sampled vertex exactly and lowers the error; a bad
value is refused before any work."""
from __future__ import annotations

import numpy as np
import pytest

from sshade import deform, prepare
from sshade.arap.problems import twisted_bar
from sshade.errors import SShaDeError
from sshade.isometric import isometric_transfer
from sshade.params import check_params
from tests.test_lrf import _rotation

from .test_prepared import faust_pair  # noqa: F401 (fixture)

COMBOS = [("vertex", "uniform"), ("triangle", "uniform"), ("vertex", "proximity"), ("triangle", "distortion")]


@pytest.mark.parametrize("transfer,average", COMBOS)
def test_the_first_prepared_solve_is_deform_bit_for_bit(faust_pair, transfer, average):  # noqa: F811
    V, F, h, V2 = faust_pair
    kw = dict(n_low=400, n_samplings=3, seed=3, transfer=transfer, average=average)
    with prepare(V, F, h, **kw) as prepared:
        Vd = prepared.solve(V2[h])
    assert np.array_equal(Vd, deform(V, F, h, V2[h], workers=1, **kw))


@pytest.mark.parametrize("transfer,average", COMBOS)
def test_a_rigid_motion_of_the_handles_is_reproduced_exactly(transfer, average):
    V, F, h, _ = twisted_bar(0.0, h=0.25)
    R, t = _rotation(np.random.default_rng(0)), np.array([0.3, -1.0, 2.0])
    Vd = deform(V, F, h, V[h] @ R.T + t, n_low=60, n_samplings=3, workers=1, transfer=transfer, average=average)
    np.testing.assert_allclose(Vd, V @ R.T + t, atol=1e-9 * np.ptp(V, axis=0).max())


def test_with_exact_low_res_positions_the_proximity_average_keeps_every_sampled_vertex():
    V, F, _, _ = twisted_bar(0.0, h=0.25)
    V1 = V + 0.2 * np.sin(1.5 * V[:, [1, 2, 0]])  # a smooth non-rigid pose, 1:1 with V
    kw = dict(n_low=60, n_samplings=4, workers=1)
    err = {}
    for average in ("uniform", "proximity"):
        Vp, _ = isometric_transfer(V, F, V1, average=average, **kw)
        err[average] = np.linalg.norm(Vp - V1, axis=1)
    scale = np.ptp(V1, axis=0).max()
    assert (err["proximity"] < 1e-9 * scale).sum() >= 60     # at least one sampling's low-res vertices, exact
    assert (err["uniform"] < 1e-9 * scale).sum() < 60
    assert err["proximity"].mean() < err["uniform"].mean()


@pytest.mark.parametrize("key,value", [("transfer", "quadratic"), ("average", "median"), ("transfer", 1)])
def test_an_unknown_transfer_or_average_is_refused_naming_it(key, value):
    with pytest.raises(SShaDeError, match=f"unknown {key}"):
        check_params(**{key: value})

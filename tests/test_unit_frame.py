"""sshade.mesh.unit_frame: the frame every solve runs in (centred, power-of-two scale)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from sshade.mesh.unit_frame import unit_frame


def _points(seed=0, n=50):
    return np.random.default_rng(seed).normal(size=(n, 3)) * [3.0, 1.0, 0.5] + [10.0, -4.0, 2.0]


def test_centre_is_the_box_midpoint_and_scale_a_power_of_two_above_the_diagonal():
    V = _points()
    fr = unit_frame(V)
    np.testing.assert_array_equal(fr.centre, 0.5 * V.min(0) + 0.5 * V.max(0))
    diag = np.linalg.norm(V.max(0) - V.min(0))
    m, _ = math.frexp(fr.scale)
    assert m == 0.5 and diag < fr.scale <= 2 * diag
    U = fr.to_unit(V)
    np.testing.assert_allclose(0.5 * U.min(0) + 0.5 * U.max(0), 0.0, atol=1e-15)
    assert 0.5 <= np.linalg.norm(U.max(0) - U.min(0)) < 1.0


def test_from_unit_undoes_to_unit_to_rounding_and_writes_into_out():
    V = _points(1)
    fr = unit_frame(V)
    U = fr.to_unit(V)
    back = fr.from_unit(U.copy())
    np.testing.assert_allclose(back, V, rtol=0, atol=4 * np.spacing(np.abs(V).max()))
    out = U.copy()
    assert fr.from_unit(out, out=out) is out


def test_a_power_of_two_scaling_gives_the_same_unit_positions_bit_for_bit():
    V = _points(2)
    for k in (2.0 ** -30, 2.0 ** 20):
        np.testing.assert_array_equal(unit_frame(V * k).to_unit(V * k), unit_frame(V).to_unit(V))


def test_energy_is_scaled_by_the_square_of_the_scale():
    fr = unit_frame(_points() * 8.0)
    assert fr.energy(3.0) == 3.0 * fr.scale ** 2 and fr.energy(None) is None
    assert set(fr.as_dict()) == {"centre", "scale"} and len(fr.as_dict()["centre"]) == 3


@pytest.mark.parametrize("V", [np.zeros((0, 3)), np.ones((4, 3)), np.zeros((3, 2)),
                               np.array([[0.0, 0, 0], [np.inf, 0, 0]])])
def test_an_empty_flat_point_or_infinite_box_is_refused(V):
    with pytest.raises(ValueError, match="unit_frame"):
        unit_frame(V)

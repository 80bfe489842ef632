"""defaust/resolutions.py: the names of a build's resolutions, checked, and read from its
manifest; a default build's item keys hold nothing of them."""
from __future__ import annotations

import pytest

from defaust.resolutions import build_resolutions, check_resolution, extra_counts, resolution_key
from sshade.errors import SShaDeError


@pytest.mark.parametrize("name", ["high", "low", "r7000", "r1"])
def test_a_resolution_name_is_high_low_or_rN(name):
    assert check_resolution(name) == name


@pytest.mark.parametrize("bad", ["mid", "r0", "r-1", "r07", "R7000", "r7000 ", 7000, None])
def test_any_other_name_is_refused_naming_the_parameter(bad):
    with pytest.raises(SShaDeError, match="resolution must be"):
        check_resolution(bad)


def test_a_manifest_says_which_resolutions_it_has():
    assert build_resolutions({"parameters": {}}) == ["low", "high"]  # a build made before resolutions
    assert build_resolutions({"parameters": {"resolutions": ["high", 20000, 7000]}}) == ["low", "high", "r20000",
                                                                                         "r7000"]
    assert build_resolutions({"parameters": {"resolutions": [7000, "junk", True]}}) == ["low", "r7000"]
    assert build_resolutions({}) == ["low", "high"]


def test_the_default_resolutions_leave_the_item_keys_as_they_were():
    assert resolution_key(("high",)) == {} and resolution_key(["high", 7000]) == {"resolutions": ["high", 7000]}
    assert extra_counts(["high", 20000, "7000"]) == [20000, 7000]

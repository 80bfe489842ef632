"""A mesh image's look as one checked, frozen record (eval/present/render_style.py): its
defaults are render_mesh's, the figures' own styles differ from them only where their
panels do, and a bad field is refused when the style is made, naming the field."""
from __future__ import annotations

import dataclasses

import pytest

from eval.present.figures import POSE_TRANSFER_STYLE, ROW_STYLE, TOSCA_STYLE, TOSCA_VIEW
from eval.present.render_style import DEFAULT_VIEW, ERROR_CMAP, RenderStyle
from sshade.errors import SShaDeError


def test_defaults_and_the_figures_styles():
    st = RenderStyle()
    assert (st.view, st.up, st.size, st.cmap, st.point_size, st.hide_occluded_points, st.ambient, st.fill,
            st.background) == (DEFAULT_VIEW, "y", (480, 640), "hot", None, True, 0.35, 0.94, "white")
    assert ROW_STYLE == RenderStyle(size=(320, 480), cmap=ERROR_CMAP)
    assert POSE_TRANSFER_STYLE == dataclasses.replace(ROW_STYLE, size=(240, 400))
    assert TOSCA_STYLE == dataclasses.replace(ROW_STYLE, view=TOSCA_VIEW, up="z", size=(320, 400))


def test_values_are_normalised_and_the_record_is_frozen():
    st = RenderStyle(view=(20, -60), size=[240, 320], point_size=40, ambient=1, fill=1)
    assert st.view == (20.0, -60.0) and st.size == (240, 320) and st.point_size == 40.0
    assert isinstance(st.ambient, float) and st.fill == 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.view = (0.0, 0.0)


def test_colormaps_by_name_or_object():
    pytest.importorskip("matplotlib")
    import matplotlib
    assert RenderStyle(cmap=ERROR_CMAP).colormap().name == ERROR_CMAP  # registered on first use
    assert RenderStyle(cmap="viridis").colormap().name == "viridis"
    cm = matplotlib.colormaps["magma"]
    assert RenderStyle(cmap=cm).colormap() is cm
    assert RenderStyle(background=(0.9, 0.9, 0.9)).background == (0.9, 0.9, 0.9)


@pytest.mark.parametrize("field, value", [
    ("view", (10.0,)), ("view", ("a", 0.0)), ("view", (float("nan"), 0.0)), ("up", "x"), ("size", (4, 4)),
    ("size", (100.5, 200)), ("size", 100), ("cmap", "no_such_colormap"), ("cmap", 3), ("point_size", 0),
    ("point_size", -1.0), ("hide_occluded_points", 1), ("ambient", 1.5), ("ambient", True), ("fill", 0.0),
    ("fill", 1.2), ("background", "no_such_colour"),
])
def test_a_bad_field_is_refused_by_name(field, value):
    with pytest.raises(SShaDeError, match=rf"^RenderStyle: {field}"):
        RenderStyle(**{field: value})

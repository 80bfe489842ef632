"""How a mesh image looks, in one checked, frozen record (:class:`RenderStyle`), as
matplotlib's rcParams hold a figure's look: camera, image size, colormap, markers,
shading, background. :func:`eval.present.render.render_mesh` takes one, and so do the
figures of :mod:`eval.present.figures` for each of their panels; the data drawn (meshes,
values, points, colour range, titles) stay those functions' parameters.
Floor 2 of eval/ (eval/present/, tests/test_layering.py); notes: docs/implementation.md.

Example::

    img = render_mesh(V, F, colors=err, style=RenderStyle(view=(20.0, -60.0), size=(240, 320), cmap="viridis"))
    case_figure(V, F, results, handles, static, "case.png", style=dataclasses.replace(ROW_STYLE, view=(0, -90)))
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import TYPE_CHECKING

from sshade.errors import SShaDeError

if TYPE_CHECKING:
    from matplotlib.colors import Colormap

__all__ = ["RenderStyle", "DEFAULT_VIEW", "ERROR_CMAP", "UPS"]

#: Default camera (elevation, azimuth) in degrees: slightly from above, turned a little to
#: the side of a y-up mesh's front.
DEFAULT_VIEW = (10.0, -75.0)
#: The data's up axis a render takes: ``"y"`` (+y up, +z towards the default viewer) or ``"z"``.
UPS = ("y", "z")
#: Error colours: matplotlib's "hot", reversed (low error light, high error dark red to
#: black) and cut before pure white so the shading of error-free regions stays readable;
#: registered with matplotlib under this name when a style first draws with it.
ERROR_CMAP = "sshade_hot"
_DEFAULT_CMAP = "hot"
_DEFAULT_BACKGROUND = "white"


def _error_colormap():
    """The :data:`ERROR_CMAP` colormap (registered with matplotlib on first use)."""
    import matplotlib
    import numpy as np
    from matplotlib.colors import ListedColormap
    if ERROR_CMAP not in matplotlib.colormaps:
        cm = matplotlib.colormaps["hot_r"]
        matplotlib.colormaps.register(ListedColormap(cm(np.linspace(0.12, 1.0, 256)), name=ERROR_CMAP))
    return matplotlib.colormaps[ERROR_CMAP]


def _number(name: str, x, lo: float, hi: float, *, lo_open: bool = False) -> float:
    ok = isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x)
    if not ok or x < lo or x > hi or (lo_open and x == lo):
        where = f"{'(' if lo_open else '['}{lo:g}, {hi:g}]"
        raise SShaDeError(f"RenderStyle: {name} must be a number in {where}, got {x!r}")
    return float(x)


@dataclass(frozen=True)
class RenderStyle:
    """How :func:`eval.present.render.render_mesh` draws a mesh, checked when made
    (SShaDeError naming the field and value). The defaults are render_mesh's; the figures
    of :mod:`eval.present.figures` have their own (:data:`eval.present.figures.ROW_STYLE`,
    ...), which :func:`dataclasses.replace` changes a field of.

    view : (float, float), default :data:`DEFAULT_VIEW`: the camera's (elevation,
        azimuth) in degrees, an orthographic view.
    up : str, default ``"y"``, one of :data:`UPS`: the data's axis drawn upwards.
    size : (int, int), default ``(480, 640)``: (width, height) in pixels of one mesh
        image (render_mesh's image, a figure's panel), each at least 16.
    cmap : str or matplotlib Colormap, default ``"hot"``: the colormap of scalar values
        (a name matplotlib knows, or :data:`ERROR_CMAP`).
    point_size : float > 0 or None, default None: marker area in pt^2 (None: scales with
        the image).
    hide_occluded_points : bool, default True: leave out the markers the surface hides.
    ambient : float in [0, 1], default 0.35: the share of light that does not depend on
        the surface's orientation.
    fill : float in (0, 1], default 0.94: the fraction of the free frame (image minus
        title band and colour bar) that the mesh's projection fills along its tighter
        direction; the mesh is centred in it.
    background : str or RGB(A) tuple, default ``"white"``: a matplotlib colour behind the mesh.

    Raises
    ------
    SShaDeError on a field of the wrong type or out of range.

    Examples
    --------
    >>> RenderStyle(view=(20, -60), size=(240, 320)).view
    (20.0, -60.0)
    """

    view: tuple[float, float] = DEFAULT_VIEW
    up: str = "y"
    size: tuple[int, int] = (480, 640)
    cmap: str | Colormap = _DEFAULT_CMAP
    point_size: float | None = None
    hide_occluded_points: bool = True
    ambient: float = 0.35
    fill: float = 0.94
    background: str | tuple[float, ...] = _DEFAULT_BACKGROUND

    def __post_init__(self):
        checked = {"view": _pair("view", self.view, lambda n, x: _number(n, x, -math.inf, math.inf)),
                   "size": _pair("size", self.size, _pixels),
                   "ambient": _number("ambient", self.ambient, 0.0, 1.0),
                   "fill": _number("fill", self.fill, 0.0, 1.0, lo_open=True)}
        if self.point_size is not None:
            checked["point_size"] = _number("point_size", self.point_size, 0.0, math.inf, lo_open=True)
        if self.up not in UPS:
            raise SShaDeError(f"RenderStyle: up must be one of {UPS}, got {self.up!r}")
        if not isinstance(self.hide_occluded_points, bool):
            raise SShaDeError(f"RenderStyle: hide_occluded_points must be True or False, got "
                              f"{self.hide_occluded_points!r}")
        _check_cmap(self.cmap)
        _check_colour(self.background)
        for name, value in checked.items():  # frozen: the checked values replace the given ones
            object.__setattr__(self, name, value)

    def colormap(self) -> Colormap:
        """:attr:`cmap` as a matplotlib Colormap (:data:`ERROR_CMAP` registered first)."""
        if not isinstance(self.cmap, str):
            return self.cmap
        if self.cmap == ERROR_CMAP:
            return _error_colormap()
        import matplotlib
        return matplotlib.colormaps[self.cmap]


def _pair(name: str, value, check) -> tuple:
    try:
        a, b = value
    except (TypeError, ValueError):
        raise SShaDeError(f"RenderStyle: {name} must be a pair, got {value!r}") from None
    return check(f"{name}[0]", a), check(f"{name}[1]", b)


def _pixels(name: str, x) -> int:
    if not isinstance(x, numbers.Integral) or isinstance(x, bool) or x < 16:
        raise SShaDeError(f"RenderStyle: size must be (width, height) in pixels, each an integer >= 16; "
                          f"{name} is {x!r}")
    return int(x)


def _check_cmap(cmap) -> None:
    """A colormap name matplotlib knows (or :data:`ERROR_CMAP`), or a Colormap; the
    defaults are taken as they are, so that making a style imports matplotlib only to
    check another one."""
    if isinstance(cmap, str) and cmap in (_DEFAULT_CMAP, ERROR_CMAP):
        return
    import matplotlib
    from matplotlib.colors import Colormap
    if isinstance(cmap, str) and cmap in matplotlib.colormaps or isinstance(cmap, Colormap):
        return
    raise SShaDeError(f"RenderStyle: cmap must be a matplotlib colormap or its name, got {cmap!r}")


def _check_colour(colour) -> None:
    if isinstance(colour, str) and colour == _DEFAULT_BACKGROUND:
        return
    from matplotlib.colors import is_color_like
    if not is_color_like(colour):
        raise SShaDeError(f"RenderStyle: background must be a matplotlib colour, got {colour!r}")

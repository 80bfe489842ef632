"""High-resolution ground truth of a source whose targets are registrations of its rest
mesh (one face array, vertex-to-vertex correspondence: the FAUST source). The high-res rest
mesh (:func:`defaust.highres.subdivide_remesh`) lies on the LS3 Loop subdivision of the
low-res rest; the target registration subdivided the same way has the same topology. Each
high-res vertex is its closest point on the subdivided rest (:class:`SurfaceMap`: triangle,
barycentric coordinates, and the vertex's rounding-sized offset from that point), read on
the subdivided target (:func:`map_target`). Definition, what it is exact for, measured
sizes: docs/defaust.md §2, "Ground truth of a FAUST build at high resolution". Pure
functions over arrays; no file I/O; the sums in a fixed order (:mod:`defaust.fixed_order`:
the same bytes on every machine).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sshade.errors import SShaDeError

from . import fixed_order as fo
from .highres import ls3_loop
from .skinning import closest_barycentric

__all__ = ["SurfaceMap", "surface_map", "map_target", "volume_area", "change_pct"]


@dataclass(frozen=True)
class SurfaceMap:
    """The vertices of a high-res rest mesh as points of the subdivided low-res rest.

    Attributes
    ----------
    iterations : int, LS3 Loop iterations (the build's ``ls3_iterations``).
    F_sub : (M, 3) int64 faces of ``ls3_loop(V0, F0, iterations)``.
    n_sub : int, its vertex count.
    face : (p,) int64, each high-res vertex's closest triangle of ``F_sub``.
    bary : (p, 3) float64, the closest point's barycentric coordinates (rows sum to 1).
    offset : (p, 3) float64 metres, the vertex minus that point (rounding-sized for a
        remesh that reprojects onto the surface, as :func:`defaust.highres.subdivide_remesh`).
    """

    iterations: int
    F_sub: np.ndarray
    n_sub: int
    face: np.ndarray
    bary: np.ndarray
    offset: np.ndarray

    @property
    def offset_max(self) -> float:
        """The largest offset's length (metres)."""
        return float(fo.norm3(self.offset).max()) if len(self.offset) else 0.0


def _at(V: np.ndarray, F: np.ndarray, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """The (p, 3) points with barycentric coordinates ``bary`` (p, 3) in triangles ``F[face]`` of ``V``
    (``(b0 v0 + b1 v1) + b2 v2``)."""
    T = V[F[face]]
    return (bary[:, 0:1] * T[:, 0] + bary[:, 1:2] * T[:, 1]) + bary[:, 2:3] * T[:, 2]


def surface_map(V0, F0, Vh, iterations: int) -> SurfaceMap:
    """Locate the high-res rest vertices on the LS3 Loop subdivision of the low-res rest.

    Parameters
    ----------
    V0 : (n, 3) float64 low-res rest vertices (metres); F0 : (m, 3) int64 its faces.
    Vh : (p, 3) float64 vertices of :func:`defaust.highres.subdivide_remesh` of ``(V0, F0)``.
    iterations : int >= 1, its LS3 iterations (``HighResResult.iterations``).

    Returns
    -------
    SurfaceMap (closest points by :func:`defaust.skinning.closest_barycentric`; the
    barycentric rows renormalised to sum to 1, so the map is affine-exact).

    Raises
    ------
    SShaDeError if ``iterations < 1``.

    Examples
    --------
    Example::

        m = surface_map(V0, F0, Vh, 2)
        np.allclose(map_target(m, V0, F0), Vh, atol=1e-12)
        # -> True
    """
    iterations = int(iterations)
    if iterations < 1:
        raise SShaDeError(f"subdivision iterations must be >= 1, got {iterations}")
    Vh = np.asarray(Vh, np.float64)
    Vs, Fs = ls3_loop(V0, F0, iterations)
    face, bary = closest_barycentric(Vs, Fs, Vh)
    bary = bary / ((bary[:, 0] + bary[:, 1]) + bary[:, 2])[:, None]  # clipped coordinates: sum back to 1
    return SurfaceMap(iterations=iterations, F_sub=Fs, n_sub=int(len(Vs)), face=face, bary=bary,
                      offset=Vh - _at(Vs, Fs, face, bary))


def map_target(m: SurfaceMap, V1, F0) -> np.ndarray:
    """The high-res ground truth of a target registration: each high-res vertex's surface
    point read at the same triangle and barycentric coordinates on the target's LS3 Loop
    subdivision, plus its offset (added as is: it is rounding-sized; docs/defaust.md §2).

    Parameters
    ----------
    m : :func:`surface_map` of the rest. V1 : (n, 3) float64 target registration (metres),
    in vertex-to-vertex correspondence with the rest. F0 : (m, 3) int64, the rest's faces.

    Returns
    -------
    (p, 3) float64 metres, on the high-res rest's faces.

    Raises
    ------
    SShaDeError if the target's subdivision has another topology than the rest's.

    Examples
    --------
    Example::

        Vg = map_target(surface_map(V0, F0, Vh, 2), V1, F0)
        Vg.shape == Vh.shape
        # -> True
    """
    Vs1, Fs1 = ls3_loop(V1, F0, m.iterations)
    if len(Vs1) != m.n_sub or not np.array_equal(Fs1, m.F_sub):
        raise SShaDeError("the target's LS3 Loop subdivision has another topology than the rest's "
                          f"({len(Vs1)} vs {m.n_sub} vertices): the registrations must share one face array")
    return _at(Vs1, m.F_sub, m.face, m.bary) + m.offset


def volume_area(V, F) -> tuple[float, float]:
    """Signed enclosed volume (divergence theorem over the faces, outward orientation
    positive; m^3) and surface area (m^2) of a closed triangle mesh, the faces' terms added
    in face order (:func:`defaust.fixed_order.sum_ascending`).

    Parameters
    ----------
    V : (n, 3) float64 metres; F : (m, 3) int64.

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> [round(x, 6) for x in volume_area(V, F)]
    [0.166667, 2.366025]
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    if not len(F):
        return 0.0, 0.0
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    vol = float(fo.sum_ascending(fo.dot3(a, np.cross(b, c))) / 6.0)
    area = float(0.5 * fo.sum_ascending(fo.norm3(np.cross(b - a, c - a))))
    return vol, area


def change_pct(V_rest, V_pose, F) -> dict:
    """Signed volume and area change of a pose, in % of its rest's (as ``python -m
    defaust describe`` reports them).

    Parameters
    ----------
    V_rest, V_pose : (n, 3) float64 metres, on the same faces F (m, 3) int64.

    Returns
    -------
    dict ``volume_change_pct``, ``area_change_pct`` (floats, unitless %).

    Examples
    --------
    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    >>> {k: round(v, 6) for k, v in change_pct(V, 2 * V, F).items()}
    {'volume_change_pct': 700.0, 'area_change_pct': 300.0}
    """
    vol0, area0 = volume_area(V_rest, F)
    vol1, area1 = volume_area(V_pose, F)
    return {"volume_change_pct": 100.0 * (vol1 - vol0) / abs(vol0), "area_change_pct": 100.0 * (area1 - area0) / area0}

"""Synthetic handle-driven deformation cases for ARAP solvers (benchmarks, tests, figures).

Every builder is pure (deterministic, no I/O) and returns ``(V, F, handles, targets)``:
V (n, 3) float64 rest positions (mesh units), F (m, 3) int64 consistently oriented
triangles of one connected 2-manifold, handles (h,) int64 sorted unique, targets (h, 3)
float64. The cases are hard for plain local/global ARAP (smooth, low-frequency
deformations of long or wide shapes): :func:`twisted_bar`, :func:`bent_cylinder`,
:func:`lifted_plane` (:data:`CASES`).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from ..errors import SShaDeError

__all__ = ["box_surface", "capped_cylinder", "plane_sheet", "twisted_bar", "bent_cylinder",
           "lifted_plane", "rotation_x", "rotation_y", "CASES"]


def rotation_x(theta: float) -> np.ndarray:
    """(3, 3) rotation by ``theta`` radians about the +x axis (right hand)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation_y(theta: float) -> np.ndarray:
    """(3, 3) rotation by ``theta`` radians about the +y axis (maps +z towards +x)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def box_surface(size=(4.0, 1.0, 1.0), h: float = 0.06) -> tuple[np.ndarray, np.ndarray]:
    """Closed triangulated surface of the box ``[0, sx] x [0, sy] x [0, sz]``.

    Each side is a regular grid of near-square cells of side about ``h`` (counts per axis
    ``max(1, round(s / h))``), each cell split into two right triangles along alternating
    diagonals. The vertices of a side's grid are shared with the adjacent sides.

    Parameters
    ----------
    size : 3 floats > 0, box extents (mesh units). h : float > 0, target edge length.

    Returns
    -------
    V : (n, 3) float64, F : (m, 3) int64 outward-oriented triangles.

    Raises
    ------
    SShaDeError on non-positive sizes or ``h``.
    """
    size = np.asarray(size, np.float64)
    if size.shape != (3,) or (size <= 0).any() or not h > 0:
        raise SShaDeError(f"box_surface needs 3 positive sizes and h > 0, got {size}, {h}")
    N = np.maximum(1, np.round(size / h).astype(np.int64))
    # lattice points on the surface: index key = (i * (N1+1) + j) * (N2+1) + k
    def key(i, j, k):
        return (i * (N[1] + 1) + j) * (N[2] + 1) + k

    tris = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        gb, gc = np.meshgrid(np.arange(N[b]), np.arange(N[c]), indexing="ij")
        gb, gc = gb.ravel(), gc.ravel()
        for side in (0, 1):
            def idx(db, dc, a=a, b=b, c=c, gb=gb, gc=gc, side=side):  # called at once, in this iteration
                ijk = [None, None, None]
                ijk[a] = np.full_like(gb, side * N[a])
                ijk[b] = gb + db
                ijk[c] = gc + dc
                return key(*ijk)
            p00, p10, p11, p01 = idx(0, 0), idx(1, 0), idx(1, 1), idx(0, 1)
            alt = ((gb + gc) % 2) == 0
            t1 = np.where(alt[:, None], np.stack([p00, p10, p11], 1), np.stack([p00, p10, p01], 1))
            t2 = np.where(alt[:, None], np.stack([p00, p11, p01], 1), np.stack([p10, p11, p01], 1))
            t = np.concatenate([t1, t2])
            if side == 0:  # (e_b x e_c = e_a) points inwards on the low side
                t = t[:, ::-1]
            tris.append(t)
    T = np.concatenate(tris)
    ukey, inv = np.unique(T.ravel(), return_inverse=True)
    F = inv.reshape(-1, 3).astype(np.int64)
    k = ukey % (N[2] + 1)
    j = (ukey // (N[2] + 1)) % (N[1] + 1)
    i = ukey // ((N[2] + 1) * (N[1] + 1))
    V = np.stack([i, j, k], 1) * (size / N)
    return V.astype(np.float64), F


def capped_cylinder(radius: float = 0.5, height: float = 4.0, h: float = 0.06) -> tuple[np.ndarray, np.ndarray]:
    """Closed cylinder along +z, ``z in [0, height]``, with flat triangulated caps.

    The side is made of rings of ``nt = round(2 pi radius / h)`` vertices, alternate rings
    shifted by half a step, ring spacing chosen so the triangles are near-equilateral.
    Each cap is the Delaunay triangulation of its rim ring plus a triangular lattice of
    spacing ``h`` inside the disc of radius ``radius - 0.6 h``.

    Parameters
    ----------
    radius, height, h : float > 0 (mesh units).

    Returns
    -------
    V : (n, 3) float64, F : (m, 3) int64 outward-oriented triangles.

    Raises
    ------
    SShaDeError on non-positive parameters or ``h`` too large (fewer than 8 vertices per
    ring).
    """

    if not (radius > 0 and height > 0 and h > 0):
        raise SShaDeError("capped_cylinder needs positive radius, height and h")
    nt = int(round(2 * np.pi * radius / h))
    if nt < 8:
        raise SShaDeError(f"h={h} is too large for radius {radius} (fewer than 8 vertices per ring)")
    step = 2 * np.pi / nt
    dz_target = radius * step * np.sqrt(3) / 2
    nz = max(1, int(round(height / dz_target)))
    z = np.linspace(0.0, height, nz + 1)
    j = np.arange(nz + 1)
    th = (np.arange(nt)[None, :] + 0.5 * (j[:, None] % 2)) * step  # (nz+1, nt)
    Vside = np.stack([radius * np.cos(th), radius * np.sin(th),
                      np.broadcast_to(z[:, None], th.shape)], -1).reshape(-1, 3)
    ring = lambda jj: jj * nt + np.arange(nt)  # noqa: E731
    tris = []
    for jj in range(nz):
        a, b = ring(jj), ring(jj + 1)
        a1, b1 = np.roll(a, -1), np.roll(b, -1)
        if jj % 2 == 0:
            tris += [np.stack([a, a1, b], 1), np.stack([a1, b1, b], 1)]
        else:
            tris += [np.stack([a, a1, b1], 1), np.stack([a, b1, b], 1)]
    Fside = np.concatenate(tris)
    # cap interior points: triangular lattice inside radius - 0.6 h
    rin = radius - 0.6 * h
    m = int(np.ceil(rin / h)) + 1
    gi, gj = np.meshgrid(np.arange(-m, m + 1), np.arange(-m, m + 1), indexing="ij")
    px = (gi + 0.5 * (gj % 2)) * h
    py = gj * h * np.sqrt(3) / 2
    inside = px ** 2 + py ** 2 <= rin ** 2
    P_in = np.stack([px[inside], py[inside]], 1)
    V_list, F_list = [Vside], [Fside]
    nv = len(Vside)
    for jj, zc, up in ((0, 0.0, False), (nz, height, True)):
        rim = ring(jj)
        P = np.concatenate([Vside[rim, :2], P_in])
        tri = Delaunay(P).simplices.astype(np.int64)
        # drop triangles with all three corners on the rim that are (near) zero area
        p = P[tri]
        area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                      - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
        tri[area < 0] = tri[area < 0][:, ::-1]
        tri = tri[np.abs(area) > 1e-12 * h * h]
        if not up:
            tri = tri[:, ::-1]
        idx = np.concatenate([rim, nv + np.arange(len(P_in))])
        V_list.append(np.concatenate([P_in, np.full((len(P_in), 1), zc)], 1))
        F_list.append(idx[tri])
        nv += len(P_in)
    return np.concatenate(V_list).astype(np.float64), np.concatenate(F_list).astype(np.int64)


def plane_sheet(side: float = 1.0, n_target: int = 40000) -> tuple[np.ndarray, np.ndarray]:
    """Flat square sheet ``[0, side]^2 x {0}`` meshed with a near-equilateral lattice.

    Rows of spacing ``dy``; even rows hold ``nx + 1`` equally spaced points from ``x = 0``
    to ``side``, odd rows the ``nx`` midpoints plus the two end points ``x = 0, side``, so
    the boundary is the straight square; triangulated by Delaunay.

    Parameters
    ----------
    side : float > 0, mesh units. n_target : int >= 16, approximate vertex count.

    Returns
    -------
    V : (n, 3) float64 with ``V[:, 2] == 0``, F : (m, 3) int64 (normals +z).

    Raises
    ------
    SShaDeError on bad parameters.
    """

    if not side > 0 or n_target < 16:
        raise SShaDeError("plane_sheet needs side > 0 and n_target >= 16")
    nx = max(2, int(round(np.sqrt(n_target * np.sqrt(3) / 2))))
    ny = max(2, int(round(nx * 2 / np.sqrt(3))))
    pts = []
    for j in range(ny + 1):
        if j % 2 == 0:
            x = np.arange(nx + 1) / nx
        else:
            x = np.concatenate([[0.0], (np.arange(nx) + 0.5) / nx, [1.0]])
        pts.append(np.stack([x, np.full_like(x, j / ny)], 1))
    P = np.concatenate(pts) * side
    tri = Delaunay(P).simplices.astype(np.int64)
    p = P[tri]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    tri[area < 0] = tri[area < 0][:, ::-1]
    tri = tri[np.abs(area) > 1e-12 * (side / nx) ** 2]
    V = np.concatenate([P, np.zeros((len(P), 1))], 1)
    return V, tri


def twisted_bar(angle_deg: float = 135.0, *, length: float = 4.0, width: float = 1.0,
                h: float = 0.06) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A square bar twisted about its long axis; both end caps are handles.

    Mesh: :func:`box_surface` of size ``(length, width, width)`` (about 5,000 vertices
    with the defaults). Handles: every vertex of the two end caps (``x = 0`` and
    ``x = length``, cap borders included). Targets: the ``x = 0`` cap stays, the
    ``x = length`` cap is rotated by ``angle_deg`` about the bar's axis
    (the line ``y = z = width / 2``).

    Parameters
    ----------
    angle_deg : float, twist angle in degrees (90-180 is hard for local/global).
    length, width, h : float > 0, mesh units (``h`` the target edge length).

    Returns
    -------
    V (n, 3) float64, F (m, 3) int64, handles (h,) int64, targets (h, 3) float64.
    """
    V, F = box_surface((length, width, width), h)
    x = V[:, 0]
    tol = 1e-9 * length
    left = np.flatnonzero(x <= tol)
    right = np.flatnonzero(x >= length - tol)
    handles = np.concatenate([left, right])
    order = np.argsort(handles)
    c = np.array([0.0, width / 2, width / 2])
    T_right = (V[right] - c) @ rotation_x(np.radians(angle_deg)).T + c
    targets = np.concatenate([V[left], T_right])
    return V, F, handles[order], targets[order]


def bent_cylinder(angle_deg: float = 90.0, *, radius: float = 0.5, height: float = 4.0,
                  h: float = 0.08, band: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A capped cylinder ("cactus") bent sideways by ``angle_deg``.

    Mesh: :func:`capped_cylinder` (about 2,500 vertices with the defaults). Handles: the
    bottom band ``z <= band * height`` (cap included) stays; the top band
    ``z >= (1 - band) * height`` moves rigidly as the end of a circular arc: with the free
    length ``l = (1 - 2 band) height`` bent with radius ``rho = l / theta`` in the x-z plane,
    ``p -> R_y(theta) (p - (0, 0, b)) + (rho (1 - cos theta), 0, a + rho sin theta)`` where
    ``a = band * height`` and ``b = (1 - band) height`` (the centreline keeps its length).

    Parameters
    ----------
    angle_deg : float, bend angle in degrees. radius, height, h : float > 0, mesh units.
    band : float in (0, 0.5), handle band height as a fraction of ``height``.

    Returns
    -------
    V (n, 3) float64, F (m, 3) int64, handles (h,) int64, targets (h, 3) float64.

    Raises
    ------
    SShaDeError on ``band`` outside (0, 0.5) or a zero angle.
    """
    if not 0 < band < 0.5:
        raise SShaDeError(f"band must be in (0, 0.5), got {band}")
    theta = np.radians(angle_deg)
    if theta == 0:
        raise SShaDeError("bent_cylinder needs a non-zero angle")
    V, F = capped_cylinder(radius, height, h)
    a, b = band * height, (1 - band) * height
    bottom = np.flatnonzero(V[:, 2] <= a + 1e-12)
    top = np.flatnonzero(V[:, 2] >= b - 1e-12)
    rho = (b - a) / theta
    T_top = (V[top] - [0.0, 0.0, b]) @ rotation_y(theta).T + [rho * (1 - np.cos(theta)), 0.0, a + rho * np.sin(theta)]
    handles = np.concatenate([bottom, top])
    targets = np.concatenate([V[bottom], T_top])
    order = np.argsort(handles)
    return V, F, handles[order], targets[order]


def lifted_plane(lift: float = 0.2, *, side: float = 1.0, disc_radius: float = 0.1,
                 n_target: int = 40000) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A flat square sheet with its boundary fixed and a central disc lifted along +z.

    Mesh: :func:`plane_sheet` (about ``n_target`` vertices). Handles: the boundary
    vertices (on the square's sides; targets = rest positions) and the vertices within
    ``disc_radius * side`` of the centre (targets = rest + ``lift * side`` along +z).

    Parameters
    ----------
    lift : float, lift height as a fraction of the side (0.2 = 20 %).
    side : float > 0, mesh units. disc_radius : float in (0, 0.5), fraction of the side.
    n_target : int, approximate vertex count.

    Returns
    -------
    V (n, 3) float64, F (m, 3) int64, handles (h,) int64, targets (h, 3) float64.

    Raises
    ------
    SShaDeError on ``disc_radius`` outside (0, 0.5) or a disc holding no vertex.
    """
    if not 0 < disc_radius < 0.5:
        raise SShaDeError(f"disc_radius must be in (0, 0.5), got {disc_radius}")
    V, F = plane_sheet(side, n_target)
    tol = 1e-9 * side
    x, y = V[:, 0], V[:, 1]
    bnd = np.flatnonzero((x <= tol) | (y <= tol) | (x >= side - tol) | (y >= side - tol))
    disc = np.flatnonzero((x - side / 2) ** 2 + (y - side / 2) ** 2 <= (disc_radius * side) ** 2)
    if len(disc) == 0:
        raise SShaDeError("the lifted disc holds no vertex; increase disc_radius or n_target")
    handles = np.concatenate([bnd, disc])
    targets = V[handles].copy()
    targets[len(bnd):, 2] += lift * side
    order = np.argsort(handles)
    return V, F, handles[order], targets[order]


#: name -> builder with its default (benchmark-size) arguments
CASES = {"twisted_bar": twisted_bar, "bent_cylinder": bent_cylinder, "lifted_plane": lifted_plane}

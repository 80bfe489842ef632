"""High-resolution rest meshes of DeFAUST (paper appendix A): LS3 Loop subdivision (Boye et
al. 2010) then isotropic remeshing (Hoppe et al. 1993) to a vertex count in [150k, 200k]
(:func:`subdivide_remesh`), both pymeshlab filters. Deterministic for a given input; the
remesh dominates a subject's build time. The filters' settings and the measurements behind
them: docs/defaust.md, "Implementation notes: defaust/highres.py".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh

__all__ = ["HighResResult", "subdivide_remesh", "ls3_loop", "isotropic_remesh", "meshset"]


@dataclass(frozen=True)
class HighResResult:
    """Output of :func:`subdivide_remesh`.

    Attributes
    ----------
    V : (n, 3) float64 vertices (input units); F : (m, 3) int64 faces.
    iterations : int, LS3 Loop iterations used.
    n_subdivided : int, vertex count after subdivision.
    target_edge : float, final target edge length of the remesh (input units).
    attempts : int, remeshes run.
    """

    V: np.ndarray
    F: np.ndarray
    iterations: int
    n_subdivided: int
    target_edge: float
    attempts: int


def ls3_loop(V, F, iterations: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """LS3 Loop subdivision of every edge (no length threshold).

    Parameters
    ----------
    V : (n, 3) float64; F : (m, 3) int, closed or open triangle mesh.
    iterations : int >= 1.

    Returns
    -------
    V : (~4^k n, 3) float64; F : (4^k m, 3) int64.

    Examples
    --------
    Example::

        V2, F2 = ls3_loop(V, F, 1)
        len(F2) == 4 * len(F)
        # -> True
    """
    ms = meshset(V, F)
    _ls3(ms, iterations)
    m = ms.current_mesh()
    return np.asarray(m.vertex_matrix(), np.float64), np.asarray(m.face_matrix(), np.int64)


def isotropic_remesh(ms, edge: float, iterations: int, *, check_distance: bool = True) -> None:
    """pymeshlab's ``meshing_isotropic_explicit_remeshing`` on the current mesh of ``ms``
    with an absolute target edge length ``edge`` (mesh units), ``iterations`` passes and
    every parameter given: pymeshlab takes a parameter left out from its *previous call*
    in the process, not from its documented default (measured: a remesh that leaves
    ``checksurfdist`` out after one with ``checksurfdist=False`` runs without the check),
    so a call that relies on a default depends on what ran before it. The values are
    pymeshlab's defaults (adaptive off, feature angle 30 deg, surface distance 1% of the
    bounding box, every step on) except ``check_distance`` (``checksurfdist``)."""
    import pymeshlab

    ms.meshing_isotropic_explicit_remeshing(
        iterations=int(iterations), adaptive=False, selectedonly=False, targetlen=pymeshlab.PureValue(float(edge)),
        featuredeg=30.0, checksurfdist=bool(check_distance), maxsurfdist=pymeshlab.PercentageValue(1.0),
        splitflag=True, collapseflag=True, swapflag=True, smoothflag=True, reprojectflag=True)


def meshset(V, F):
    """A pymeshlab ``MeshSet`` holding one mesh: ``V`` (n, 3) float64 and ``F`` (m, 3)
    taken as int32, pymeshlab's face type (contiguous copies where needed). Unchecked: the
    caller passes a checked mesh. Raises ImportError without pymeshlab."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int32)))
    return ms


def _ls3(ms, iterations: int) -> None:
    import pymeshlab

    ms.meshing_surface_subdivision_ls3_loop(loopweight="Loop", iterations=int(iterations),
                                            threshold=pymeshlab.PercentageValue(0.0))


def subdivide_remesh(V, F, *, vertex_range=(150_000, 200_000), remesh_iterations: int = 10,
                     max_attempts: int = 4, check_distance: bool = False) -> HighResResult:
    """High-resolution version of a mesh: LS3 Loop, then isotropic remeshing.

    Parameters
    ----------
    V : (n, 3) float64 vertex positions (any unit; FAUST and synthetic: metres).
    F : (m, 3) int faces, a closed or open 2-manifold.
    vertex_range : (lo, hi) int, accepted vertex counts of the result (paper:
        [150k, 200k]).
    remesh_iterations : int, iterations of the isotropic remesh (pymeshlab default 10).
    max_attempts : int, remeshes tried before giving up.
    check_distance : bool, pymeshlab's ``checksurfdist`` (its default True): test every
        collapse and flip against the subdivided surface with a tolerance of 1% of the
        bounding box. False (the builder's default) halves the remesh time; the ``ci``
        preset's coarse meshes need True (docs/defaust.md, "Implementation notes:
        defaust/highres.py").

    Returns
    -------
    HighResResult, its mesh validated (:func:`sshade.mesh.validate.validate_mesh`) and with
    ``lo <= len(V) <= hi``.

    Raises
    ------
    SShaDeError on a bad range, or if no attempt gives a valid mesh (a manifold single
    component without degenerate faces) in the range; an attempt whose mesh is refused
    is followed by one with a 0.5 % shorter target edge.

    Examples
    --------
    Example::

        r = subdivide_remesh(V, F, vertex_range=(8000, 12000))
        8000 <= len(r.V) <= 12000
        # -> True
    """


    lo, hi = (int(x) for x in vertex_range)
    if not 0 < lo <= hi:
        raise SShaDeError(f"high-res vertex range must satisfy 0 < lo <= hi, got [{lo}, {hi}]")
    V = np.ascontiguousarray(V, np.float64)
    F = np.ascontiguousarray(F, np.int64)
    target_n = 0.5 * (lo + hi)
    # fewest LS3 iterations (>= 1) that reach half the target count: the remesh then
    # mostly collapses/flips instead of splitting long edges of a coarse surface
    k, n_est = 1, 4 * len(V)
    while n_est < 0.5 * target_n and k < 8:
        k, n_est = k + 1, 4 * n_est
    base = meshset(V, F)
    _ls3(base, k)
    Vs = np.asarray(base.current_mesh().vertex_matrix(), np.float64)
    Fs = np.asarray(base.current_mesh().face_matrix(), np.int64)
    n_sub = len(Vs)
    area = float(base.get_geometric_measures()["surface_area"])
    del base
    edge = float(np.sqrt(2.0 * area / (np.sqrt(3.0) * target_n)))
    tried, invalid = [], []
    for attempt in range(1, int(max_attempts) + 1):
        ms = meshset(Vs, Fs)
        isotropic_remesh(ms, edge, remesh_iterations, check_distance=check_distance)
        m = ms.current_mesh()
        n = m.vertex_number()
        tried.append((edge, n))
        if lo <= n <= hi:
            Vh = np.asarray(m.vertex_matrix(), np.float64)
            Fh = np.asarray(m.face_matrix(), np.int64)
            try:
                Vh, Fh = validate_mesh(Vh, Fh, name="high-res remesh")
            except SShaDeError as e:  # e.g. a degenerate face: the next attempt, a 0.5 % shorter edge
                invalid.append(str(e))
                edge *= 0.995
                continue
            return HighResResult(V=Vh, F=Fh, iterations=k, n_subdivided=int(n_sub), target_edge=edge,
                                 attempts=attempt)
        edge *= float(np.sqrt(n / target_n))
    why = f"; meshes refused: {'; '.join(invalid)}" if invalid else ""
    raise SShaDeError(f"isotropic remesh did not reach a valid mesh of [{lo}, {hi}] vertices in {max_attempts} "
                      f"attempts (target edge length -> vertex count: {[(round(e, 6), n) for e, n in tried]}{why})")

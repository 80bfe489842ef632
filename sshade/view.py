"""``python -m sshade view``: drag a mesh's handle region with a transformation gizmo in
polyscope and see SShaDe's result on every change (prepared once, solved per change:
:func:`sshade.prepared.prepare`). polyscope is the optional ``[view]`` extra.

Usage::

    python -m sshade view MESH (--sel F.sel | --dmat F.dmat | --handles F.json|F.csv)
        [--n-low N] [--k K] [--seed S]

With a selection (``.sel``/``.dmat``) the gizmo moves the handle vertices (status 2) and
the fixed ones stay; with ``--handles`` it moves every listed handle (their stored targets
are not used). The gizmo starts at the moved vertices' centroid, so it turns them about it.
Each change re-solves; the window shows the last solve's time. Nothing is written (no
polyscope preference files). Exit status 0 when the window is closed, 2 after one
``error:`` line (no polyscope, bad input).
"""
from __future__ import annotations

import time

import numpy as np

from .clirun import ArgumentParser, run_command
from .errors import SShaDeError
from .mesh.handle_files import apply_def, read_moving_handles
from .mesh.io import read_mesh
from .prepared import prepare

__all__ = ["Viewer", "build_parser", "main"]


def _polyscope():
    """The ``polyscope`` module, or SShaDeError saying how to install it."""
    try:
        import polyscope
        import polyscope.imgui  # noqa: F401 -- the window's text (Viewer.update)
    except (ImportError, OSError) as e:  # missing, or present but its shared libraries do not load
        raise SShaDeError(f"python -m sshade view needs polyscope: pip install 'sshade[view]' "
                          f"({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})") from None
    return polyscope


class Viewer:
    """The state behind the window: the prepared SShaDe, the gizmo, the last result.

    Parameters
    ----------
    ps : the polyscope module (initialised). V : (n, 3) float64; F : (m, 3) int64.
    handles : (h,) int64; moved : (h,) bool, the handles the gizmo moves (the others stay).
    prepared : :class:`sshade.prepared.Prepared` for ``(V, F, handles)``.

    Attributes
    ----------
    Vd : (n, 3) float64 the shown result. solves : int. frame_s : float or None, the last
    solve's seconds.
    """

    def __init__(self, ps, V, F, handles, moved, prepared):
        self.ps, self.V, self.handles, self.moved, self.prepared = ps, V, handles, moved, prepared
        self.rest = V[handles]
        c = self.rest[moved].mean(axis=0)
        self.T0 = np.eye(4)
        self.T0[:3, 3] = c
        self.mesh = ps.register_surface_mesh("mesh", V, F)
        ps.register_point_cloud("fixed handles", self.rest[~moved], color=(0.2, 0.4, 1.0))
        self.points = ps.register_point_cloud("moved handles", self.rest[moved], color=(1.0, 0.85, 0.1))
        self.gizmo = ps.add_transformation_gizmo("handles")
        self.gizmo.set_transform(self.T0)
        self.last = np.asarray(self.gizmo.get_transform(), np.float64)  # as the gizmo stores it (float32)
        self.Vd, self.solves, self.frame_s = V.copy(), 0, None

    def targets(self, T: np.ndarray) -> np.ndarray:
        """(h, 3) targets for the gizmo transform ``T`` (4, 4): the moved handles by
        ``T @ inv(T0)`` (``T0``: the gizmo's start), the others at rest."""
        out = self.rest.copy()
        out[self.moved] = apply_def(T @ np.linalg.inv(self.T0), self.rest[self.moved])
        return out

    def refresh(self) -> bool:
        """Re-solve when the gizmo moved since the last solve; returns whether it did."""
        T = np.asarray(self.gizmo.get_transform(), np.float64)
        if np.array_equal(T, self.last):
            return False
        t0 = time.perf_counter()
        targets = self.targets(T)
        self.Vd = self.prepared.solve(targets)
        self.frame_s = time.perf_counter() - t0
        self.mesh.update_vertex_positions(self.Vd)
        self.points.update_point_positions(targets[self.moved])
        self.last, self.solves = T, self.solves + 1
        return True

    def callback(self) -> None:
        """polyscope's per-frame user callback: :meth:`refresh`, then the last solve's time
        in the window (imgui: only inside a frame)."""
        self.refresh()
        imgui = getattr(self.ps, "imgui", None)
        if imgui is not None:
            imgui.TextUnformatted("drag the gizmo" if self.frame_s is None else
                                  f"last solve {1000 * self.frame_s:.0f} ms ({self.solves} solves)")


def build_parser() -> ArgumentParser:
    """The argument parser of ``python -m sshade view`` (module docstring)."""
    p = ArgumentParser(prog="python -m sshade view", description="Drag handles and see SShaDe's result.")
    p.add_argument("mesh", help="input mesh (.obj, .off, .ply)")
    g = p.add_argument_group("handles (one of)")
    g.add_argument("--sel", help="deformation-benchmark selection: 0 fixed, 1 free, 2 handle (moved)")
    g.add_argument("--dmat", help="libigl .dmat selection: -1 free, 0 fixed, >= 1 handle (moved)")
    g.add_argument("--handles", help=".json or .csv of handle indices (all moved together)")
    p.add_argument("--n-low", default="auto", help="SShaDe's low-resolution vertex count (int or auto)")
    p.add_argument("--k", type=int, default=5, help="SShaDe's number of samplings (default 5)")
    p.add_argument("--seed", type=int, default=0, help="SShaDe's seed (default 0)")
    return p


def open_viewer(a, ps, backend: str | None = None) -> Viewer:
    """Read the mesh and handles of arguments ``a``, prepare SShaDe, initialise ``ps``
    (``backend``: polyscope's, e.g. ``"openGL_mock"`` for tests) and return the
    :class:`Viewer`, its callback installed. Raises SShaDeError on bad input."""
    if sum(map(bool, (a.sel, a.dmat, a.handles))) != 1:
        raise SShaDeError("give exactly one of --sel F.sel, --dmat F.dmat, --handles F.json|F.csv")
    V, F = read_mesh(a.mesh, validate=False)
    handles, moved = read_moving_handles(len(V), sel=a.sel, dmat=a.dmat, handles=a.handles)
    if not moved.any():
        raise SShaDeError("the selection has no handle vertex (status 2) for the gizmo to move")
    prepared = prepare(V, F, handles, n_low=a.n_low, n_samplings=a.k, seed=a.seed)  # n_low checked there
    ps.set_use_prefs_file(False)  # no .polyscope.ini / imgui.ini in the user's folder
    ps.init(backend) if backend else ps.init()
    viewer = Viewer(ps, prepared.V, prepared.F, prepared.handles, moved, prepared)
    ps.set_user_callback(viewer.callback)
    return viewer


def main(argv: list[str]) -> int:
    """``python -m sshade view ...`` with ``argv`` (the words after ``view``); returns the
    exit status."""
    a = build_parser().parse_args(argv)

    def run():
        ps = _polyscope()
        viewer = open_viewer(a, ps)
        try:
            ps.show()
        finally:
            viewer.prepared.close()
        return 0
    return run_command(run, where=None)

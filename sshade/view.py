"""``python -m sshade view``: drag a mesh's handle region with a gizmo in polyscope (the
``[view]`` extra) and see SShaDe's result on every change, or play an animation that
``python -m sshade animate`` wrote (:class:`Player`). Behaviour: docs/implementation.md
("Implementation notes: sshade/view.py").

Usage::

    python -m sshade view MESH (--sel F.sel | --dmat F.dmat | --handles F.json|F.csv)
        [--n-low N] [--k K] [--seed S]
    python -m sshade view ANIMATION.npz|ANIMATION.glb [--fps FPS]
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .animate import DEFAULT_FPS, read_animation_npz
from .command_errors import ArgumentParser, run_command
from .errors import SShaDeError
from .mesh.gltf import read_glb_animation
from .mesh.handle_files import apply_def, read_moving_handles
from .mesh.io import read_mesh
from .prepared import prepare

__all__ = ["Viewer", "Player", "build_parser", "open_viewer", "open_player", "read_animation", "main"]

#: The suffixes of an animation (``python -m sshade animate``'s outputs) to play.
ANIMATIONS = (".npz", ".glb")


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


class Player:
    """The state behind an animation's window: the frames, the one shown, play/pause.

    Parameters
    ----------
    ps : the polyscope module (initialised). frame : callable, ``frame(i)`` -> (n, 3) float
    positions of frame i. F : (m, 3) int64. times : (f,) float64 seconds of the frames,
    increasing. clock : callable -> seconds (default ``time.monotonic``).

    Attributes
    ----------
    mesh : the registered polyscope surface mesh ("animation"). shown : int, the frame on
    it. playing : bool.
    """

    def __init__(self, ps, frame, F, times, clock=time.monotonic):
        self.ps, self.frame, self.times, self.clock = ps, frame, np.asarray(times, np.float64), clock
        self.mesh = ps.register_surface_mesh("animation", frame(0), F)
        self.shown, self.playing, self.start = 0, False, 0.0
        step = float(np.median(np.diff(self.times))) if len(self.times) > 1 else 1.0
        self.period = float(self.times[-1] - self.times[0]) + step  # a loop: the last frame is shown for a step

    def show(self, i: int) -> None:
        """Put frame ``i`` (clipped to the frames) on the mesh."""
        i = int(np.clip(i, 0, len(self.times) - 1))
        if i != self.shown:
            self.mesh.update_vertex_positions(self.frame(i))
            self.shown = i

    def play(self, on: bool) -> None:
        """Start (from the shown frame) or stop playing."""
        self.playing = bool(on) and len(self.times) > 1
        self.start = self.clock() - (self.times[self.shown] - self.times[0])

    def tick(self) -> None:
        """While playing, show the frame whose time has come (looping)."""
        if self.playing:
            t = self.times[0] + (self.clock() - self.start) % self.period
            self.show(int(np.searchsorted(self.times, t, side="right")) - 1)

    def callback(self) -> None:
        """polyscope's per-frame user callback: the frame slider, the play/pause button,
        :meth:`tick`, the shown frame's time."""
        imgui = self.ps.imgui
        changed, i = imgui.SliderInt("frame", self.shown, 0, len(self.times) - 1)
        if changed:
            self.show(i)
            if self.playing:
                self.play(True)  # go on from the frame chosen
        if imgui.Button("pause" if self.playing else "play"):
            self.play(not self.playing)
        self.tick()
        imgui.TextUnformatted(f"frame {self.shown} of 0-{len(self.times) - 1}, {self.times[self.shown]:.3f} s")


def read_animation(path, fps: float | None = None) -> tuple:
    """(frame, F, times) of an animation file for :class:`Player`: ``frame(i)`` -> (n, 3)
    positions, F (m, 3) int64, times (f,) float64 seconds (``i / fps`` with ``fps`` given;
    else the ``.glb``'s keyframe times or the ``.npz``'s ``fps``). Memory: an ``.npz``'s
    frames are read whole ((f, n, 3) float64); a ``.glb`` is memory-mapped, each frame made
    when shown. Raises SShaDeError naming the file and the place on a bad file."""
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise SShaDeError(f"--fps must be a positive number, got {fps}")
    if Path(path).suffix.lower() == ".npz":
        V, F, stored = read_animation_npz(path)
        return V.__getitem__, F, np.arange(len(V)) / (fps or stored)
    anim = read_glb_animation(path)
    times = anim.times
    if fps is not None or times is None:
        rate = anim.extras.get("fps", DEFAULT_FPS)
        rate = fps or (rate if isinstance(rate, (int, float)) and np.isfinite(rate) and rate > 0 else DEFAULT_FPS)
        times = np.arange(anim.n_frames) / rate
    return anim.frame, anim.F, times


def open_player(a, ps, backend: str | None = None, clock=time.monotonic) -> Player:
    """Read the animation of arguments ``a`` (:func:`read_animation`), initialise ``ps``
    (``backend`` as in :func:`open_viewer`) and return the :class:`Player`, its callback
    installed. Raises SShaDeError on bad input (before ``ps`` is initialised)."""
    if a.sel or a.dmat or a.handles:
        raise SShaDeError(f"{a.mesh} is an animation, played as it is; --sel, --dmat and --handles are for a mesh")
    frame, F, times = read_animation(a.mesh, a.fps)
    _init(ps, backend)
    player = Player(ps, frame, F, times, clock)
    ps.set_user_callback(player.callback)
    return player


def _init(ps, backend: str | None) -> None:
    """Initialise polyscope ``ps`` (``backend``, or its default) without a preferences file
    in the user's folder; SShaDeError in one line where no window can be opened (no
    display, no OpenGL: polyscope's RuntimeError)."""
    ps.set_use_prefs_file(False)  # no .polyscope.ini / imgui.ini in the user's folder
    try:
        ps.init(backend) if backend else ps.init()
    except RuntimeError as e:
        raise SShaDeError(f"the viewer cannot open a window here ({' '.join(str(e).split())[:300]}); it needs a "
                          "display with OpenGL (over SSH: ssh -X, or xvfb-run for a screenshot)") from None


def build_parser() -> ArgumentParser:
    """The argument parser of ``python -m sshade view`` (module docstring)."""
    p = ArgumentParser(prog="python -m sshade view",
                       description="Drag handles and see SShaDe's result, or play an animation of sshade animate.")
    p.add_argument("mesh", help="input mesh (.obj, .off, .ply), or an animation to play (.npz, .glb of sshade animate)")
    g = p.add_argument_group("handles (one of)")
    g.add_argument("--sel", help="deformation-benchmark selection: 0 fixed, 1 free, 2 handle (moved)")
    g.add_argument("--dmat", help="libigl .dmat selection: -1 free, 0 fixed, >= 1 handle (moved)")
    g.add_argument("--handles", help=".json or .csv of handle indices (all moved together)")
    p.add_argument("--n-low", default="auto", help="SShaDe's low-resolution vertex count (int or auto)")
    p.add_argument("--k", type=int, default=5, help="SShaDe's number of samplings (default 5)")
    p.add_argument("--seed", type=int, default=0, help="SShaDe's seed (default 0)")
    p.add_argument("--fps", type=float, default=None,
                   help="an animation's frames per second (default: the file's keyframe times or fps)")
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
    _init(ps, backend)
    viewer = Viewer(ps, prepared.V, prepared.F, prepared.handles, moved, prepared)
    ps.set_user_callback(viewer.callback)
    return viewer


def main(argv: list[str]) -> int:
    """``python -m sshade view ...`` with ``argv`` (the words after ``view``); returns the
    exit status."""
    a = build_parser().parse_args(argv)

    def run():
        ps = _polyscope()
        if Path(a.mesh).suffix.lower() in ANIMATIONS:
            open_player(a, ps)
            ps.show()
            return 0
        viewer = open_viewer(a, ps)
        try:
            ps.show()
        finally:
            viewer.prepared.close()
        return 0
    return run_command(run, where=None)

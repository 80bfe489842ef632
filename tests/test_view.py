"""sshade/view.py (``python -m sshade view``): a moved gizmo moves the drawn mesh to the
solve's result, through polyscope's mock backend (no display) and in the real window under
Xvfb (screenshots, and the positions polyscope holds); an animation's frame slider and
play button put frame k on the drawn mesh; skips with one line where polyscope cannot be
imported (mark ``view``) or xvfb-run is not on PATH (mark ``xvfb``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sshade.deform_command import main as sshade_main
from sshade.mesh.handle_files import write_sel
from sshade.mesh.io import read_mesh
from sshade.prepared import prepare
from sshade.view import build_parser, open_player, open_viewer

from .conftest import SHARED_DATA
from .optional import optional_import

MESH = SHARED_DATA / "faust_reg" / "tr_reg_000.ply"


def _drawn(structure) -> np.ndarray:
    """(n, 3) float32: the vertex positions polyscope holds for a registered surface mesh
    (its ``vertexPositions`` buffer), i.e. what the window draws."""
    buf = structure.get_buffer("vertexPositions")
    return np.array([buf.get_value(i).as_tuple() for i in range(buf.size())], np.float32)


def _head_and_feet(sel: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """FAUST's first registration and a selection written to ``sel``: the feet fixed
    (status 0, the lowest 10 %), the head moved (status 2, the top 5 %): (V, F, status)."""
    if not MESH.is_file():
        pytest.skip(f"FAUST registration not found: {MESH}")
    V, F = read_mesh(MESH)
    status = np.ones(len(V), int)
    status[V[:, 1] < np.quantile(V[:, 1], 0.1)] = 0
    status[V[:, 1] > np.quantile(V[:, 1], 0.95)] = 2
    write_sel(sel, status)
    return V, F, status


@pytest.mark.view
def test_a_moved_gizmo_moves_the_handle_region_and_the_mesh_with_it(tmp_path, monkeypatch):
    ps = optional_import("polyscope")
    V, F, status = _head_and_feet(tmp_path / "s.sel")
    a = build_parser().parse_args([str(MESH), "--sel", str(tmp_path / "s.sel"), "--n-low", "300", "--k", "2"])
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    viewer = open_viewer(a, ps, backend="openGL_mock")
    assert not viewer.refresh() and viewer.solves == 0  # nothing moved: no solve
    T = viewer.gizmo.get_transform()
    T[:3, 3] += [0.1, 0.0, 0.0]  # drag the head 10 cm sideways
    viewer.gizmo.set_transform(T)
    ps.frame_tick()  # one frame of the window loop runs the callback
    ps.frame_tick()
    assert viewer.solves == 1 and viewer.frame_s is not None
    head, feet = status == 2, status == 0
    np.testing.assert_allclose(viewer.Vd[head], V[head] + [0.1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(viewer.Vd[feet], V[feet], atol=1e-12)
    handles = np.flatnonzero(status != 1)
    expected = prepare(V, F, handles, n_low=300, n_samplings=2).solve(viewer.targets(T))
    assert np.array_equal(viewer.Vd, expected)  # the viewer's result is SShaDe's
    drawn = _drawn(ps.get_surface_mesh("mesh"))
    assert np.array_equal(drawn, expected.astype(np.float32))  # and it is what the window draws,
    assert np.abs(drawn[head] - V[head]).max() > 0.09  # not the rest pose
    assert list(cwd.iterdir()) == []  # no preference files written where it ran


def test_without_polyscope_the_command_is_one_error_line(tmp_path, monkeypatch, capsys):
    import builtins
    real = builtins.__import__

    def no_polyscope(name, *args, **kwargs):
        if name.startswith("polyscope"):
            raise ImportError(name)
        return real(name, *args, **kwargs)
    monkeypatch.setattr(builtins, "__import__", no_polyscope)
    from sshade.view import main
    assert main([str(tmp_path / "m.obj"), "--handles", str(tmp_path / "h.json")]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("error: python -m sshade view needs polyscope: pip install "
                                               "'sshade[view]' (ImportError: ")


def test_where_no_window_can_open_the_command_is_one_error_line(tmp_path, monkeypatch, capsys):
    """polyscope installed but no display (its init raises RuntimeError): one ``error:``
    line saying what the viewer needs, exit 2, no traceback."""
    import sys
    import types

    from sshade.mesh.io import write_mesh
    from sshade.view import main
    fake = types.ModuleType("polyscope")
    fake.set_use_prefs_file = lambda flag: None

    def init(*args):
        raise RuntimeError("[polyscope] [EXCEPTION] GLFW initialization failed")
    fake.init = init
    fake.__path__ = []  # a package, with its imgui module
    monkeypatch.setitem(sys.modules, "polyscope", fake)
    monkeypatch.setitem(sys.modules, "polyscope.imgui", types.ModuleType("polyscope.imgui"))
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    write_mesh(tmp_path / "m.obj", V, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    (tmp_path / "h.json").write_text('{"handles": [0, 1, 2], "targets": [[0, 0, 0], [1, 0, 0], [0, 1.5, 0]]}')
    assert main([str(tmp_path / "m.obj"), "--handles", str(tmp_path / "h.json"), "--n-low", "4"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("error: the viewer cannot open a window here") and "GLFW" in err[0]


_SCREENSHOTS = """
import sys
import numpy as np
import polyscope as ps
from sshade.view import build_parser, open_viewer
viewer = open_viewer(build_parser().parse_args(sys.argv[1:]), ps)  # polyscope's OpenGL backend
ps.set_ground_plane_mode("none")
others = [ps.get_point_cloud("fixed handles"), ps.get_point_cloud("moved handles"), viewer.gizmo]

def shots(name):  # the whole window, then the mesh alone (no handle points, no gizmo)
    ps.screenshot(name + ".png", transparent_bg=False)
    for s in others:
        s.set_enabled(False)
    ps.screenshot(name + "_mesh.png", transparent_bg=False)
    for s in others:
        s.set_enabled(True)

ps.frame_tick()
shots("before")
T = viewer.gizmo.get_transform()
T[:3, 3] += MOVE
viewer.gizmo.set_transform(T)
ps.frame_tick()
ps.frame_tick()
shots("after")
buf = ps.get_surface_mesh("mesh").get_buffer("vertexPositions")  # what polyscope draws
np.save("drawn.npy", np.array([buf.get_value(i).as_tuple() for i in range(buf.size())], np.float32))
np.save("solved.npy", viewer.Vd)
print("solves", viewer.solves)
"""


def _screenshots(tmp_path, move) -> dict:
    """Run the viewer under Xvfb, drag the head's gizmo by ``move`` (3,) metres between two
    sets of screenshots: ``before``/``after`` (the window) and ``before_mesh``/``after_mesh``
    (the mesh alone) RGB images in [0, 1], ``drawn`` (n, 3) float32 the positions polyscope
    holds after the drag, ``solved`` (n, 3) the viewer's solve, ``V`` the rest pose and the
    selection's ``status``."""
    import os
    import shutil
    import subprocess
    import sys
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run not found on PATH (Debian: apt-get install xvfb xauth libgl1-mesa-dri); "
                    ".ci/run installs it and reruns the tests marked 'xvfb'")
    optional_import("polyscope")
    from matplotlib.image import imread
    V, _, status = _head_and_feet(tmp_path / "s.sel")
    (tmp_path / "shots.py").write_text(f"MOVE = {list(map(float, move))}\n{_SCREENSHOTS}")
    env = {**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", sys.executable, "shots.py", str(MESH),
                        "--sel", "s.sel", "--n-low", "300", "--k", "2"], cwd=tmp_path,
                       env=env, capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert r.returncode == 0 and "solves 1" in r.stdout, r.stdout + r.stderr
    out = {k: imread(tmp_path / f"{k}.png")[..., :3] for k in ("before", "after", "before_mesh", "after_mesh")}
    return {**out, "drawn": np.load(tmp_path / "drawn.npy"), "solved": np.load(tmp_path / "solved.npy"), "V": V,
            "status": status}


def _head_x(img: np.ndarray) -> float:
    """Mean column of the drawn pixels (those unlike the background, the top-left pixel) in
    the top tenth of the drawn rows: the head."""
    m = np.abs(img - img[0, 0]).max(axis=2) > 0.1
    rows = np.flatnonzero(m.any(axis=1))
    top = m[rows[0]:rows[0] + max(1, (rows[-1] - rows[0]) // 10)]
    assert top.sum() > 100
    return float(np.nonzero(top)[1].mean())


def _yellow_x(img: np.ndarray) -> float:
    """Mean column of the pixels in the handle points' colour (polyscope's yellow)."""
    m = (img[..., 0] > 0.75) & (img[..., 1] > 0.65) & (img[..., 2] < 0.4)
    assert m.sum() > 100
    return float(np.nonzero(m)[1].mean())


@pytest.mark.view
@pytest.mark.xvfb
def test_under_xvfb_a_dragged_gizmo_moves_the_drawn_mesh_to_the_solve_and_not_the_feet(tmp_path):
    """The real window (polyscope's OpenGL backend on Xvfb with Mesa's software renderer),
    the gizmo moving the head 30 cm sideways: the positions polyscope draws are the solve's
    (not the rest pose), the mesh alone (handle points and gizmo hidden) shows its head
    moved right on screen, the head's handle points (drawn yellow) too, and the fixed feet
    (the bottom fifth) are drawn where they were."""
    s = _screenshots(tmp_path, (0.3, 0.0, 0.0))
    head = s["status"] == 2
    assert np.array_equal(s["drawn"], s["solved"].astype(np.float32))
    np.testing.assert_allclose(s["drawn"][head], s["V"][head] + [0.3, 0, 0], atol=1e-6)
    assert _head_x(s["after_mesh"]) - _head_x(s["before_mesh"]) > 20  # pixels, to the right
    assert _yellow_x(s["after"]) - _yellow_x(s["before"]) > 20
    before, after = s["before"], s["after"]
    feet = slice(int(0.8 * before.shape[0]), before.shape[0])
    assert np.abs(before[feet] - after[feet]).max(axis=2).mean() < 0.01


@pytest.fixture(scope="module")
def animation(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """A four-frame animation of FAUST's first registration whose handles (every 53rd
    vertex) go to the second's, written by ``python -m sshade animate`` as ``a.npz`` and
    ``a.glb`` (10 frames per second) in a folder: (folder, the .npz's frames (4, n, 3))."""
    if not MESH.is_file():
        pytest.skip(f"FAUST registration not found: {MESH}")
    import json
    d = tmp_path_factory.mktemp("animation")
    V, _ = read_mesh(MESH)
    V2, _ = read_mesh(MESH.with_name("tr_reg_001.ply"))
    h = np.arange(0, len(V), 53)
    (d / "h.json").write_text(json.dumps({"handles": h.tolist(), "targets": V[h].tolist()}))
    np.save(d / "frames.npy", np.stack([V[h] + t * (V2[h] - V[h]) for t in (0.0, 1 / 3, 2 / 3, 1.0)]))
    for out in ("a.npz", "a.glb"):
        assert sshade_main(["animate", str(MESH), "--handles", str(d / "h.json"), "--frames", str(d / "frames.npy"),
                            "--n-low", "300", "--k", "2", "--fps", "10", "-o", str(d / out)]) == 0
    return d, np.load(d / "a.npz")["V"]


def _assert_shows(ps, frame: np.ndarray, exact: bool) -> None:
    """The drawn animation mesh is ``frame``: its float32 cast (an .npz's float64 frames),
    or within float32 rounding (a .glb's base + target)."""
    drawn = _drawn(ps.get_surface_mesh("animation"))
    if exact:
        assert np.array_equal(drawn, frame.astype(np.float32))
    else:
        assert np.abs(drawn - frame).max() <= 4 * np.finfo(np.float32).eps * np.abs(frame).max()


@pytest.mark.view
@pytest.mark.parametrize("name", ["a.npz", "a.glb"])
def test_the_frame_slider_set_to_frame_k_puts_frame_k_on_the_drawn_mesh(animation, monkeypatch, name):
    ps = optional_import("polyscope")
    d, frames = animation
    monkeypatch.chdir(d)
    player = open_player(build_parser().parse_args([name]), ps, backend="openGL_mock")
    ps.set_frame_tick_limit_fps_mode("ignore_limits")  # else a tick within 1/60 s of the last is skipped
    _assert_shows(ps, frames[0], name == "a.npz")  # it opens on the first frame
    for k in (2, 3, 1):
        monkeypatch.setattr(ps.imgui, "SliderInt", lambda label, v, lo, hi, *a, k=k: (True, k))
        ps.frame_tick()  # the window's loop runs the callback: the slider says k
        assert player.shown == k
        _assert_shows(ps, frames[k], name == "a.npz")
        assert np.abs(frames[k] - frames[0]).max() > 0.01  # a frame other than the first


@pytest.mark.view
def test_play_shows_each_frame_at_its_time_and_loops(animation, monkeypatch):
    ps = optional_import("polyscope")
    d, frames = animation
    now = [100.0]
    player = open_player(build_parser().parse_args([str(d / "a.glb")]), ps, backend="openGL_mock",
                         clock=lambda: now[0])
    ps.set_frame_tick_limit_fps_mode("ignore_limits")
    presses = iter([True])
    monkeypatch.setattr(ps.imgui, "Button", lambda label, *a: label == "play" and next(presses, False))
    ps.frame_tick()  # "play" pressed at t = 0
    assert player.playing and player.shown == 0
    for t, k in ((0.25, 2), (0.31, 3), (0.45, 0), (0.52, 1)):  # keyframes 0.1 s apart; one loop is 0.4 s
        now[0] = 100.0 + t
        ps.frame_tick()
        assert player.shown == k, t
        _assert_shows(ps, frames[k], exact=False)


@pytest.mark.view
@pytest.mark.parametrize("case, says", [
    ("other.npz", "other.npz: not an animation of python -m sshade animate (no 'sshade_animation' array"),
    ("cut.glb", "cut.glb: its header gives"),
    ("with --sel", "is an animation, played as it is; --sel, --dmat and --handles are for a mesh")])
def test_a_file_that_is_not_an_animation_is_one_error_line(animation, tmp_path, capsys, case, says):
    optional_import("polyscope")
    from sshade.view import main
    d, _ = animation
    np.savez(tmp_path / "other.npz", V=np.zeros((2, 3, 3)))
    (tmp_path / "cut.glb").write_bytes((d / "a.glb").read_bytes()[:-10])
    argv = [str(d / "a.npz"), "--sel", "s.sel"] if case == "with --sel" else [str(tmp_path / case)]
    assert main(argv) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("error: ") and says in err[0], err

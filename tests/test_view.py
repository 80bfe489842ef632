"""sshade/view.py (``python -m sshade view``): a moved gizmo moves the mesh, through
polyscope's mock backend (no display) and in the real window under Xvfb (two screenshots);
skips with one line where polyscope cannot be imported (mark ``view``) or xvfb-run is not on
PATH (mark ``xvfb``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sshade.mesh.handle_files import write_sel
from sshade.mesh.io import read_mesh
from sshade.prepared import prepare
from sshade.view import build_parser, open_viewer

from .conftest import SHARED_DATA
from .optional import optional_import

MESH = SHARED_DATA / "faust_reg" / "tr_reg_000.ply"


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
    assert np.array_equal(viewer.Vd, expected)  # what the window shows is SShaDe's result
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


_SCREENSHOTS = """
import sys
import numpy as np
import polyscope as ps
from sshade.view import build_parser, open_viewer
viewer = open_viewer(build_parser().parse_args(sys.argv[1:]), ps)  # polyscope's OpenGL backend
ps.set_ground_plane_mode("none")
ps.frame_tick()
ps.screenshot("before.png", transparent_bg=False)
T = viewer.gizmo.get_transform()
T[:3, 3] += MOVE
viewer.gizmo.set_transform(T)
ps.frame_tick()
ps.frame_tick()
ps.screenshot("after.png", transparent_bg=False)
print("solves", viewer.solves)
"""


def _screenshots(tmp_path, move) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run the viewer under Xvfb, drag the head's gizmo by ``move`` (3,) metres between two
    screenshots: (before, after) RGB images in [0, 1] and the selection's status."""
    import os
    import shutil
    import subprocess
    import sys
    if shutil.which("xvfb-run") is None:
        pytest.skip("xvfb-run not found on PATH (Debian: apt-get install xvfb xauth libgl1-mesa-dri); "
                    ".ci/run installs it and reruns the tests marked 'xvfb'")
    optional_import("polyscope")
    from matplotlib.image import imread
    _, _, status = _head_and_feet(tmp_path / "s.sel")
    (tmp_path / "shots.py").write_text(f"MOVE = {list(map(float, move))}\n{_SCREENSHOTS}")
    env = {**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1024x768x24", sys.executable, "shots.py", str(MESH),
                        "--sel", "s.sel", "--n-low", "300", "--k", "2"], cwd=tmp_path,
                       env=env, capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert r.returncode == 0 and "solves" in r.stdout, r.stdout + r.stderr
    return imread(tmp_path / "before.png")[..., :3], imread(tmp_path / "after.png")[..., :3], status


def _yellow_x(img: np.ndarray) -> float:
    """Mean column of the pixels in the handle points' colour (polyscope's yellow)."""
    m = (img[..., 0] > 0.75) & (img[..., 1] > 0.65) & (img[..., 2] < 0.4)
    assert m.sum() > 100
    return float(np.nonzero(m)[1].mean())


@pytest.mark.view
@pytest.mark.xvfb
def test_under_xvfb_a_dragged_gizmo_moves_the_rendered_head_and_not_the_feet(tmp_path):
    """The real window (polyscope's OpenGL backend on Xvfb with Mesa's software renderer):
    the head's handle points (drawn yellow) move right on screen when the gizmo moves the
    head 30 cm sideways, and the fixed feet (the bottom fifth) are drawn where they were."""
    before, after, _ = _screenshots(tmp_path, (0.3, 0.0, 0.0))
    assert _yellow_x(after) - _yellow_x(before) > 20  # pixels, to the right
    feet = slice(int(0.8 * before.shape[0]), before.shape[0])
    assert np.abs(before[feet] - after[feet]).max(axis=2).mean() < 0.01

"""sshade/view.py (``python -m sshade view``): a moved gizmo moves the mesh, through
polyscope's mock backend (no display); skips with one line without polyscope."""
from __future__ import annotations

import numpy as np
import pytest

from sshade.mesh.handle_files import write_sel
from sshade.mesh.io import read_mesh
from sshade.prepared import prepare
from sshade.view import build_parser, open_viewer

from .conftest import SHARED_DATA

MESH = SHARED_DATA / "faust_reg" / "tr_reg_000.ply"


@pytest.mark.view
def test_a_moved_gizmo_moves_the_handle_region_and_the_mesh_with_it(tmp_path, monkeypatch):
    ps = pytest.importorskip("polyscope", reason="polyscope (the [view] extra) is not installed")
    if not MESH.is_file():
        pytest.skip(f"FAUST registration not found: {MESH}")
    V, F = read_mesh(MESH)
    status = np.ones(len(V), int)
    status[V[:, 1] < np.quantile(V[:, 1], 0.1)] = 0
    status[V[:, 1] > np.quantile(V[:, 1], 0.95)] = 2
    write_sel(tmp_path / "s.sel", status)
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
    assert err == ["error: python -m sshade view needs polyscope: pip install 'sshade[view]'"]

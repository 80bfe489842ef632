"""Headless rendering (eval/present/render.py), case figures (eval/present/figures.py) and the
evaluator's optional figure hook (``figures.enabled``)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("matplotlib")
import matplotlib.image as mimage  # noqa: E402

from eval.config_check import check_config
from eval.metrics.measures import edge_length_error  # noqa: E402
from eval.present.figures import (  # noqa: E402
    POSE_TRANSFER_STYLE,
    ROW_STYLE,
    TOSCA_STYLE,
    case_figure,
    face_edge_error,
    mesh_row,
    pose_transfer_figure,
    safe_figure,
    tosca_figure,
    vertex_error_pct,
)
from eval.present.render import figure_row, png_size, render_mesh, save_png  # noqa: E402
from eval.present.render_style import RenderStyle  # noqa: E402
from sshade.errors import SShaDeError  # noqa: E402

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def sphere():
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=3, radius=1.0)  # 642 vertices, 1280 faces
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def _n_colours(img) -> int:
    return len(np.unique(np.asarray(img).reshape(-1, img.shape[-1]), axis=0))


def test_render_mesh_size_and_content(sphere, tmp_path):
    V, F = sphere
    img = render_mesh(V, F, style=RenderStyle(size=(200, 150)))
    assert img.shape == (150, 200, 3) and img.dtype == np.uint8
    assert _n_colours(img) > 20                       # shaded, not one flat colour
    assert (img == 255).all(axis=2).any()             # white background around the mesh
    assert (img.max(axis=2) < 240).mean() > 0.1       # the sphere covers a good part of it
    p = save_png(tmp_path / "sphere.png", img)
    back = mimage.imread(p)
    assert back.shape[:2] == (150, 200)
    assert png_size(p) == (200, 150)
    assert np.allclose(back[..., :3], img / 255.0, atol=1 / 255 + 1e-6)
    assert not list(tmp_path.glob(".*.tmp"))         # atomic write left no temporary file


def test_render_scalars_points_title_colorbar(sphere):
    V, F = sphere
    img = render_mesh(V, F, colors=V[:, 1], clim=(-1, 1), title="height", colorbar_label="y", points=V[:5],
                      point_colors="blue", style=RenderStyle(cmap="hot", size=(240, 200), view=(20, -60)))
    assert img.shape == (200, 240, 3)
    r, g, b = (img[..., i].astype(int) for i in range(3))
    assert ((r > 150) & (g < 80) & (b < 80)).any()    # red part of "hot"
    per_face = render_mesh(V, F, colors=V[F].mean(axis=1)[:, 0], style=RenderStyle(size=(64, 64)))
    assert per_face.shape == (64, 64, 3) and _n_colours(per_face) > 10


def test_render_hides_points_behind_the_surface(sphere):
    V, F = sphere
    style = RenderStyle(size=(120, 120), view=(0, -90), up="z", point_size=40)
    plain = render_mesh(V, F, style=style)
    # up="z", azim=-90: the viewer is on the -y side; +y points are on the far side
    back = V[V[:, 1] > 0.8]
    front = V[V[:, 1] < -0.8]
    assert np.array_equal(render_mesh(V, F, points=back, point_colors="red", style=style), plain)
    assert not np.array_equal(render_mesh(V, F, points=front, point_colors="red", style=style), plain)
    shown = render_mesh(V, F, points=back, point_colors="red", style=replace(style, hide_occluded_points=False))
    assert not np.array_equal(shown, plain)


def test_render_rejects_bad_input(sphere):
    V, F = sphere
    with pytest.raises(SShaDeError, match="shape"):
        render_mesh(V[:, :2], F)
    with pytest.raises(SShaDeError, match="out of range"):
        render_mesh(V, F + len(V))
    with pytest.raises(SShaDeError, match="colors"):
        render_mesh(V, F, colors=np.ones(7))
    with pytest.raises(SShaDeError, match="points"):
        render_mesh(V, F, points=np.ones((2, 2)))


def test_figure_row_layout(sphere, tmp_path):
    V, F = sphere
    a = render_mesh(V, F, style=RenderStyle(size=(100, 80)))
    b = render_mesh(V, F, colors=V[:, 2], style=RenderStyle(size=(120, 90)))
    p = figure_row([("a", a), {"image": b, "title": "b"}], tmp_path / "row.png",
                   colorbar={"cmap": "hot", "clim": (0, 1), "label": "err"})
    assert p.read_bytes()[:8] == PNG_SIGNATURE
    assert png_size(p) == (100 + 120 + 90, 90 + 28)
    img = mimage.imread(p)
    assert img.shape[:2] == (118, 310) and _n_colours(img) > 20


def test_face_edge_error_matches_metric(sphere):
    V, F = sphere
    Vd = V * np.array([1.3, 1.0, 0.8])
    e = face_edge_error(V, Vd, F)
    assert e.shape == (len(F),) and (e >= 0).all()
    # closed mesh: every edge in two faces, so the face mean equals the edge mean
    assert np.isclose(e.mean(), edge_length_error(V, Vd, F))
    assert np.allclose(face_edge_error(V, V + 0.5, F), 0.0)


def test_case_figure_png(sphere, tmp_path):
    V, F = sphere
    handles = np.array([0, 1, 2, 3, 10, 11])
    static = np.array([True, True, True, False, False, False])
    results = {"ARAP": V * [1.2, 1.0, 1.0], "SShaDe": V + 0.05 * np.sin(5 * V), "Broken": None}
    p = case_figure(V, F, results, handles, static, tmp_path / "figs" / "case.png", title="case",
                    style=replace(ROW_STYLE, size=(160, 200)))
    data = p.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    assert png_size(p) == (4 * 160 + 90, 200 + 28 + 28)
    img = mimage.imread(p)
    assert img.shape[:2] == (256, 730) and _n_colours(img) > 50
    with pytest.raises(SShaDeError):
        case_figure(V, F, results, handles, static[:2], tmp_path / "bad.png")


def test_vertex_error_pct_known_answer():
    Vgt = np.array([[0.0, 0, 0], [3, 0, 0], [0, 4, 0]])   # bounding-box diagonal 5
    Vd = Vgt + [[0.05, 0, 0], [0, 0, 0], [0, 0, 0.5]]
    np.testing.assert_allclose(vertex_error_pct(Vd, Vgt), [1.0, 0.0, 10.0])
    with pytest.raises(SShaDeError):
        vertex_error_pct(Vd[:2], Vgt)


def test_tosca_and_pose_transfer_figures(sphere, tmp_path):
    V, F = sphere
    pose = V * [1.0, 1.4, 0.8]
    pred = pose + 0.02 * np.sin(7 * V)
    p = tosca_figure(V, pose, pred, F, tmp_path / "tosca.png", title="t", style=replace(TOSCA_STYLE, size=(120, 150)))
    assert p.read_bytes()[:8] == PNG_SIGNATURE and png_size(p) == (3 * 120 + 90, 150 + 56)
    S = V * 1.1
    p = pose_transfer_figure(V, S, pose, pred * 1.1, pose * 1.1, F, tmp_path / "pt.png",
                             style=replace(POSE_TRANSFER_STYLE, size=(100, 150)))
    assert png_size(p) == (5 * 100 + 90, 150 + 28)
    img = mimage.imread(p)
    assert _n_colours(img) > 50


def test_mesh_row_without_values_has_no_colour_bar(sphere, tmp_path):
    V, F = sphere
    p = mesh_row([{"title": "a", "V": V, "F": F}, {"title": "failed", "V": None}], tmp_path / "r.png",
                 style=replace(ROW_STYLE, size=(100, 120)))
    assert png_size(p) == (2 * 100, 120 + 28)
    with pytest.raises(SShaDeError, match="no panel"):
        mesh_row([{"title": "x", "V": None}], tmp_path / "none.png")


def test_safe_figure_logs_instead_of_raising(sphere, tmp_path, caplog):
    V, F = sphere
    with caplog.at_level("WARNING", logger="eval"):
        assert safe_figure("bad", tosca_figure, V, V[:-1], V, F, tmp_path / "bad.png") is None
    assert "figure for bad failed" in caplog.text and not (tmp_path / "bad.png").exists()


def test_figures_options():
    """The door's ``figures`` (eval/config_check.py): off without the section, 4 cases by default."""
    from eval.run.spec import FigureOptions
    assert check_config({"methods": ["ARAP"]}).figures == FigureOptions(enabled=False, max_cases=4)
    assert check_config({"figures": {"enabled": False}}).figures.enabled is False
    assert check_config({"figures": {"enabled": True}}).figures == FigureOptions(enabled=True, max_cases=4)
    assert check_config({"figures": {"enabled": True, "max_cases": 2}}).figures == FigureOptions(True, 2)


def test_app_writes_case_figures(shared_data, tmp_path):
    """The evaluator hook: figures.enabled renders at most figures.max_cases cases."""
    root = shared_data / "faust_reg"
    if len(list(root.glob("tr_reg_00[0-9].ply"))) < 3:
        pytest.skip(f"FAUST subject 0 rest + two poses not found in {root}")
    from hydra import compose, initialize_config_dir

    from eval.app import CONF_DIR, run
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=[
            "dataset=faust", f"dataset.root={root}", "dataset.limit=2", "methods=[SShaDe]", "sshade.n_low=300",
            "sshade.n_samplings=1", f"out_dir={tmp_path / 'run'}", "++figures.enabled=true",
            "++figures.max_cases=1"])
    res = run(check_config(cfg))
    figs = sorted((res["out_dir"] / "figures").glob("*.png"))
    assert [f.name for f in figs] == ["s0_p1.png"]
    assert figs[0].read_bytes()[:8] == PNG_SIGNATURE
    w, h = png_size(figs[0])
    assert w == 2 * 320 + 90 and h == 480 + 56


# ---------------------------------------------------------------- "not run" vs "failed" panels

def _results(V):
    from eval.present.figures import NOT_RUN
    Vd = V.copy()
    Vd[:, 1] *= 1.1
    return {"ARAP": None, "Elastic": NOT_RUN, "SShaDe": Vd}


def test_case_panels_label_not_run_and_failed(sphere):
    from eval.present.figures import NOT_RUN, case_panels
    V, F = sphere
    panels = case_panels(V, F, _results(V), [0, 1], [True, False])
    titles = [p["title"] for p in panels]
    assert titles[:3] == ["rest + handles", "ARAP: failed", "Elastic: not run"]
    assert titles[3].startswith("SShaDe  (EL ")
    assert panels[1]["V"] is None and panels[2]["V"] is None and panels[3]["values"].shape == (len(F),)
    assert _results(V)["Elastic"] is NOT_RUN and NOT_RUN is not None  # "not run" is not "failed" (None)


def test_case_figure_with_a_not_run_method_writes_a_png(sphere, tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    import eval.present.figures as figs
    from eval.present.render import png_size
    V, F = sphere
    seen = []
    real = figs.mesh_row
    monkeypatch.setattr(figs, "mesh_row", lambda panels, path, **kw: seen.append(panels) or real(panels, path, **kw))
    p = figs.case_figure(V, F, _results(V), [0, 1], [True, False], tmp_path / "c.png", title="c",
                         style=replace(figs.ROW_STYLE, size=(120, 160)))
    assert p.is_file() and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png_size(p) == (4 * 120 + 90, 160 + 28 + 28)
    assert [q["title"] for q in seen[0]][1:3] == ["ARAP: failed", "Elastic: not run"]


def test_write_case_figure_marks_not_run_methods(tmp_path, monkeypatch):
    """eval.app passes the methods skipped by dataset.baseline_cases as ``not_run``."""
    import types

    import eval.present.figures as figs
    got = {}
    monkeypatch.setattr(figs, "case_figure", lambda V, F, results, *a, **kw: got.update(results) or "ok")
    case = types.SimpleNamespace(name="c7", V=None, F=None, handles=None, static=None)
    out = figs.write_case_figure(case, {"ARAP": None, "Elastic": None, "SShaDe": "Vd"}, tmp_path,
                                 not_run=["ARAP"])
    assert out == "ok"
    assert list(got) == ["ARAP", "Elastic", "SShaDe"]  # panel order kept
    assert got["ARAP"] is figs.NOT_RUN and got["Elastic"] is None and got["SShaDe"] == "Vd"

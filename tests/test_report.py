"""The browser report (eval/report.py, eval/present/meshview.py): index.html of a tiny evaluator
run (2 FAUST cases, a toy plug-in method and one that always fails), its tables parsed
with html.parser, the CLI's no-harm rules, the display decimation; and, when a
``chromium`` is on PATH, the page in headless Chromium (SwiftShader WebGL): no JS error,
the table rows in the DOM, both 3D views drawn, mesh pixels on the screenshot (mark
``browser``, through the ``chromium_on_path`` fixture: without one they skip with one line)."""
from __future__ import annotations

import csv
import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from eval.app import CONF_DIR, run_experiment
from eval.present.meshview import (
    case_view,
    cluster_decimate,
    cluster_means,
    cluster_positions,
    read_view,
    vertex_edge_error,
)
from eval.report import PAGE, chromium, main, screenshot, write_index, write_report
from eval.run.outdir import REPRODUCE_ENV, read_marker, results_dir
from eval.run.pending_rows import pending_on_other_data

METHODS = ["Mine", "NaNOutput"]


class _Tables(HTMLParser):
    """Rows (lists of cell texts) of every ``<table id=...>``, and the ``<script src>``s."""

    def __init__(self):
        super().__init__()
        self.tables, self.scripts, self.views = {}, [], []
        self._id, self._row, self._cell = None, None, None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table" and a.get("id"):
            self._id = a["id"]
            self.tables[self._id] = []
        elif tag == "tr" and self._id:
            self._row = []
        elif tag in ("td", "th") and self._row is not None:
            self._cell = ""
        elif tag == "script" and a.get("src"):
            self.scripts.append(a["src"])
        elif tag == "div" and "view" in (a.get("class") or "").split():
            self.views.append(a.get("data-case"))

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._cell is not None:
            self._row.append(self._cell.strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.tables[self._id].append(self._row)
            self._row = None
        elif tag == "table":
            self._id = None


def _parse(text: str) -> _Tables:
    p = _Tables()
    p.feed(text)
    return p


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, faust_root):
    """A finished evaluator run: 2 FAUST cases, ``Mine`` (5 Jacobi steps) and
    ``NaNOutput`` (fails on every case), a figure of the first case, 2 views."""
    from hydra import compose, initialize_config_dir
    out = tmp_path_factory.mktemp("report") / "run"
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=[
            "dataset=faust", f"dataset.root={faust_root}", "dataset.limit=2", "reference.cases=none",
            "methods=[{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:5},"
            "{_target_:tests.bad_methods.NaNOutput}]",
            "figures.enabled=true", "figures.max_cases=1", f"out_dir={out}"])
    run_experiment(cfg)
    return out


def test_page_tables_views_and_provenance(run_dir):
    text = (run_dir / PAGE).read_text()
    p = _parse(text)
    head, *rows = p.tables["main-table"]
    assert head[:3] == ["Method", "Cases", "Failed"] and "Volume (%)" in head
    assert [r[0] for r in rows] == METHODS
    assert [(r[1], r[2]) for r in rows] == [("2", "0"), ("0", "2")]  # cases averaged, failed runs
    assert "How each method stopped" in text and "NaNOutput: 2 of 2 cases failed" in text
    # the 3D views: one per case (report.view_cases=2), their data next to the page
    cases = json.loads((run_dir / "run.json").read_text())["seeds"]["cases"]
    assert p.views == list(cases)
    for src in p.scripts:
        assert (run_dir / src).is_file() and src.startswith("report/")
    view = read_view(run_dir / p.scripts[0])
    assert [m["label"] for m in view["meshes"]] == ["rest", "target (ground truth)", *METHODS]
    assert [m["kind"] for m in view["meshes"]] == ["rest", "target", "result", "failed"]
    assert view["meshes"][-1]["pos"] is None and view["n_vertices"] == 6890
    # breakdown, figure, provenance
    assert "breakdown-table" not in p.tables and "per pose" in text
    assert 'src="figures/' in text
    commit = json.loads((run_dir / "run.json").read_text())["git"]["commit"]
    prov = dict((r[0], r[1]) for r in p.tables["provenance-table"] if len(r) == 2)
    assert prov["git commit"] == commit and prov["dirty"] in ("True", "False") and "python" in prov
    assert "<summary>seeds</summary>" in text and "<summary>config</summary>" in text
    # sizes: the page itself is small, each view well under the cap
    assert (run_dir / PAGE).stat().st_size < 200_000
    assert all((run_dir / s).stat().st_size < 2_000_000 for s in p.scripts)
    assert PAGE in read_marker(run_dir)["files"]  # a later run into the folder replaces it


def test_cli_rewrites_a_run_and_refuses_other_folders(run_dir, tmp_path, monkeypatch, capsys):
    page = run_dir / PAGE
    page.write_text(page.read_text().replace("Main table", "OLD"))
    assert main([str(run_dir)]) == 0 and "OLD" not in page.read_text()
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("x")
    assert main([str(other)]) == 2 and not (other / PAGE).exists()  # no earlier evaluator output
    assert "not an earlier eval output" in capsys.readouterr().err
    assert main(["--index", str(tmp_path)]) == 2 and not (tmp_path / PAGE).exists()
    res = results_dir()
    if res is not None and (res / "faust").is_dir():
        monkeypatch.delenv(REPRODUCE_ENV, raising=False)
        before = sorted(p.name for p in (res / "faust").iterdir())
        assert main([str(res / "faust")]) == 2  # results/ only under eval.reproduce
        assert sorted(p.name for p in (res / "faust").iterdir()) == before
    assert main([]) == 2


def test_a_report_refuses_an_edited_cases_csv_and_leaves_out_a_fifo_or_a_deeply_nested_view(run_dir, tmp_path,
                                                                                             capsys):
    """``python -m eval.report`` on a copy of a run: a FIFO or a view nested 100,000 deep
    in place of a view file is left out, without blocking; a number edited in
    ``cases.csv`` is one error line naming the file and the row, and no page is made."""
    import os
    import shutil
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    views = sorted((run / "report").glob("*.js"))
    views[0].unlink()
    os.mkfifo(views[0])
    views[1].write_text("(window.SSHADE_VIEWS = window.SSHADE_VIEWS || {})[" + "[" * 100_000)
    rc = main([str(run)])
    assert rc == 0, capsys.readouterr().err
    cases = run / "cases.csv"
    rows = list(csv.DictReader(cases.open()))
    i, col = next((i, c) for i, r in enumerate(rows) for c in ("volume_err_pct", "edge_err_pct") if r.get(c))
    rows[i][col] = "0.000123"
    with cases.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    (run / PAGE).unlink()
    capsys.readouterr()
    rc, err = main([str(run)]), capsys.readouterr().err
    assert rc == 2 and not (run / PAGE).exists(), err
    errors = [ln for ln in err.splitlines() if ln.startswith("error: ")]  # log lines may come before it
    assert len(errors) == 1 and str(cases) in errors[0] and f"{col} 0.000123 in cases.csv" in errors[0], err


def test_a_page_written_by_someone_else_is_kept(tmp_path):
    (tmp_path / "run.json").write_text("{}")
    (tmp_path / PAGE).write_text("<html>my notes</html>")
    with pytest.raises(Exception, match="not written by"):
        write_report(tmp_path)
    assert (tmp_path / PAGE).read_text() == "<html>my notes</html>"


def test_index_links_every_run(run_dir):
    page = write_index(run_dir.parent)
    rows = _parse(page.read_text()).tables["runs-table"]
    assert rows[1][0] == "run" and f'href="run/{PAGE}"' in page.read_text()


def _sphere(level: int):
    """An icosphere subdivided ``level`` times (trimesh): 20 * 4**level faces."""
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=level)
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def test_cluster_decimate_keeps_correspondence_and_the_cap():
    V, F = _sphere(6)  # 81920 faces
    labels, G = cluster_decimate(V, F, 5000)
    c = int(labels.max()) + 1
    assert 2000 < len(G) <= 5000 and labels.shape == (len(V),) and G.max() < c
    assert (G[:, 0] != G[:, 1]).all() and len(np.unique(np.sort(G, 1), axis=0)) == len(G)
    P = cluster_positions(2 * V, labels, c)  # a scaled copy: the same clusters, scaled
    assert np.allclose(P, 2 * cluster_positions(V, labels, c))
    assert np.allclose(np.linalg.norm(cluster_positions(V, labels, c), axis=1), 1, atol=0.05)
    lab, G2 = cluster_decimate(V, F, len(F))  # nothing to do
    assert (G2 == F).all() and (lab == np.arange(len(V))).all()


def test_case_view_quantises_on_a_common_box():
    V, F = _sphere(5)
    view = case_view("s", V, F, {"rest": ("rest", V), "moved": ("result", V + 3.0), "x": ("failed", None)},
                     max_faces=2000)
    assert view["shown_faces"] <= 2000 and not view["idx32"] and view["meshes"][2]["pos"] is None
    import base64
    q = np.frombuffer(base64.b64decode(view["meshes"][1]["pos"]), "<u2").reshape(-1, 3)
    x = np.asarray(view["lo"]) + q * np.asarray(view["step"])
    assert q.shape == (view["clusters"], 3) and x.min() > 1.9 and x.max() < 4.1
    nbytes = sum(len(m["pos"] or "") for m in view["meshes"]) + len(view["faces"])
    assert nbytes < 4 / 3 * (6 * view["clusters"] * 2 + 6 * view["shown_faces"]) + 16


# ----------------------------------------------------------------------------- headless Chromium
def test_page_in_headless_chromium(chromium_on_path, run_dir):
    dom = chromium(run_dir / PAGE, "--dump-dom").stdout
    assert 'id="js-errors"' in dom, "chromium gave no DOM"
    box = re.search(r'<div id="js-errors"[^>]*>.*?</div>(?!\s*<div class="js-error")', dom, re.S).group(0)
    assert 'data-count="0"' in box, f"JavaScript errors: {box}"
    rows = _parse(dom).tables["main-table"][1:]
    assert [r[0] for r in rows] == METHODS
    assert re.search(r'id="views-status"[^>]*data-drawn="2"', dom), "the two 3D views were not drawn"


def test_js_errors_are_written_into_the_page(chromium_on_path, tmp_path):
    hook = (Path(__file__).resolve().parents[1] / "eval" / "report_assets" / "errors.js").read_text()
    page = tmp_path / "e.html"
    page.write_text(f'<html><head><script>{hook}</script></head><body><div id="js-errors" data-count="0" hidden>'
                    '</div><script>console.error("bad thing"); undefinedFunction();</script></body></html>')
    dom = chromium(page, "--dump-dom").stdout
    assert 'data-count="2"' in dom and "console.error: bad thing" in dom and "undefinedFunction" in dom


def test_screenshot_shows_the_meshes(chromium_on_path, run_dir, tmp_path):
    png = screenshot(run_dir / PAGE, tmp_path / "page.png", size=(1200, 1500), fragment="#mode=plain")
    from matplotlib.image import imread
    img = imread(png)[..., :3].astype(float)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    green = (g > r + 0.12) & (g > b + 0.12)  # the target mesh: nothing else on the page is green
    blue = (b > r + 0.2) & (b > 0.4) & (g > 0.3)  # the results (link text is thin)
    assert green.sum() > 2000, f"no target mesh drawn ({int(green.sum())} green pixels)"
    assert blue.sum() > 2000, f"no result mesh drawn ({int(blue.sum())} blue pixels)"


def test_views_are_coloured_by_edge_error_with_a_legend(chromium_on_path, run_dir, tmp_path):
    dom = chromium(run_dir / PAGE, "--dump-dom").stdout
    assert len(re.findall(r'<div class="view" [^>]*data-mode="edge"', dom)) == 2, "views not in edge-error mode"
    assert dom.count('class="view-ramp"') == 2 and "edge-length error, % of the longest rest edge" in dom
    assert 'data-mode="gt"' in dom  # the ground-truth toggle, where the case has a ground truth
    png = screenshot(run_dir / PAGE, tmp_path / "edge.png", size=(1200, 1500))
    from matplotlib.image import imread
    img = imread(png)[..., :3].astype(float)
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    low = (b > 0.55) & (r < 0.35)                 # the ramp's low end (blue)
    high = (r > 0.6) & (g > 0.5) & (b < 0.35)     # its upper half (yellow to red): where the error is large
    assert low.sum() > 2000 and high.sum() > 50, (int(low.sum()), int(high.sum()))


def test_case_view_colours_share_one_scale_per_case():
    V, F = _sphere(4)
    stretched = V * np.array([1.3, 1.0, 1.0])
    view = case_view("s", V, F, {"rest": ("rest", V), "target (ground truth)": ("target", V),
                                 "a": ("result", stretched), "b": ("result", V * 1.01)}, max_faces=2000)
    import base64
    vals = {m["label"]: m for m in view["meshes"]}
    assert vals["rest"]["edge"] is None and vals["rest"]["gt"] is None and vals["target (ground truth)"]["gt"] is None
    ea = np.frombuffer(base64.b64decode(vals["a"]["edge"]), np.uint8)
    eb = np.frombuffer(base64.b64decode(vals["b"]["edge"]), np.uint8)
    assert ea.shape == (view["clusters"],) and ea.mean() > 5 * eb.mean()  # one scale: b's 1 % is faint beside a
    e_max = view["scales"]["edge"]["max"]
    want = np.percentile(cluster_means(vertex_edge_error(V, stretched, F), *_labels(V, F, 2000)), 99)
    assert e_max == pytest.approx(want)
    et = np.frombuffer(base64.b64decode(vals["target (ground truth)"]["edge"]), np.uint8)
    assert et.max() == 0  # the target is the rest shape: no edge changes length
    assert view["scales"]["gt"]["legend"].startswith("distance to the ground truth")


def _labels(V, F, max_faces):
    labels, _ = cluster_decimate(V, F, max_faces)
    return labels, int(labels.max()) + 1


def test_vertex_edge_error_averages_to_the_table_metric_on_a_regular_mesh():
    from eval.metrics.measures import edge_length_error
    V, F = _sphere(3)
    X = V * np.array([1.2, 0.9, 1.0])
    per_vertex = vertex_edge_error(V, X, F)
    # every edge counted at its two ends: the valence-weighted mean of the per-vertex
    # values is the mean over edges, which is the table's EL
    from eval.metrics.meshes import unique_edges
    k = np.bincount(unique_edges(F, len(V)).ravel(), minlength=len(V))
    assert np.sum(per_vertex * k) / np.sum(k) == pytest.approx(edge_length_error(V, X, F), rel=1e-12)
    assert np.array_equal(vertex_edge_error(V, V, F), np.zeros(len(V)))
    assert vertex_edge_error(V, X, F, edges=unique_edges(F, len(V))).tobytes() == per_vertex.tobytes()


@pytest.mark.parametrize("bad, where", [("report.max_faces=0", "check"), ("report.view_cases=-1", "check"),
                                        ("report.enabled=maybe", "compose"), ("report.max_faces=1e9", "compose")])
def test_report_options_are_checked_before_any_work(bad, where):
    """A value of the wrong type is refused by Hydra as it composes (eval/config_schema.py),
    one out of range by the check at the door; each message names the key."""
    from hydra import compose, initialize_config_dir

    from eval.config_check import check_config
    from harness.command import config_error_types
    from sshade.errors import SShaDeError
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        check_config(compose(config_name="config", overrides=["dataset=faust", "dataset.root=x"]))
        if where == "compose":
            with pytest.raises(config_error_types(), match=bad.split("=")[0]):
                compose(config_name="config", overrides=["dataset=faust", "dataset.root=x", bad])
            return
        cfg = compose(config_name="config", overrides=["dataset=faust", "dataset.root=x", bad])
    with pytest.raises(SShaDeError, match=bad.split("=")[0]):
        check_config(cfg)


def test_a_click_on_a_header_sorts_the_table(chromium_on_path, tmp_path):
    assets = Path(__file__).resolve().parents[1] / "eval" / "report_assets"
    page = tmp_path / "t.html"
    page.write_text(
        f"<html><head><script>{(assets / 'errors.js').read_text()}</script></head><body>"
        '<div id="js-errors" data-count="0" hidden></div><table class="sortable" id="t"><thead><tr><th>Method</th>'
        '<th>Time</th></tr></thead><tbody><tr><td>A</td><td data-v="3.5">3.5</td></tr><tr><td>B</td>'
        '<td data-v="">--</td></tr><tr><td>C</td><td data-v="0.25">0.25</td></tr></tbody></table>'
        f"<script>{(assets / 'report.js').read_text()}</script><script>"  # after report.js's own listener:
        "document.addEventListener('DOMContentLoaded', function () {"
        "var th = document.querySelectorAll('#t th')[1]; var order = [];"
        "function names() { return Array.from(document.querySelectorAll('#t tbody td:first-child'))"
        ".map(c => c.textContent).join(''); }"
        "th.click(); order.push(names()); th.click(); order.push(names());"
        "document.body.setAttribute('data-order', order.join(',')); });</script></body></html>")
    dom = chromium(page, "--dump-dom").stdout
    assert re.search(r'<body[^>]*data-order="CAB,ACB"', dom), dom[-300:]  # ascending (no value last), descending
    assert re.search(r'id="js-errors" data-count="0"', dom)


@pytest.mark.slow  # about 50 s: every committed page opened; CI runs it with the slow tests or the browser ones
def test_committed_results_pages_open_in_headless_chromium(chromium_on_path):
    """The committed ``results/index.html`` and every page it links to (each folder's
    ``index.html``, written by ``python -m eval.reproduce``) load in headless Chromium
    without a JavaScript error, and every link of the index leads to something committed."""
    root = Path(__file__).resolve().parents[1] / "results"
    index = root / PAGE
    if not index.is_file():
        pytest.skip("no results/index.html in this checkout")
    links = re.findall(r'href="([^"#:]+)"', index.read_text())
    assert links, "results/index.html links to nothing"
    missing = [h for h in links if not (root / h).exists()]
    assert not missing, missing
    pages = [index, *sorted({(root / h).resolve() for h in links if h.endswith(PAGE)})]
    for page in pages:
        dom = chromium(page, "--dump-dom").stdout
        assert 'id="js-errors"' in dom, f"{page}: chromium gave no DOM"
        box = re.search(r'<div id="js-errors"[^>]*>.*?</div>(?!\s*<div class="js-error")', dom, re.S).group(0)
        assert 'data-count="0"' in box, f"{page}: JavaScript errors: {box}"


def _committed_run_pages() -> list:
    """The committed run folders whose page shows 3D views: ``(folder, the methods it
    ran, the view files the page loads)``. The methods: those of its run.json config,
    which a comparison's cases.csv (a ``method`` column) must hold every one of; an
    experiment of SShaDe alone (TOSCA, §4.2: no ``method`` column) ran SShaDe."""
    root = Path(__file__).resolve().parents[1] / "results"
    out = []
    for page in sorted(root.glob(f"*/{PAGE}")):
        run, cases = page.parent / "run.json", page.parent / "cases.csv"
        views = sorted(set(re.findall(r"\b(report/[\w.-]+\.js)\b", page.read_text().split('id="left-out"')[0])))
        if not (run.is_file() and cases.is_file() and views):
            continue
        with cases.open(newline="") as f:
            rows = csv.DictReader(f)
            ran = {row["method"] for row in rows} if "method" in (rows.fieldnames or ()) else {"SShaDe"}
        if ran != {"SShaDe"}:
            assert ran == set(json.loads(run.read_text())["config"]["methods"]), f"{page.parent.name}: {ran}"
        out.append((page.parent, sorted(ran), views))
    return out


def test_committed_results_pages_show_every_method_in_3d_coloured_by_edge_error():
    """Every committed run page's 3D views (the view cases of ``python -m eval.reproduce``)
    show every method of its run as a result mesh with its vertices, each carrying its
    per-vertex edge error (the colour; paper Fig. 4), and the ground-truth distance where
    the case has a ground truth (a method that failed or was not run would have no result
    panel); the page names no view "not stored"; a row the table lists as pending and made
    on other case data (an earlier build's mesh), whose vertices do not fit the case shown,
    has no result panel."""
    pages = _committed_run_pages()
    if not pages:
        pytest.skip("no committed run page with 3D views in this checkout")
    for folder, methods, views in pages:
        other = pending_on_other_data(folder)
        text = (folder / PAGE).read_text()
        assert "not stored" not in text, f"{folder.name}: a panel says not stored"
        for src in views:
            view = read_view(folder / src)
            results = {m["label"]: m for m in view["meshes"] if m["kind"] == "result"}
            expected = [m for m in methods if (view["case"], m) not in other]
            assert sorted(set(results) - {m for m in methods if (view["case"], m) in other}) == sorted(expected), \
                f"{folder.name}/{src}: panels {sorted(results)}"
            has_gt = any(m["kind"] == "target" for m in view["meshes"])
            for label, m in results.items():
                assert m["pos"] and m["edge"], f"{folder.name}/{src}: {label} has no vertices or no edge error"
                assert not has_gt or m["gt"], f"{folder.name}/{src}: {label} has no ground-truth distance"

# ----------------------------------------------------------------------------- only this run's outputs
def _faust_run(faust_root, out, *extra):
    """``run_experiment`` on FAUST with toy plug-in methods (``extra``: more overrides)."""
    from hydra import compose, initialize_config_dir
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        cfg = compose(config_name="config", overrides=[
            "dataset=faust", f"dataset.root={faust_root}", "reference.cases=none", "jobs=1", f"out_dir={out}",
            *extra])
    run_experiment(cfg)
    return _parse((out / PAGE).read_text()), (out / PAGE).read_text()


_MINE = "{_target_:tests.plugin_example.MyMethod,name:Mine,iterations:3}"


def test_a_resumed_run_with_fewer_cases_shows_only_its_cases(tmp_path, faust_root):
    out = tmp_path / "run"
    p, _ = _faust_run(faust_root, out, "dataset.limit=2", f"methods=[{_MINE}]")
    first, second = p.views
    p, text = _faust_run(faust_root, out, "dataset.limit=1", f"methods=[{_MINE}]", "resume=true")
    assert p.views == [first] and len(p.scripts) == 1  # the dropped case's view is neither shown nor loaded
    assert read_view(out / p.scripts[0])["case"] == first
    assert second not in text.split('id="left-out"')[0]  # named only in the list of what was left out
    assert re.search(rf"3D view report/{second}\.js left out: not of a case of this run", text)


def test_a_resumed_run_shows_restored_results_from_the_earlier_view_of_the_same_record(tmp_path, faust_root):
    """Every pair restored without its mesh (store.meshes=false): each panel is taken
    from the earlier view, which showed the same stored record (its key); one whose
    record was recomputed with another parameter is drawn fresh; none says not stored."""
    out = tmp_path / "run"
    other = "{_target_:tests.plugin_example.MyMethod,name:Other,iterations:%d}"
    p, _ = _faust_run(faust_root, out, "dataset.limit=1", f"methods=[{_MINE},{other % 2}]")
    (case,) = p.views
    before = read_view(out / "report" / f"{case}.js")
    p, text = _faust_run(faust_root, out, "dataset.limit=1", f"methods=[{_MINE},{other % 4}]", "resume=true")
    after = read_view(out / "report" / f"{case}.js")
    panels = {m["label"]: m for m in after["meshes"]}
    assert panels["Mine"]["carried"] and not panels["Other"]["carried"]
    assert all(m["pos"] for m in after["meshes"]) and "not stored" not in text
    old = {m["label"]: m for m in before["meshes"]}
    assert panels["Mine"]["key"] == old["Mine"]["key"] and panels["Other"]["key"] != old["Other"]["key"]
    def xyz(v, m):
        q = np.frombuffer(__import__("base64").b64decode(m["pos"]), "<u2").reshape(-1, 3)
        return np.asarray(v["lo"]) + q * np.asarray(v["step"])
    # the carried positions are the earlier ones, up to one quantisation step of either box
    tol = 2 * (np.asarray(before["step"]) + np.asarray(after["step"]))
    assert (np.abs(xyz(after, panels["Mine"]) - xyz(before, old["Mine"])) <= tol).all()


def test_an_earlier_view_of_another_record_is_not_carried():
    V, F = _sphere(3)
    first = case_view("s", V, F, {"rest": ("rest", V), "A": ("result", V * 1.1)}, max_faces=500, keys={"A": "k1"})
    later = case_view("s", V, F, {"rest": ("rest", V), "A": ("not stored", None)}, max_faces=500, keys={"A": "k2"},
                      earlier=first)
    assert later["meshes"][1]["pos"] is None and later["meshes"][1]["kind"] == "not stored"
    same = case_view("s", V, F, {"rest": ("rest", V), "A": ("not stored", None)}, max_faces=500, keys={"A": "k1"},
                     earlier=first)
    assert same["meshes"][1]["carried"] and same["meshes"][1]["kind"] == "result"
    other_clusters = case_view("s", V, F, {"rest": ("rest", V), "A": ("not stored", None)}, max_faces=200,
                               keys={"A": "k1"}, earlier=first)
    assert other_clusters["meshes"][1]["pos"] is None  # another decimation: nothing carried


def test_a_figure_not_redrawn_is_not_shown_as_current(tmp_path, faust_root):
    """A resume where one method runs again (another parameter) and the other is restored
    without its mesh (store.meshes=false): the case figure cannot be redrawn, so the
    earlier one is gone from the page (and the folder) and the page says why."""
    out = tmp_path / "run"
    other = "{_target_:tests.plugin_example.MyMethod,name:Other,iterations:%d}"
    opts = ("dataset.limit=1", "figures.enabled=true", "figures.max_cases=1", "figures.rerun_restored=false")
    p, text = _faust_run(faust_root, out, *opts, f"methods=[{_MINE},{other % 2}]")
    (case,) = p.views
    assert f'src="figures/{case}.png"' in text
    p, text = _faust_run(faust_root, out, *opts, f"methods=[{_MINE},{other % 4}]", "resume=true")
    assert f"figures/{case}.png" not in text.split('id="left-out"')[0]  # no img, no link: not shown
    assert not (out / "figures" / f"{case}.png").exists()  # the earlier run's figure removed
    assert f"figure of case {case} not redrawn: its restored runs of Mine have no stored mesh" in text
    assert "store.meshes=true keeps them" in text
    assert p.views == [case]  # the 3D view is redrawn, Mine's panel from the earlier view of its record
    meshes = read_view(out / p.scripts[0])["meshes"]
    assert [(m["kind"], m["carried"]) for m in meshes][-2:] == [("result", True), ("result", False)]


def test_a_restored_run_without_its_mesh_is_rerun_and_its_figure_shows_the_stored_vertices(tmp_path, faust_root,
                                                                                            monkeypatch):
    """The same resume with figures.rerun_restored (the default): Mine is run again
    after every pair, its vertices are the stored record's bit for bit (its output
    digest), so the figure is redrawn, stamped with both records, and the page says so.
    A rerun that gives other vertices (here: moved by a hundredth) draws nothing and
    says why."""
    from eval.experiments.cases import case_outputs
    from eval.present.figures import FIGURE_RECORDS
    from eval.present.render import png_text
    out = tmp_path / "run"
    other = "{_target_:tests.plugin_example.MyMethod,name:Other,iterations:%d}"
    opts = ("dataset.limit=1", "figures.enabled=true", "figures.max_cases=1")
    p, _ = _faust_run(faust_root, out, *opts, f"methods=[{_MINE},{other % 2}]")
    (case,) = p.views
    fig = out / "figures" / f"{case}.png"
    fig.unlink()  # no earlier figure of these records to keep
    p, text = _faust_run(faust_root, out, *opts, f"methods=[{_MINE},{other % 4}]", "resume=true")
    stamp = json.loads(png_text(fig)[FIGURE_RECORDS])
    mine = json.loads((out / "runs" / case / "Mine.json").read_text())
    assert stamp["records"]["Mine"] == mine["key"] and mine["mesh"] is None  # restored, no mesh stored
    assert f'src="figures/{case}.png"' in text
    assert re.search(rf"outputs of case {case}: Mine rerun \(\d+ s, the stored vertices bit for bit\)", text)
    fig.unlink()
    real = case_outputs.rerun_output
    monkeypatch.setattr(case_outputs, "rerun_output", lambda m, n, c, g: real(m, n, c, g) + 0.01)
    p, text = _faust_run(faust_root, out, *opts, f"methods=[{_MINE},{other % 4}]", "resume=true")
    assert not fig.exists() and f"figure of case {case} not redrawn" in text
    assert f"outputs of case {case}: its rerun of Mine gave other vertices than the stored run" in text


def test_a_resumed_run_keeps_the_figure_stamped_with_its_restored_records(tmp_path, faust_root):
    """Every pair restored without its mesh: the earlier figure, stamped with the records
    it shows, stays this run's figure, byte for byte (nothing is rerun); a figure whose
    stamp names other records (here: edited by hand) is removed when reruns are off, and
    redrawn from a rerun when they are on."""
    from eval.present.figures import FIGURE_RECORDS
    from eval.present.render import png_text, set_png_text
    out = tmp_path / "run"
    opts = ("dataset.limit=1", "figures.enabled=true", "figures.max_cases=1", f"methods=[{_MINE}]")
    p, _ = _faust_run(faust_root, out, *opts)
    (case,) = p.views
    fig = out / "figures" / f"{case}.png"
    stamp = json.loads(png_text(fig)[FIGURE_RECORDS])
    assert set(stamp["records"]) == {"Mine"} and stamp["records"]["Mine"] and stamp["not_run"] == []
    before = fig.read_bytes()
    p, text = _faust_run(faust_root, out, *opts, "resume=true")
    assert fig.read_bytes() == before and f'src="figures/{case}.png"' in text
    assert f"figure of case {case} kept from the earlier run: it shows the same stored records" in text
    set_png_text(fig, {FIGURE_RECORDS: json.dumps({**stamp, "records": {"Mine": "another record"}})})
    p, text = _faust_run(faust_root, out, *opts, "resume=true", "figures.rerun_restored=false")
    assert not fig.exists() and f"figure of case {case} not redrawn" in text
    p, text = _faust_run(faust_root, out, *opts, "resume=true")  # redrawn from a rerun of the stored vertices
    assert json.loads(png_text(fig)[FIGURE_RECORDS]) == stamp and f"outputs of case {case}: Mine rerun" in text


class _Links(HTMLParser):
    """Every ``href`` and ``src`` value of a page."""

    def __init__(self):
        super().__init__()
        self.targets = []

    def handle_starttag(self, tag, attrs):
        self.targets += [v for k, v in attrs if k in ("href", "src") and v is not None]


def _links(page: Path) -> list[str]:
    p = _Links()
    p.feed(page.read_text())
    return p.targets


def _assert_inside(page: Path, targets) -> None:
    """Each link of ``page`` a relative path to a file inside its folder (or an anchor)."""
    from urllib.parse import unquote, urlsplit
    base = page.parent.resolve()
    for t in targets:
        if t.startswith("#"):
            continue
        u = urlsplit(t)
        assert not u.scheme and not u.netloc and not u.query and not t.startswith("/"), t
        target = (base / unquote(u.path)).resolve()
        assert target.is_relative_to(base) and target.exists(), t


def test_links_are_relative_paths_inside_the_run_folder(run_dir, tmp_path):
    import shutil
    d = tmp_path / "run"
    shutil.copytree(run_dir, d, symlinks=True)
    for name in ("javascript:alert(1)", "javascript:alert(2).png", "data:text,x", "a b#c?d.txt"):
        (d / name).write_text("x")
    (d / "outside").symlink_to(tmp_path, target_is_directory=True)  # a link leaving the folder
    assert main([str(d)]) == 0
    targets = _links(d / PAGE)
    assert not [t for t in targets if re.match(r"\s*[a-z][a-z0-9+.-]*:", t, re.I)], targets  # no scheme at all
    _assert_inside(d / PAGE, targets)
    assert "javascript%3Aalert%281%29" in targets and "javascript%3Aalert%282%29.png" in targets
    assert not [t for t in targets if t.startswith("outside")]
    # the index of run folders: a folder named like a URL
    (tmp_path / "javascript:alert(3)").mkdir()
    (tmp_path / "javascript:alert(3)" / "run.json").write_text("{}")
    _assert_inside(write_index(tmp_path), _links(tmp_path / PAGE))
    # what the page's links go through: no path that leaves the folder is ever a link target
    from eval.present.report_scope import link_target
    for rel in ("../x", "a/../../x", "/etc/passwd", "//host/x", "a\\..\\x", "a\nb", "", "outside/x"):
        assert link_target(d, rel) is None, rel
    assert link_target(d, "figures/s0 p1.png") == "figures/s0%20p1.png"

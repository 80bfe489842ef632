"""Paper-style case figures: the rest mesh with its handles, then every method's result
coloured by the per-edge length error (paper Fig. 1 handle colours, Fig. "defaust-volume"
error colouring), rendered headless with :mod:`eval.present.render`.
Floor 2 of eval/ (eval/present/, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from eval.present.render import figure_row, render_mesh
from eval.present.render_style import ERROR_CMAP, RenderStyle
from eval.run.names import safe_name
from sshade.errors import SShaDeError
from sshade.isometric import rigid_align

__all__ = ["face_edge_error", "vertex_error_pct", "mesh_row", "case_figure", "case_panels", "tosca_figure",
           "pose_transfer_figure", "safe_figure", "write_case_figure", "case_figure_path",
           "ERROR_CMAP", "STATIC_COLOR", "DYNAMIC_COLOR", "TOSCA_VIEW", "NOT_RUN", "distribution_figure",
           "FIGURE_RECORDS", "ROW_STYLE", "POSE_TRANSFER_STYLE", "TOSCA_STYLE"]

log = logging.getLogger("eval")

#: PNG text keyword of a case figure's stamp: the store record key of each result it
#: shows (method name -> key) and the methods not run, as JSON; a resumed run keeps a
#: figure whose stamp equals its restored records (eval/experiments/cases/cases_experiment.py).
FIGURE_RECORDS = "sshade-records"

#: Handle colours of the paper's Fig. 1: static blue, dynamic yellow.
STATIC_COLOR = "#1f3fff"
DYNAMIC_COLOR = "#ffd000"
#: Camera for TOSCA (z-up data): a three-quarter view from the front-left, a little above.
TOSCA_VIEW = (15.0, -60.0)
#: The panels of :func:`mesh_row` and :func:`case_figure` when no style is given: 320 x 480
#: px, coloured with :data:`ERROR_CMAP`, the other fields
#: :class:`~eval.present.render_style.RenderStyle`'s defaults. Change a field with
#: :func:`dataclasses.replace`: ``replace(ROW_STYLE, view=(0, -90))``.
ROW_STYLE = RenderStyle(size=(320, 480), cmap=ERROR_CMAP)
#: The panels of :func:`pose_transfer_figure` when no style is given: :data:`ROW_STYLE` at 240 x 400 px.
POSE_TRANSFER_STYLE = replace(ROW_STYLE, size=(240, 400))
#: The panels of :func:`tosca_figure` when no style is given: :data:`ROW_STYLE` at 320 x 400
#: px, seen from :data:`TOSCA_VIEW` with z up.
TOSCA_STYLE = replace(ROW_STYLE, view=TOSCA_VIEW, up="z", size=(320, 400))


class _NotRun:
    """Type of :data:`NOT_RUN` (a singleton)."""

    _instance = None

    def __new__(cls):
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "NOT_RUN"

    def __reduce__(self):
        return (_NotRun, ())


#: Value of a method in :func:`case_figure`'s ``results`` that was not run on the case
#: (drawn "<name>: not run"), as opposed to ``None``, a method that ran and failed.
NOT_RUN = _NotRun()


def face_edge_error(V, Vd, F) -> np.ndarray:
    """Per-face edge length error in percent of the longest rest edge.

    For each face, the mean over its 3 edges of ``100 * |l - l'| / max_e l``; an edge
    shared by two faces has the same value in both (paper eq. (eq:edge-error) per edge).

    Raises SShaDeError on mismatched shapes, bad indices or all-zero rest edges.
    """
    V = np.asarray(V, np.float64)
    Vd = np.asarray(Vd, np.float64)
    F = np.asarray(F, np.int64)
    if V.shape != Vd.shape or V.ndim != 2 or V.shape[1] != 3:
        raise SShaDeError(f"face_edge_error: rest {V.shape} and deformed {Vd.shape} vertices must both be (n, 3)")
    if F.ndim != 2 or F.shape[1] != 3 or len(F) == 0 or F.min() < 0 or F.max() >= len(V):
        raise SShaDeError(f"face_edge_error: bad faces {F.shape} for {len(V)} vertices")
    a, b = F, np.roll(F, -1, axis=1)                       # edges (0,1), (1,2), (2,0)
    l0 = np.linalg.norm(V[a] - V[b], axis=2)
    l1 = np.linalg.norm(Vd[a] - Vd[b], axis=2)
    lmax = float(l0.max())
    if not lmax > 0:
        raise SShaDeError("face_edge_error: all rest edges have zero length")
    return 100.0 * np.abs(l0 - l1).mean(axis=1) / lmax


def vertex_error_pct(Vd, Vgt) -> np.ndarray:
    """Per-vertex distance ``||Vd - Vgt||`` in percent of ``Vgt``'s bounding-box diagonal.

    Vd, Vgt : (n, 3) float, in 1:1 correspondence. Returns (n,) float64 (the per-vertex
    values behind :func:`eval.metrics.measures.ground_truth_metrics`' ``gt_vertex_*_pct``).
    Raises SShaDeError on mismatched shapes or a zero diagonal.
    """
    Vd = np.asarray(Vd, np.float64)
    Vgt = np.asarray(Vgt, np.float64)
    if Vd.shape != Vgt.shape or Vd.ndim != 2 or Vd.shape[1] != 3:
        raise SShaDeError(f"vertex_error_pct: {Vd.shape} and {Vgt.shape} vertices must both be (n, 3)")
    diag = float(np.linalg.norm(Vgt.max(axis=0) - Vgt.min(axis=0)))
    if not diag > 0:
        raise SShaDeError("vertex_error_pct: the ground truth's bounding-box diagonal is 0")
    return 100.0 * np.linalg.norm(Vd - Vgt, axis=1) / diag


def mesh_row(panels: Sequence[Mapping], path, *, title: str | None = None, clim: float | None = None,
             colorbar_label: str = "error", style: RenderStyle | None = None) -> Path:
    """Render several meshes side by side on one framing and one colour scale, into a PNG.

    Parameters
    ----------
    panels : sequence of mappings, one per panel, with keys ``title`` (str), ``V``
        ((n, 3) vertices, or None for a failed item: an empty panel), ``F`` ((m, 3)),
        and optionally ``values`` ((m,) per-face or (n,) per-vertex scalars, drawn
        through the shared colour scale; absent = uniform grey), ``points`` ((k, 3)
        markers) and ``point_colors`` (one colour or k).
    path : output PNG (written atomically).
    title : line above the row. clim : upper end of the shared scale ``0 .. clim``
        (default: the largest 99th percentile of the panels' values; larger values are
        drawn in the top colour and the bar gets an arrow). colorbar_label : label of the
        shared bar (drawn only when a panel has values).
    style : :class:`eval.present.render_style.RenderStyle` of every panel (its ``size``:
        (w, h) px per panel; its ``cmap``: the shared scale's, bar included; its
        ``background``: the row's too), or None: :data:`ROW_STYLE`.

    Returns the path. The PNG is ``len(panels) * w (+ 90 with a colour bar)`` wide and
    ``h + 28 (+ 28 with title)`` high.

    Raises SShaDeError on malformed meshes or values (before anything is written).
    """
    style = ROW_STYLE if style is None else style
    cm = style.colormap()
    panel_w, panel_h = style.size
    vals = [None if p.get("V") is None or p.get("values") is None else np.asarray(p["values"], np.float64)
            for p in panels]
    finite = [v[np.isfinite(v)] for v in vals if v is not None]
    if clim is None:
        clim = max([float(np.percentile(v, 99)) for v in finite if len(v)] + [0.0])
    clim = float(clim) if clim and clim > 0 else 1.0
    extend = "max" if any(len(v) and v.max() > clim for v in finite) else "neither"
    meshes = [np.asarray(p["V"], np.float64) for p in panels if p.get("V") is not None]
    if not meshes:
        raise SShaDeError("mesh_row: no panel has a mesh")
    frame = np.concatenate([X[::max(1, len(X) // 5000)] for X in meshes])  # one framing for all panels
    kw = dict(style=style, frame=frame)
    images = []
    for p, v in zip(panels, vals):
        if p.get("V") is None:
            images.append((p.get("title", ""), np.full((panel_h, panel_w, 3), 255, np.uint8)))
            continue
        extra = {} if v is None else {"colors": v, "clim": (0.0, clim)}
        if p.get("points") is not None and len(p["points"]):
            extra.update(points=p["points"], point_colors=p.get("point_colors"))
        images.append((p.get("title", ""), render_mesh(np.asarray(p["V"], np.float64), p["F"], **extra, **kw)))
    bar = {"cmap": cm, "clim": (0.0, clim), "label": colorbar_label, "extend": extend} if finite else None
    return figure_row(images, path, title=title, colorbar=bar, background=style.background)


def case_figure(V_rest, F, results: Mapping, handles, static_mask, path, *, title: str | None = None,
                clim: float | None = None, style: RenderStyle | None = None) -> Path:
    """Render one deformation case into a PNG row: rest + handles, then each method's
    deformed mesh coloured by its per-face edge error (:func:`face_edge_error`).

    Parameters
    ----------
    V_rest : (n, 3) rest vertices; F : (m, 3) faces.
    results : method name -> (n, 3) deformed vertices, in panel order; ``None`` for a
        method that failed (drawn as an empty panel titled "<name>: failed");
        :data:`NOT_RUN` for a method that was not run on this case (an empty panel
        titled "<name>: not run").
    handles : (h,) handle vertex indices; static_mask : (h,) bool, True = static handle
        (drawn blue; dynamic ones yellow, paper Fig. 1).
    path : output PNG (written atomically).
    title : line above the row (e.g. the case name).
    clim : upper end of the shared colour scale in percent (default: the largest 99th
        percentile over the methods' face errors).
    style : :class:`eval.present.render_style.RenderStyle` of the panels (camera, (w, h)
        px per panel as ``size``, colormap, ...), or None: :data:`ROW_STYLE` (320 x 480 px,
        :data:`ERROR_CMAP`, a light-to-dark "hot").

    Returns the path. The PNG is ``(1 + len(results)) * w + 90`` px wide and
    ``h + 28`` (+ 28 with ``title``) px high.

    Raises SShaDeError on mismatched handles/flags or bad meshes.
    """
    panels = case_panels(V_rest, F, results, handles, static_mask)
    return mesh_row(panels, path, title=title, clim=clim, colorbar_label="edge error (% of max rest edge)",
                    style=style)


def case_panels(V_rest, F, results: Mapping, handles, static_mask) -> list[dict]:
    """The :func:`mesh_row` panels of :func:`case_figure` (same parameters).

    Returns
    -------
    list of ``1 + len(results)`` dicts: the rest mesh with its handles (``points``,
    ``point_colors``), then per method either its deformed mesh with the per-face edge
    error as ``values`` (title "<name>  (EL x.xx%)"), or an empty panel (``V`` None)
    titled "<name>: failed" (value ``None``) or "<name>: not run" (value :data:`NOT_RUN`).

    Raises SShaDeError on mismatched handles/flags or bad meshes.
    """
    V = np.asarray(V_rest, np.float64)
    F = np.asarray(F, np.int64)
    handles = np.asarray(handles, np.int64).ravel()
    static = np.asarray(static_mask, bool).ravel()
    if len(static) != len(handles):
        raise SShaDeError(f"case_figure: {len(handles)} handles but {len(static)} static flags")
    if len(handles) and (handles.min() < 0 or handles.max() >= len(V)):
        raise SShaDeError(f"case_figure: handle index out of range [0, {len(V)})")
    panels = [{"title": "rest + handles", "V": V, "F": F, "points": V[handles],
               "point_colors": list(np.where(static, STATIC_COLOR, DYNAMIC_COLOR))}]
    for name, Vd in results.items():
        if Vd is NOT_RUN:
            panels.append({"title": f"{name}: not run", "V": None})
            continue
        if Vd is None:
            panels.append({"title": f"{name}: failed", "V": None})
            continue
        e = face_edge_error(V, Vd, F)
        panels.append({"title": f"{name}  (EL {float(np.mean(e)):.2f}%)", "V": Vd, "F": F, "values": e})
    return panels


def tosca_figure(V_rest, V_true, V_pred, F, path, *, title: str | None = None, clim: float | None = None,
                 style: RenderStyle | None = None) -> Path:
    """TOSCA isometric case (paper §4.2, Fig. fig:tosca-isometric): rest pose M, true pose M', and
    SShaDe's reconstruction of M' coloured by the per-vertex error against M'
    (:func:`vertex_error_pct`, % of M''s bounding-box diagonal), one shared colour bar.

    V_rest, V_true, V_pred : (n, 3) in 1:1 correspondence; F : (m, 3) (the rest pose's).
    Other parameters as :func:`mesh_row`; ``style`` None: :data:`TOSCA_STYLE`. Returns
    the path; PNG ``3 * w + 90`` by ``h + 28 (+ 28)`` px. Raises SShaDeError on mismatched shapes.
    """
    e = vertex_error_pct(V_pred, V_true)
    panels = [{"title": "rest pose M", "V": V_rest, "F": F},
              {"title": "true pose M'", "V": V_true, "F": F},
              {"title": f"SShaDe (mean {float(e.mean()):.3f}%)", "V": V_pred, "F": F, "values": e}]
    return mesh_row(panels, path, title=title, clim=clim, colorbar_label="vertex error (% of diagonal)",
                    style=TOSCA_STYLE if style is None else style)


def pose_transfer_figure(M, S, M_pose, S_pred, S_true, F, path, *, title: str | None = None,
                         clim: float | None = None, style: RenderStyle | None = None) -> Path:
    """Pose transfer case (paper §4.3, Fig. fig:pose-transfer): the source M, M in the target
    pose M', the subject S, SShaDe's S in the target pose coloured by the per-vertex
    error against the ground truth, and the ground truth.

    M, S, M_pose, S_pred, S_true : (n, 3) in 1:1 correspondence, sharing F (m, 3).
    ``S_pred`` is drawn as given; its error is taken after moving it rigidly onto
    ``S_true`` (:func:`sshade.isometric.rigid_align`, as in the table). Other parameters
    as :func:`mesh_row`; ``style`` None: :data:`POSE_TRANSFER_STYLE`. Returns the path;
    PNG ``5 * w + 90`` by ``h + 28 (+ 28)`` px. Raises SShaDeError on mismatched shapes.
    """
    e = vertex_error_pct(rigid_align(np.asarray(S_pred, np.float64), np.asarray(S_true, np.float64)), S_true)
    panels = [{"title": "source M", "V": M, "F": F},
              {"title": "M in the pose (M')", "V": M_pose, "F": F},
              {"title": "subject S", "V": S, "F": F},
              {"title": f"SShaDe (mean {float(e.mean()):.2f}%)", "V": S_pred, "F": F, "values": e},
              {"title": "ground truth", "V": S_true, "F": F}]
    return mesh_row(panels, path, title=title, clim=clim, colorbar_label="vertex error (% of diagonal)",
                    style=POSE_TRANSFER_STYLE if style is None else style)


def safe_figure(name: str, draw, *args, **kwargs) -> Path | None:
    """Call a figure function; log and return None instead of raising, so a rendering
    problem never stops an experiment (figures are a by-product)."""
    try:
        path = draw(*args, **kwargs)
    except Exception as e:  # noqa: BLE001
        log.warning("figure for %s failed: %s: %s", name, type(e).__name__, e)
        return None
    log.info("figure %s", path)
    return path


def case_figure_path(fig_dir, name) -> Path:
    """``fig_dir/<name>.png``, the figure file of case ``name`` (:func:`write_case_figure`;
    the name through :func:`eval.run.names.safe_name`: never a path outside ``fig_dir``)."""
    return Path(fig_dir) / f"{safe_name(name)}.png"


def write_case_figure(case, results: Mapping, fig_dir, *, not_run=()) -> Path | None:
    """Evaluator hook: ``fig_dir/<case>.png`` (:func:`case_figure_path`) for one case
    (attributes ``name``, ``V``, ``F``, ``handles``, ``static``). Logs and returns None
    instead of raising, so a rendering problem never stops an evaluation.

    results : method name -> deformed vertices, ``None`` (failed) or :data:`NOT_RUN`, as
    :func:`case_figure`. not_run : names of methods not run on this case; their value
    becomes :data:`NOT_RUN` (panel "<name>: not run"), appended after ``results`` when
    absent from it.
    """
    results = {**dict(results), **{name: NOT_RUN for name in not_run}}
    return safe_figure(str(case.name), case_figure, case.V, case.F, results, case.handles, case.static,
                       case_figure_path(fig_dir, case.name), title=str(case.name))


def distribution_figure(df, path, *, metrics, methods=None, seed: int = 0) -> Path:
    """The per-case distribution of each metric per method: one panel per metric, a box
    (quartiles, whiskers at 1.5 IQR) per method with every case drawn over it as a dot
    (horizontal jitter from :func:`numpy.random.default_rng` (``seed``)).

    df : per-case rows (``method`` and the metric columns; successful rows only, the
    caller filters). metrics : sequence of (column, label). methods : the methods, in
    order (default: those of ``df``, sorted). Writes a PNG (matplotlib Agg, created
    folders); returns ``path``. Raises ValueError when no metric has a finite value.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    methods = list(methods) if methods is not None else sorted(df["method"].unique())
    panels = []
    for col, label in metrics:
        data = [np.asarray(df.loc[df["method"] == m, col], dtype=float) for m in methods]
        data = [x[np.isfinite(x)] for x in data]
        if any(len(x) for x in data):
            panels.append((label, data))
    if not panels:
        raise ValueError("no metric with a finite value to draw")
    rng = np.random.default_rng(seed)
    fig = Figure(figsize=(3.2 * len(panels), 3.4), dpi=120)
    FigureCanvasAgg(fig)
    for k, (label, data) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1)
        pos = [i + 1 for i, x in enumerate(data) if len(x)]
        ax.boxplot([x for x in data if len(x)], positions=pos, widths=0.6, showfliers=False)
        for i, x in enumerate(data):
            ax.plot(i + 1 + rng.uniform(-0.15, 0.15, len(x)), x, "o", ms=3, alpha=0.6, color="#d62728")
        ax.set_xticks(range(1, len(methods) + 1), methods, rotation=45, ha="right", fontsize=8)
        ax.set_xlim(0.4, len(methods) + 0.6)
        ax.set_title(label, fontsize=9)
        ax.tick_params(axis="y", labelsize=8)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path

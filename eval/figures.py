"""Paper-style case figures: the rest mesh with its handles, then every method's result
coloured by the per-edge length error (paper Fig. 1 handle colours, Fig. "defaust-volume"
error colouring), rendered headless with :mod:`eval.render`.

- :func:`face_edge_error`: per-face edge error of paper eq. (eq:edge-error): for every
  edge ``|l - l'| / max_e l`` (rest length ``l``, deformed ``l'``, normalised by the
  longest rest edge), in percent, spread to the faces as the mean over each face's 3
  edges (so the mean over edges of the face values is close to the table's
  ``edge_err_pct``).
- :func:`case_figure`: one PNG per case: panel 1 the rest mesh with static handles in
  blue and dynamic handles in yellow, then one panel per method, all on one scale and
  framing, with one shared colour bar (``0 .. clim``; default: the largest 99th
  percentile of the methods' face errors, values above drawn in the top colour).
- :func:`write_case_figure`: what the evaluator calls for a case (``figures.enabled``
  in the config, see ``docs/sweeps.md``); never raises, logs a warning instead.
"""
from __future__ import annotations

import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError

from .render import DEFAULT_VIEW, figure_row, render_mesh

__all__ = ["face_edge_error", "case_figure", "write_case_figure", "figures_options", "ERROR_CMAP",
           "STATIC_COLOR", "DYNAMIC_COLOR"]

log = logging.getLogger("eval")

#: Handle colours of the paper's Fig. 1: static blue, dynamic yellow.
STATIC_COLOR = "#1f3fff"
DYNAMIC_COLOR = "#ffd000"
#: Error colours: matplotlib's "hot", reversed (low error light, high error dark red to
#: black) and cut before pure white so the shading of error-free regions stays readable.
ERROR_CMAP = "sshade_hot"


def _error_cmap():
    import matplotlib
    from matplotlib.colors import ListedColormap
    if ERROR_CMAP not in matplotlib.colormaps:
        cm = matplotlib.colormaps["hot_r"]
        matplotlib.colormaps.register(ListedColormap(cm(np.linspace(0.12, 1.0, 256)), name=ERROR_CMAP))
    return matplotlib.colormaps[ERROR_CMAP]


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


def case_figure(V_rest, F, results: Mapping, handles, static_mask, path, *, title: str | None = None,
                view=DEFAULT_VIEW, up: str = "y", panel_size=(320, 480), clim: float | None = None,
                cmap=None) -> Path:
    """Render one case into a PNG row: rest + handles, then each method's deformed mesh.

    Parameters
    ----------
    V_rest : (n, 3) rest vertices; F : (m, 3) faces.
    results : method name -> (n, 3) deformed vertices, in panel order; ``None`` for a
        method that failed (drawn as an empty panel titled "<name>: failed").
    handles : (h,) handle vertex indices; static_mask : (h,) bool, True = static handle.
    path : output PNG (written atomically).
    title : line above the row (e.g. the case name).
    view, up : camera, see :func:`eval.render.render_mesh`.
    panel_size : (w, h) pixels per mesh panel.
    clim : upper end of the shared colour scale in percent (default: the largest 99th
        percentile over the methods' face errors).
    cmap : colormap (default :data:`ERROR_CMAP`, a light-to-dark "hot").

    Returns the path. The PNG is ``(1 + len(results)) * panel_w + 90`` px wide and
    ``panel_h + 28`` (+ 28 with ``title``) px high.
    """
    V = np.asarray(V_rest, np.float64)
    F = np.asarray(F, np.int64)
    handles = np.asarray(handles, np.int64).ravel()
    static = np.asarray(static_mask, bool).ravel()
    if len(static) != len(handles):
        raise SShaDeError(f"case_figure: {len(handles)} handles but {len(static)} static flags")
    if len(handles) and (handles.min() < 0 or handles.max() >= len(V)):
        raise SShaDeError(f"case_figure: handle index out of range [0, {len(V)})")
    cm = cmap if cmap is not None else _error_cmap()
    errs: dict[str, np.ndarray | None] = {}
    for name, Vd in results.items():
        errs[name] = None if Vd is None else face_edge_error(V, Vd, F)
    finite = [e[np.isfinite(e)] for e in errs.values() if e is not None]
    if clim is None:
        clim = max([float(np.percentile(e, 99)) for e in finite if len(e)] + [0.0])
    clim = float(clim) if clim and clim > 0 else 1.0
    extend = "max" if any(len(e) and e.max() > clim for e in finite) else "neither"

    # one framing for every panel: all meshes (subsampled) in one box
    step = max(1, len(V) // 5000)
    frame = np.concatenate([V[::step]] + [np.asarray(Vd, np.float64)[::step]
                                          for Vd in results.values() if Vd is not None])
    kw = dict(view=view, up=up, size=panel_size, frame=frame)
    pcol = np.where(static, STATIC_COLOR, DYNAMIC_COLOR) if len(handles) else None
    panels = [("rest + handles", render_mesh(V, F, points=V[handles] if len(handles) else None,
                                            point_colors=list(pcol) if pcol is not None else None, **kw))]
    for name, Vd in results.items():
        if Vd is None:
            panels.append((f"{name}: failed", np.full((panel_size[1], panel_size[0], 3), 255, np.uint8)))
            continue
        e = errs[name]
        panels.append((f"{name}  (EL {float(np.mean(e)):.2f}%)",
                       render_mesh(np.asarray(Vd, np.float64), F, colors=e, cmap=cm, clim=(0.0, clim), **kw)))
    return figure_row(panels, path, title=title,
                      colorbar={"cmap": cm, "clim": (0.0, clim), "label": "edge error (% of max rest edge)",
                                "extend": extend})


def figures_options(cfg) -> tuple[bool, int]:
    """``(enabled, max_cases)`` from ``cfg.figures``; a missing key means disabled."""
    fig = cfg.get("figures", None) if cfg is not None else None
    if not fig:
        return False, 0
    enabled = bool(fig.get("enabled", False))
    max_cases = fig.get("max_cases", 4)
    return enabled, int(4 if max_cases is None else max_cases)


def write_case_figure(case, results: Mapping, fig_dir) -> Path | None:
    """Evaluator hook: ``fig_dir/<case.name>.png`` for one case (attributes ``name``,
    ``V``, ``F``, ``handles``, ``static``). Logs and returns None instead of raising, so
    a rendering problem never stops an evaluation."""
    path = Path(fig_dir) / f"{case.name}.png"
    try:
        case_figure(case.V, case.F, results, case.handles, case.static, path, title=str(case.name))
    except Exception as e:  # noqa: BLE001 -- figures are a by-product
        log.warning("figure for %s failed: %s: %s", case.name, type(e).__name__, e)
        return None
    log.info("figure %s", path)
    return path

"""Headless mesh rendering with matplotlib (Agg): shaded triangle meshes as RGB arrays.
Floor 2 of eval/ (eval/present/, tests/test_layering.py); notes: docs/implementation.md.

No display and no ``pyplot`` state: every image is drawn on its own
:class:`matplotlib.figure.Figure` with a :class:`~matplotlib.backends.backend_agg.FigureCanvasAgg`,
so this works on servers, in Hydra jobs and in worker processes whatever
``MPLBACKEND`` says.

Example::

    img = render_mesh(V, F, colors=err, clim=(0, 5), style=RenderStyle(view=(20.0, -60.0), size=(320, 480)))
    save_png("out.png", img)"""
from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from eval.present.render_style import RenderStyle
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.mesh.validate import check_arrays

__all__ = ["render_mesh", "save_png", "figure_row", "face_scalars", "png_size", "png_text", "set_png_text"]

_DPI = 100
_GREY = (0.80, 0.80, 0.82)
_BAD = (0.55, 0.55, 0.55)        # NaN scalars
_TITLE_PX = 28                    # band on top of an image for its title
_CBAR_PX = 90                     # width of a colour bar (bar + ticks + label)


# ----------------------------------------------------------------------------- helpers
def _mpl():
    """Import matplotlib for off-screen drawing (never touches pyplot or the display)."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    return matplotlib, Figure, FigureCanvasAgg


def _points(X, what: str) -> np.ndarray:
    try:
        X = np.asarray(X, dtype=np.float64).reshape(-1, 3)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"render: {what} must be (k, 3) coordinates ({e})") from None
    if not np.isfinite(X).all():
        raise SShaDeError(f"render: {what} has NaN/inf coordinates")
    return X


def _to_plot(P: np.ndarray, up: str) -> np.ndarray:
    """Data coordinates -> matplotlib's z-up coordinates."""
    if up == "z":
        return P
    if up == "y":  # (x, y, z) -> (x, -z, y): +y up, +z towards the default viewer
        return np.stack([P[:, 0], -P[:, 2], P[:, 1]], axis=1)
    raise SShaDeError(f"render: up must be 'y' or 'z', got {up!r}")


def _camera(view) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(eye direction, screen right, screen up) in plot coordinates for (elev, azim)."""
    el, az = np.deg2rad(float(view[0])), np.deg2rad(float(view[1]))
    eye = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    right = np.array([-np.sin(az), np.cos(az), 0.0])
    upv = np.cross(eye, right)
    return eye, right, upv


def _canvas_rgb(fig, canvas, w: int, h: int) -> np.ndarray:
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    if img.shape[:2] != (h, w):  # guard against rounding of figsize * dpi
        out = np.full((h, w, 3), 255, np.uint8)
        hh, ww = min(h, img.shape[0]), min(w, img.shape[1])
        out[:hh, :ww] = img[:hh, :ww]
        img = out
    return img


def face_scalars(values, F, n_vertices: int) -> np.ndarray:
    """Per-face values from per-face ``(m,)`` or per-vertex ``(n,)`` scalars (vertex values
    are averaged over each face's 3 corners). A length equal to both m and n is taken
    as per-face."""
    c = np.asarray(values, dtype=np.float64)
    F = np.asarray(F)
    if c.ndim != 1:
        raise SShaDeError(f"render: scalar colors must be 1-D, got shape {c.shape}")
    if len(c) == len(F):
        return c
    if len(c) == n_vertices:
        return c[F].mean(axis=1)
    raise SShaDeError(f"render: colors has {len(c)} values; expected {len(F)} (faces) or {n_vertices} (vertices)")


def _norm_clim(vals: np.ndarray, clim):
    if clim is not None:
        lo, hi = float(clim[0]), float(clim[1])
    else:
        fin = vals[np.isfinite(vals)]
        lo, hi = (float(fin.min()), float(fin.max())) if len(fin) else (0.0, 1.0)
    if not hi > lo:
        hi = lo + (abs(lo) * 1e-6 or 1e-12)
    return lo, hi


def _get_cmap(cmap):
    import matplotlib
    return matplotlib.colormaps[cmap] if isinstance(cmap, str) else cmap


def _base_colors(colors, F, n: int, cmap, clim):
    """-> (m, 3) RGB per face, and (cmap, lo, hi) when scalars were mapped (else None)."""
    m = len(F)
    if colors is None:
        return np.tile(np.asarray(_GREY), (m, 1)), None
    c = np.asarray(colors)
    if c.ndim == 2 and c.shape[1] in (3, 4):  # explicit RGB(A), per face or per vertex
        c = c[:, :3].astype(np.float64)
        if c.max(initial=0) > 1.0:
            c = c / 255.0
        if len(c) == m:
            return np.clip(c, 0, 1), None
        if len(c) == n:
            return np.clip(c[F].mean(axis=1), 0, 1), None
        raise SShaDeError(f"render: RGB colors have {len(c)} rows; expected {m} (faces) or {n} (vertices)")
    vals = face_scalars(c, F, n)
    lo, hi = _norm_clim(vals, clim)
    cm = _get_cmap(cmap)
    t = np.clip((vals - lo) / (hi - lo), 0.0, 1.0)
    rgb = cm(np.nan_to_num(t, nan=0.0))[:, :3]
    rgb[~np.isfinite(vals)] = _BAD
    return rgb, (cm, lo, hi)


def _lambert(P: np.ndarray, F: np.ndarray, light: np.ndarray, ambient: float) -> np.ndarray:
    n = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])
    ln = np.linalg.norm(n, axis=1)
    ok = ln > 0
    n[ok] /= ln[ok, None]
    d = np.abs(n @ light)  # two-sided: orientation-agnostic
    d[~ok] = 0.0
    return ambient + (1.0 - ambient) * d


def _point_rgba(point_colors, k: int) -> np.ndarray:
    """One colour or k colours (names, RGB(A) rows) -> (k, 4) RGBA."""
    from matplotlib.colors import to_rgba_array
    try:
        c = to_rgba_array("tab:blue" if point_colors is None else point_colors)
    except (TypeError, ValueError) as e:
        raise SShaDeError(f"render: bad point_colors ({e})") from None
    if len(c) == 1:
        return np.repeat(c, k, axis=0)
    if len(c) != k:
        raise SShaDeError(f"render: {len(c)} point colors for {k} points")
    return c


def _visible_points(pts: np.ndarray, P: np.ndarray, F: np.ndarray, eye, right, upv) -> np.ndarray:
    """Which points are not covered by the surface (coarse depth grid over vertices and
    face centroids; a point is visible when it is within a few edge lengths of the
    front-most surface sample of its cell)."""
    e = P[F[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)]
    h = float(np.median(np.linalg.norm(e[:, 0] - e[:, 1], axis=1)))
    if not h > 0:
        return np.ones(len(pts), bool)
    S = np.concatenate([P, P[F].mean(axis=1)])
    cell = 1.5 * h
    sx, sy, sd = S @ right, S @ upv, S @ eye
    x0, y0 = sx.min(), sy.min()
    nx = int((sx.max() - x0) / cell) + 1
    ny = int((sy.max() - y0) / cell) + 1
    idx = (((sx - x0) / cell).astype(np.int64) * ny + ((sy - y0) / cell).astype(np.int64))
    front = np.full(nx * ny, -np.inf)
    np.maximum.at(front, idx, sd)
    px = np.clip(((pts @ right - x0) / cell).astype(np.int64), 0, nx - 1)
    py = np.clip(((pts @ upv - y0) / cell).astype(np.int64), 0, ny - 1)
    return pts @ eye >= front[px * ny + py] - 3.0 * h


# ----------------------------------------------------------------------------- public API
def render_mesh(V, F, *, colors=None, clim=None, points=None, point_colors=None, title: str | None = None,
                colorbar_label: str | None = None, frame=None, style: RenderStyle | None = None) -> np.ndarray:
    """Render a triangle mesh off-screen; returns an ``(h, w, 3)`` uint8 RGB image.

    Parameters
    ----------
    V : (n, 3) float vertices; F : (m, 3) int triangles.
    colors : None (uniform grey), ``(m,)`` per-face or ``(n,)`` per-vertex scalars
        (vertex values averaged per face) mapped through the style's ``cmap`` over
        ``clim`` (default: data min..max; NaN drawn grey), or ``(m|n, 3|4)`` RGB(A) in [0, 1].
    clim : (lo, hi) or None.
    points : (k, 3) marker positions (e.g. handles), drawn on top of the surface;
        those the surface hides are left out unless the style's ``hide_occluded_points``
        is False.
    point_colors : one colour or k colours (names, RGB rows).
    title : text above the mesh. colorbar_label : when given (and colors are scalars),
        a colour bar with this label is drawn on the right.
    frame : optional (k, 3) points to frame instead of the mesh (pass the same points to
        several renders, e.g. all meshes of a figure row, to give them one common scale
        and position).
    style : :class:`eval.present.render_style.RenderStyle` or None (its defaults): the
        camera (``view``, ``up``), the image's ``size`` (width, height) in pixels,
        ``cmap``, ``point_size``, ``hide_occluded_points``, ``ambient``, ``fill`` and
        ``background``.

    Raises
    ------
    SShaDeError on malformed V/F/colors/points.
    """
    V, F = check_arrays(V, F, name="render")
    st = RenderStyle() if style is None else style
    w, h = st.size
    view, up, background = st.view, st.up, st.background
    _, Figure, FigureCanvasAgg = _mpl()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: F401  (registers projection)

    P = _to_plot(V, up)
    eye, right, upv = _camera(view)
    light = eye + 0.45 * upv - 0.35 * right
    light /= np.linalg.norm(light)
    base, mapped = _base_colors(colors, F, len(V), st.colormap(), clim)
    rgb = np.clip(base * _lambert(P, F, light, st.ambient)[:, None], 0.0, 1.0)

    fig = Figure(figsize=(w / _DPI, h / _DPI), dpi=_DPI, facecolor=background)
    canvas = FigureCanvasAgg(fig)
    show_cbar = mapped is not None and colorbar_label is not None
    top = 1.0 - (_TITLE_PX / h if title else 0.0)
    right_edge = 1.0 - (min(_CBAR_PX, w // 3) / w if show_cbar else 0.0)
    rect = (0.0, 0.0, right_edge, top)
    ax = fig.add_axes(rect, projection="3d", facecolor=background)
    ax.set_axis_off()
    Q = _to_plot(_points(frame, "frame"), up) if frame is not None else P
    if len(Q) == 0:
        Q = P
    lo, hi = Q.min(axis=0), Q.max(axis=0)
    span = hi - lo
    pad = np.maximum(span, 1e-6 * max(float(span.max()), 1e-12))
    mid = (lo + hi) / 2
    ax.set_xlim(mid[0] - pad[0] / 2, mid[0] + pad[0] / 2)
    ax.set_ylim(mid[1] - pad[1] / 2, mid[1] + pad[1] / 2)
    ax.set_zlim(mid[2] - pad[2] / 2, mid[2] + pad[2] / 2)
    ax.set_proj_type("ortho")
    ax.view_init(elev=float(view[0]), azim=float(view[1]))
    _fit(ax, canvas, Q, pad, rect, w, h, st.fill)
    coll = Poly3DCollection(P[F], facecolors=rgb, edgecolors="none", linewidths=0.0, antialiased=False)
    coll.set_clip_on(False)  # the fitted mesh may extend past mplot3d's square axes box
    ax.add_collection3d(coll)

    if points is not None:
        pts = _to_plot(_points(points, "points"), up)
        pc = _point_rgba(point_colors, len(pts))
        keep = (_visible_points(pts, P, F, eye, right, upv) if st.hide_occluded_points and len(pts)
                else np.ones(len(pts), bool))
        pc = pc[keep]
        s = st.point_size if st.point_size is not None else max(4.0, (min(w, h) / 120.0) ** 2)
        if keep.any():
            ax.computed_zorder = False
            coll.set_zorder(1)
            ax.scatter(pts[keep, 0], pts[keep, 1], pts[keep, 2], c=pc, s=s, depthshade=False,
                       edgecolors="black", linewidths=0.3, zorder=5, clip_on=False)

    if title:
        fig.text(0.5, 1.0 - 0.5 * _TITLE_PX / h, str(title), ha="center", va="center", fontsize=11)
    if show_cbar:
        _colorbar(fig, *mapped, colorbar_label, rect=(right_edge + 0.12 * (1 - right_edge),
                                                      0.12, 0.2 * (1 - right_edge), top - 0.2))
    return _canvas_rgb(fig, canvas, w, h)


def _projected_bbox(ax, canvas, P):
    from mpl_toolkits.mplot3d import proj3d
    canvas.draw()  # lays out the (still empty) 3D axes: cheap
    x, y, _ = proj3d.proj_transform(P[:, 0], P[:, 1], P[:, 2], ax.get_proj())
    pix = ax.transData.transform(np.column_stack([x, y]))
    return pix.min(axis=0), pix.max(axis=0)


def _fit(ax, canvas, P, box, rect, w: int, h: int, fill: float) -> None:
    """Zoom and shift the 3D axes so the projected mesh fills ``fill`` of ``rect`` (in
    figure fractions) and is centred in it (orthographic: the projection is linear, so
    one measurement per step suffices)."""
    ax.set_box_aspect(tuple(box), zoom=1.0)
    lo, hi = _projected_bbox(ax, canvas, P)
    ext = np.maximum(hi - lo, 1e-9)
    avail = np.array([rect[2] * w, rect[3] * h])
    zoom = fill * float(np.min(avail / ext))
    ax.set_box_aspect(tuple(box), zoom=zoom)
    lo, hi = _projected_bbox(ax, canvas, P)
    centre = np.array([(rect[0] + rect[2] / 2) * w, (rect[1] + rect[3] / 2) * h])
    d = centre - (lo + hi) / 2
    ax.set_position((rect[0] + d[0] / w, rect[1] + d[1] / h, rect[2], rect[3]))


def _colorbar(fig, cmap, lo, hi, label, rect, extend="neither"):
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    cax = fig.add_axes(rect)
    cb = fig.colorbar(ScalarMappable(norm=Normalize(lo, hi), cmap=_get_cmap(cmap)), cax=cax, extend=extend)
    if label:
        cb.set_label(str(label), fontsize=9)
    cb.ax.tick_params(labelsize=8)
    return cb


def _png_bytes(fig, canvas) -> bytes:
    buf = io.BytesIO()
    canvas.print_png(buf)
    return buf.getvalue()


def _write_bytes(path, data: bytes) -> Path:
    path = Path(path)
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    return path


def save_png(path, image) -> Path:
    """Write an ``(h, w, 3|4)`` image (uint8, or float in [0, 1]) as PNG, atomically
    (temporary file beside ``path``, then rename). Returns the path."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.shape[0] < 1 or img.shape[1] < 1:
        raise SShaDeError(f"save_png: image must have shape (h, w, 3|4), got {img.shape}")
    if img.dtype != np.uint8:
        img = (np.clip(np.asarray(img, np.float64), 0.0, 1.0) * 255 + 0.5).astype(np.uint8)
    import matplotlib.image as mimage
    buf = io.BytesIO()
    mimage.imsave(buf, img, format="png")
    return _write_bytes(path, buf.getvalue())


def png_size(path) -> tuple[int, int]:
    """(width, height) from a PNG file's header; raises SShaDeError if it is not a PNG."""
    with open(path, "rb") as fh:
        head = fh.read(24)
    if len(head) < 24 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        raise SShaDeError(f"not a PNG file: {path}")
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _png_chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    """(type, payload) of every chunk of the PNG ``data``; SShaDeError when it is not one
    (bad signature, a truncated chunk, a wrong CRC, no IEND at the end)."""
    import zlib
    if data[:8] != _PNG_SIGNATURE:
        raise SShaDeError("not a PNG file")
    chunks, i = [], 8
    while i < len(data):
        if i + 12 > len(data):
            raise SShaDeError("truncated PNG chunk")
        n, kind = int.from_bytes(data[i:i + 4], "big"), data[i + 4:i + 8]
        body, crc = data[i + 8:i + 8 + n], data[i + 8 + n:i + 12 + n]
        if len(crc) != 4 or zlib.crc32(kind + body) != int.from_bytes(crc, "big"):
            raise SShaDeError(f"damaged PNG chunk {kind!r}")
        chunks.append((kind, body))
        i += 12 + n
    if not chunks or chunks[-1][0] != b"IEND":
        raise SShaDeError("PNG file without its IEND chunk")
    return chunks


def png_text(path) -> dict[str, str]:
    """The ``tEXt`` chunks of the PNG file ``path``, keyword -> text (Latin-1, as the PNG
    specification defines them). Raises SShaDeError when the file is not a whole PNG,
    OSError when it cannot be read."""
    out = {}
    for kind, body in _png_chunks(Path(path).read_bytes()):
        if kind == b"tEXt" and b"\0" in body:
            key, text = body.split(b"\0", 1)
            out[key.decode("latin-1")] = text.decode("latin-1")
    return out


def set_png_text(path, texts: Mapping[str, str]) -> Path:
    """Rewrite the PNG file ``path`` (atomically) with a ``tEXt`` chunk per item of
    ``texts`` (keyword: 1-79 Latin-1 characters; text: Latin-1), replacing chunks of the
    same keywords; the image itself is unchanged. Returns the path.

    Raises SShaDeError for a keyword or text that PNG cannot hold, or a file that is not
    a whole PNG; OSError when it cannot be read or written.

    Example::

        set_png_text("case.png", {"sshade-records": json.dumps(keys)})
        png_text("case.png")["sshade-records"]
    """
    import zlib
    new = []
    for key, text in texts.items():
        try:
            k, t = str(key).encode("latin-1"), str(text).encode("latin-1")
        except UnicodeEncodeError as e:
            raise SShaDeError(f"set_png_text: not Latin-1: {e}") from None
        if not 1 <= len(k) <= 79 or b"\0" in k or b"\0" in t:
            raise SShaDeError(f"set_png_text: bad keyword {key!r}")
        new.append((b"tEXt", k + b"\0" + t))
    keys = {body.split(b"\0", 1)[0] for _, body in new}
    chunks = [(kind, body) for kind, body in _png_chunks(Path(path).read_bytes())
              if not (kind == b"tEXt" and body.split(b"\0", 1)[0] in keys)]
    chunks[-1:-1] = new  # before IEND
    data = _PNG_SIGNATURE + b"".join(len(body).to_bytes(4, "big") + kind + body
                                     + zlib.crc32(kind + body).to_bytes(4, "big") for kind, body in chunks)
    return _write_bytes(path, data)


def _panel(p) -> tuple[np.ndarray, str | None]:
    if isinstance(p, Mapping):
        return np.asarray(p["image"]), p.get("title")
    if isinstance(p, tuple) and len(p) == 2 and isinstance(p[0], (str, type(None))):
        return np.asarray(p[1]), p[0]
    return np.asarray(p), None


def figure_row(panels: Sequence, path, *, title: str | None = None, colorbar: Mapping | None = None,
               background="white") -> Path:
    """Put images side by side (pixel-exact, no resampling) into one PNG, atomically.

    Parameters
    ----------
    panels : images ``(h, w, 3|4)``, ``(title, image)`` pairs or ``{"image", "title"}`` dicts.
    path : output PNG.
    title : optional line above the whole row.
    colorbar : optional ``{"cmap", "clim": (lo, hi), "label", "extend"}``: one shared colour
        bar at the right end of the row.

    The PNG is ``sum(panel widths) + colour bar`` wide and ``max(panel heights)`` plus a
    title band (28 px when any panel has a title, again for ``title``) high.
    Returns the path.
    """
    items = [_panel(p) for p in panels]
    if not items:
        raise SShaDeError("figure_row: no panels")
    for img, _ in items:
        if img.ndim != 3 or img.shape[2] not in (3, 4):
            raise SShaDeError(f"figure_row: panel images must have shape (h, w, 3|4), got {img.shape}")
    _, Figure, FigureCanvasAgg = _mpl()
    ph = max(img.shape[0] for img, _ in items)
    band = _TITLE_PX if any(t for _, t in items) else 0
    sup = _TITLE_PX if title else 0
    cbw = _CBAR_PX if colorbar else 0
    W = sum(img.shape[1] for img, _ in items) + cbw
    H = ph + band + sup
    fig = Figure(figsize=(W / _DPI, H / _DPI), dpi=_DPI, facecolor=background)
    canvas = FigureCanvasAgg(fig)
    x = 0
    for img, t in items:
        ih, iw = img.shape[:2]
        if img.dtype != np.uint8:
            img = (np.clip(img.astype(np.float64), 0, 1) * 255 + 0.5).astype(np.uint8)
        fig.figimage(img, xo=x, yo=(ph - ih) // 2, origin="upper")  # y from the bottom
        if t:
            fig.text((x + iw / 2) / W, (ph + band / 2) / H, str(t), ha="center", va="center", fontsize=11)
        x += iw
    if title:
        fig.text(0.5, 1.0 - sup / 2 / H, str(title), ha="center", va="center", fontsize=12, weight="bold")
    if colorbar:
        clim = colorbar.get("clim", (0.0, 1.0))
        _colorbar(fig, colorbar.get("cmap", "hot"), float(clim[0]), float(clim[1]), colorbar.get("label"),
                  rect=((x + 0.12 * cbw) / W, 0.12 * ph / H, 0.2 * cbw / W, 0.76 * ph / H),
                  extend=colorbar.get("extend", "neither"))
    canvas.draw()
    return _write_bytes(path, _png_bytes(fig, canvas))

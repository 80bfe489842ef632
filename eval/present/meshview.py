"""Display meshes for the HTML report (:mod:`eval.report`): one case's rest mesh, its
target (ground truth) and every method's result, decimated and quantised for a small
file, written next to the report as a script the page loads from ``file://``.
Floor 2 of eval/ (eval/present/, tests/test_layering.py); notes: docs/implementation.md.

Size: about ``4/3 * (6 * clusters * meshes + (2 or 4) * 3 * faces)`` bytes per case
(clusters ~ faces / 2); 30000 faces and 7 meshes: about 1.6 MB."""
from __future__ import annotations

import base64
import json
import logging
import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from eval.metrics.meshes import unique_edges
from eval.run.jsonsafe import json_safe
from eval.run.names import safe_name
from eval.run.spec import ReportOptions
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.json_file import read_bounded, read_json

__all__ = ["VIEW_DIR", "OUTPUTS", "DEFAULT_MAX_FACES", "DEFAULT_VIEW_CASES", "COLOUR_MODES", "cluster_decimate",
           "cluster_positions", "cluster_means", "vertex_edge_error", "case_view",
           "OTHER_DATA_KIND", "case_view_path", "write_case_view", "read_view", "write_outputs", "read_outputs"]

log = logging.getLogger("eval")

VIEW_DIR = "report"  #: the views' folder inside a run folder (next to index.html)
DEFAULT_MAX_FACES = ReportOptions.max_faces    #: faces shown per mesh unless ``report.max_faces`` says otherwise
DEFAULT_VIEW_CASES = ReportOptions.view_cases  #: cases with a 3D view unless ``report.view_cases`` says otherwise
#: What a panel says of a restored row made on an earlier build's mesh (a pending row on
#: other case data: its vertices, if stored, do not fit the case shown).
OTHER_DATA_KIND = "pending: made on an earlier build's mesh"
#: The per-vertex quantities a view colours its meshes by (:func:`case_view`): key -> legend.
COLOUR_MODES = {"edge": "edge-length error, % of the longest rest edge (paper Fig. 4)",
                "gt": "distance to the ground truth, % of the bounding-box diagonal"}
#: Percentile of the per-cluster values that sets a case's colour scale (one per case and
#: quantity, shared by its meshes); larger values show saturated.
SCALE_PERCENTILE = 99.0
OUTPUTS = "outputs.json"  #: in VIEW_DIR: the per-case views and figures the run wrote (write_outputs)
#: The largest view file read back (bytes): a view of 8 meshes of ``max_faces`` faces is
#: a few MiB at the default, about 100 MiB at 2 million faces each.
MAX_VIEW_BYTES = 512 * 2**20


def cluster_decimate(V, F, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering of the mesh ``(V, F)`` down to at most ``max_faces`` faces.

    Parameters
    ----------
    V : (n, 3) float, the rest vertices (the clusters are cells of a grid over them).
    F : (m, 3) int, faces. max_faces : int >= 1.

    Returns
    -------
    labels : (n,) int64, each vertex's cluster in ``0 .. c-1``.
    faces : (k, 3) int64 over the clusters, ``k <= max_faces``, no face with a repeated
        cluster, each kept once (orientation of its first occurrence). Without
        decimation (``m <= max_faces``): ``arange(n)`` and ``F``.

    Raises SShaDeError on bad shapes or indices, or ``max_faces < 1``.
    """
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or len(F) == 0:
        raise SShaDeError(f"cluster_decimate: need (n, 3) vertices and (m, 3) faces, got {V.shape}, {F.shape}")
    if F.min() < 0 or F.max() >= len(V) or int(max_faces) < 1:
        raise SShaDeError(f"cluster_decimate: bad faces for {len(V)} vertices or max_faces {max_faces!r}")
    if len(F) <= max_faces:
        return np.arange(len(V)), F
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1).sum()
    lo = V.min(axis=0)
    h = math.sqrt(2.0 * max(area, 1e-300) / max_faces)  # a grid triangulation of spacing h: ~2 A / h^2 faces
    for _ in range(30):
        cells = np.floor((V - lo) / h).astype(np.int64)
        dims = cells.max(axis=0) + 1
        _, labels = np.unique((cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2], return_inverse=True)
        labels = labels.reshape(-1)
        G = labels[F]
        G = G[(G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 2] != G[:, 0])]
        S, c = np.sort(G, axis=1), int(labels.max()) + 1  # c < 2**21 here: the key fits in int64
        _, first = np.unique((S[:, 0] * c + S[:, 1]) * c + S[:, 2], return_index=True)
        G = G[np.sort(first)]
        if len(G) <= max_faces:
            return labels, G
        h *= max(1.05, 1.02 * math.sqrt(len(G) / max_faces))
    raise SShaDeError(f"cluster_decimate: could not reach {max_faces} faces")  # pragma: no cover


def cluster_positions(X, labels, n_clusters: int) -> np.ndarray:
    """(c, 3) float64: the mean of ``X`` (n, 3) over each cluster of ``labels`` (n,);
    a cluster without vertices (never from :func:`cluster_decimate`) at 0."""
    return cluster_means(X, labels, n_clusters)


def cluster_means(x, labels, n_clusters: int) -> np.ndarray:
    """(c,) or (c, d) float64: the mean of the values ``x`` (n,) or (n, d) over each
    group of ``labels`` (n,) int in ``0 .. c-1``; 0 for a group without members."""
    x = np.asarray(x, np.float64)
    cnt = np.maximum(np.bincount(labels, minlength=n_clusters), 1)
    if x.ndim == 1:
        return np.bincount(labels, x, minlength=n_clusters) / cnt
    return np.stack([np.bincount(labels, x[:, k], minlength=n_clusters) / cnt for k in range(x.shape[1])], axis=1)


def vertex_edge_error(V, X, F, *, edges=None) -> np.ndarray:
    """(n,) float64 per-vertex edge-length error in % of the longest rest edge: the mean,
    over the vertex's incident edges, of ``| ||u - v|| - ||u' - v'|| | / max_e ||e||`` (the
    per-edge term of paper eq. (eq:edge-error), whose mean over all edges is
    :func:`eval.metrics.measures.edge_length_error`). ``V``, ``X``: (n, 3) rest and deformed
    vertices; ``F``: (m, 3) faces; ``edges``: (e, 2) int64 ``unique_edges(F, len(V))``
    when the caller has them (None: found here). An isolated vertex gets 0; all rest edges
    of length 0 give zeros.

    >>> V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> np.round(vertex_edge_error(V, 2 * V, np.array([[0, 1, 2]])), 4)  # edges 1, sqrt2, 1 over sqrt2
    array([70.7107, 85.3553, 85.3553])
    """
    E = unique_edges(np.asarray(F, np.int64), len(V)) if edges is None else edges
    l0 = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    l1 = np.linalg.norm(X[E[:, 0]] - X[E[:, 1]], axis=1)
    lmax = float(l0.max()) if len(l0) else 0.0
    e = 100.0 * np.abs(l1 - l0) / lmax if lmax > 0 else np.zeros(len(E))
    return cluster_means(np.repeat(e, 2), E.ravel(), len(V))  # each edge at both its ends


def _colour_values(V, F, meshes: Mapping, pos: dict, labels, c: int, carried=None) -> tuple[dict, dict]:
    """Per-cluster colour values of the shown meshes and one scale per quantity
    (:data:`COLOUR_MODES`): ``({label: {mode: (c,) values}}, {mode: {"max", "legend"}})``.
    ``edge`` for the target and the results; ``gt`` for the results when a target is shown
    (the distance of each vertex to its ground-truth position, same connectivity);
    ``carried``: label -> the values of a panel taken from an earlier view."""
    target = next((X for _l, (k, X) in meshes.items() if k == "target" and X is not None), None)
    diag = float(np.linalg.norm(np.ptp(np.asarray(V, np.float64), axis=0))) or 1.0
    vals: dict = dict(carried or {})
    E = None  # the rest mesh's edges, found once for every mesh shown
    for label, (kind, X) in meshes.items():
        if label not in pos or kind not in ("target", "result"):
            continue
        X = np.asarray(X, np.float64)
        E = unique_edges(np.asarray(F, np.int64), len(V)) if E is None else E
        v = {"edge": cluster_means(vertex_edge_error(V, X, F, edges=E), labels, c)}
        if target is not None and kind == "result":
            v["gt"] = cluster_means(100.0 * np.linalg.norm(X - target, axis=1) / diag, labels, c)
        vals[label] = v
    scales = {}
    for mode, legend in COLOUR_MODES.items():
        top = [float(np.percentile(v[mode], SCALE_PERCENTILE)) for v in vals.values() if mode in v]
        if top:
            scales[mode] = {"max": max(max(top), 1e-12), "legend": legend}
    return vals, scales


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).astype(a.dtype.newbyteorder("<")).tobytes()).decode("ascii")


def _carried(earlier, meshes: Mapping, keys: Mapping, faces: str, c: int, aliases: Mapping) -> dict:
    """Panels of an ``earlier`` view of the same case (:func:`read_view`) for the meshes
    restored without their vertices (kind ``not stored``): ``{label: (P (c, 3) cluster
    positions, {quantity: (c,) values})}`` for each whose earlier panel shows the same
    stored record (its ``key`` equals ``keys[label]``, or ``aliases[label]``: the key that
    record had before it was re-keyed) on the same clusters (the same ``faces``, ``c``
    clusters); nothing else is taken from it."""
    if not isinstance(earlier, Mapping) or earlier.get("faces") != faces or earlier.get("clusters") != c:
        return {}
    try:
        lo, step = np.asarray(earlier["lo"], np.float64), np.asarray(earlier["step"], np.float64)
        scales = earlier.get("scales") or {}
        old = {m["label"]: m for m in earlier["meshes"] if isinstance(m, Mapping) and m.get("pos")}
        out = {}
        for label, (kind, X) in meshes.items():
            m = old.get(label)
            if (X is not None or kind != "not stored" or m is None or not keys.get(label)
                    or m.get("key") not in (keys[label], aliases.get(label))):
                continue
            q = np.frombuffer(base64.b64decode(m["pos"]), "<u2").reshape(-1, 3)
            vals = {k: np.frombuffer(base64.b64decode(m[k]), np.uint8) / 255.0 * float(scales[k]["max"])
                    for k in COLOUR_MODES if m.get(k) and k in scales}
            if len(q) == c and all(len(v) == c for v in vals.values()):
                out[label] = (lo + q * step, vals)
        return out
    except (KeyError, TypeError, ValueError):
        return {}


def case_view(name: str, V, F, meshes: Mapping, *, max_faces: int = DEFAULT_MAX_FACES, keys=None,
              earlier=None, aliases=None) -> dict:
    """The view of one case (module docstring).

    Parameters
    ----------
    name : the case's name. V : (n, 3) rest vertices. F : (m, 3) faces.
    meshes : label -> ``(kind, X)`` in panel order, ``kind`` one of ``rest``, ``target``,
        ``result`` (colours), ``X`` (n, 3) vertices, or None with ``kind`` the text
        shown instead (``failed``, ``not run``, ``not stored``,
        :data:`OTHER_DATA_KIND`).
    max_faces : faces shown (:func:`cluster_decimate`).
    keys : mapping label -> the store record key of that result (each panel keeps its
        ``key``), or None.
    earlier : the case's earlier view (:func:`read_view`) or None: a ``not stored``
        mesh whose record key it shows on the same clusters is taken from it (its
        panel's ``carried`` is true) instead of being left out (:func:`_carried`).
    aliases : mapping label -> the key that result's record had before it was re-keyed
        (shown by an earlier view under that key), or None.

    Returns a JSON-able dict: ``case``, ``n_vertices``, ``n_faces`` (the mesh's),
    ``shown_faces``, ``clusters``, ``idx32``, ``faces`` (base64), ``lo`` / ``step`` (the
    quantisation: ``x = lo + q * step``), ``meshes`` (``label``, ``kind``, ``pos``
    base64 ``uint16`` or None, and per colour quantity of :data:`COLOUR_MODES` the
    per-cluster values as base64 ``uint8``, ``255 * value / scale max`` clipped, or None),
    ``scales`` (quantity -> ``max`` (the case's :data:`SCALE_PERCENTILE` percentile over
    its meshes, one scale for all of them) and ``legend``). Raises SShaDeError on bad
    shapes, or when no mesh has finite vertices.
    """
    labels, G = cluster_decimate(V, F, max_faces)
    c = int(labels.max()) + 1
    idx32 = c > 65535
    faces = _b64(G.astype(np.uint32 if idx32 else np.uint16))
    keys = dict(keys or {})
    carried = _carried(earlier, meshes, keys, faces, c, dict(aliases or {}))
    pos = {label: P for label, (P, _) in carried.items()}
    for label, (_kind, X) in meshes.items():
        if X is None:
            continue
        X = np.asarray(X, np.float64)
        if X.shape != np.shape(V):
            raise SShaDeError(f"case_view: {label} has {X.shape} vertices, the rest mesh {np.shape(V)}")
        P = cluster_positions(X, labels, c)
        if np.isfinite(P).all():
            pos[label] = P
    if not pos:
        raise SShaDeError(f"case_view: no mesh of {name} to show")
    allp = np.concatenate(list(pos.values()))
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    step = np.where(hi > lo, (hi - lo) / 65535.0, 1.0)
    vals, scales = _colour_values(np.asarray(V, np.float64), F, meshes, pos, labels, c,
                                  {label: v for label, (_, v) in carried.items()})
    out = []
    for label, (kind, _) in meshes.items():
        q = None
        if label in pos:
            q = _b64(np.clip(np.rint((pos[label] - lo) / step), 0, 65535).astype(np.uint16))
        m = {"label": str(label), "kind": "result" if label in carried else str(kind), "pos": q,
             "key": keys.get(label), "carried": label in carried}
        for mode in COLOUR_MODES:
            v = vals.get(label, {}).get(mode)
            m[mode] = None if v is None else _b64(np.clip(np.rint(255 * v / scales[mode]["max"]), 0, 255)
                                                   .astype(np.uint8))
        out.append(m)
    return {"case": str(name), "n_vertices": int(len(V)), "n_faces": int(len(F)), "shown_faces": int(len(G)),
            "clusters": c, "idx32": bool(idx32), "faces": faces,
            "lo": json_safe(lo), "step": json_safe(step), "scales": scales, "meshes": out}


_PREFIX = "(window.SSHADE_VIEWS = window.SSHADE_VIEWS || {})["


def read_view(path) -> dict:
    """The view (:func:`case_view`'s dict) in a file :func:`write_case_view` wrote, read
    as untrusted input (a regular file of at most :data:`MAX_VIEW_BYTES`). Raises
    ValueError when the file is not such a view (nested too deeply included), OSError
    when unreadable, not a regular file or too large."""
    text = read_bounded(path, MAX_VIEW_BYTES).decode("utf-8")
    if not text.startswith(_PREFIX):
        raise ValueError(f"{path} is not a view file")
    dec = json.JSONDecoder()
    try:
        _, i = dec.raw_decode(text, len(_PREFIX))
        if not text.startswith("] = ", i):
            raise ValueError(f"{path} is not a view file")
        view, _ = dec.raw_decode(text, i + 4)
    except RecursionError:
        raise ValueError(f"{path} is not a view file (nested too deeply)") from None
    if not isinstance(view, dict) or "meshes" not in view or "case" not in view:
        raise ValueError(f"{path} is not a view file")
    return view


def case_view_path(run_dir, name) -> Path:
    """``run_dir/report/<name>.js``, the view file of case ``name`` (:func:`write_case_view`;
    the name through :func:`eval.run.names.safe_name`)."""
    return Path(run_dir) / VIEW_DIR / f"{safe_name(name)}.js"


def write_case_view(case, results: Mapping, run_dir, *, not_run=(), max_faces: int = DEFAULT_MAX_FACES,
                    stored=(), other_data=(), keys=None, aliases=None) -> Path | None:
    """``run_dir/report/<case>.js`` for one evaluated case (attributes ``name``, ``V``,
    ``F``, optional ``V_gt``): panels rest, target (when the case has a ground truth),
    then every method of ``results`` (name -> deformed vertices (n, 3), or None: failed;
    names in ``not_run``: not run; in ``stored``: restored without a mesh, shown from the
    earlier view file when it shows the same record; in ``other_data``: a pending row made
    on an earlier build's mesh, :data:`OTHER_DATA_KIND`; ``keys``: name -> store record key,
    ``aliases``: name -> the key its record had before it was re-keyed, :func:`case_view`).
    Returns the path, or None after a logged warning (a view never stops an evaluation)."""
    meshes = {"rest": ("rest", case.V)}
    if getattr(case, "V_gt", None) is not None:
        meshes["target (ground truth)"] = ("target", case.V_gt)
    for n, U in results.items():
        kind = ("not run" if n in not_run else OTHER_DATA_KIND if n in other_data else "not stored" if n in stored
                else "failed")
        meshes[str(n)] = ("result", U) if U is not None else (kind, None)
    for n in not_run:
        meshes.setdefault(str(n), ("not run", None))
    p = case_view_path(run_dir, case.name)
    earlier = None
    if stored and keys:
        try:
            earlier = read_view(p)
        except (OSError, ValueError):
            earlier = None
    try:
        view = case_view(case.name, case.V, case.F, meshes, max_faces=max_faces, keys=keys, earlier=earlier,
                         aliases=aliases)
        p.parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps(view, separators=(",", ":"))
        with atomic_write(p, "w") as fh:
            fh.write(f"{_PREFIX}{json.dumps(str(case.name))}] = {text};\n")
    except (SShaDeError, OSError, ValueError) as e:
        log.warning("3D view of %s not written: %s", getattr(case, "name", "?"), e)
        return None
    log.info("3D view %s (%d of %d faces, %.0f kB)", p, view["shown_faces"], view["n_faces"], p.stat().st_size / 1e3)
    return p


def write_outputs(run_dir, cases, views: Mapping, figures: Mapping, notes) -> Path:
    """``run_dir/report/outputs.json`` (atomically): the per-case files of the run.

    Parameters
    ----------
    cases : the run's case names, in order. views, figures : case name -> path of its
        3D view / figure relative to ``run_dir`` (posix), only those this run wrote.
    notes : texts saying which view or figure was not (re)drawn and why.

    Returns the path. Raises OSError when it cannot be written.
    """
    p = Path(run_dir) / VIEW_DIR / OUTPUTS
    p.parent.mkdir(parents=True, exist_ok=True)
    rec = {"cases": [str(c) for c in cases], "views": {str(k): str(v) for k, v in views.items()},
           "figures": {str(k): str(v) for k, v in figures.items()}, "notes": [str(n) for n in notes]}
    with atomic_write(p, "w") as fh:
        fh.write(json.dumps(rec, indent=1) + "\n")
    return p


def read_outputs(run_dir) -> dict | None:
    """What :func:`write_outputs` recorded in ``run_dir`` (keys ``cases`` list, ``views``
    and ``figures`` dicts, ``notes`` list), or None when the file is absent, unreadable
    or not such a record (a run folder written before it existed)."""
    try:
        rec = read_json(Path(run_dir) / VIEW_DIR / OUTPUTS)
    except (OSError, ValueError):
        return None
    ok = (isinstance(rec, dict) and isinstance(rec.get("cases"), list) and isinstance(rec.get("views"), dict)
          and isinstance(rec.get("figures"), dict) and isinstance(rec.get("notes"), list))
    return rec if ok else None

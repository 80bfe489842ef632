"""User-defined deformations of single shapes (paper §4.1, Fig. arap-examples).
Floor 2 of eval/ (eval/datasets/, tests/test_layering.py); notes: docs/implementation.md.

Example::

    cases = shape_cases("../shared/data/classic", ShapesOptions(files=["armadillo.obj"], vertex_range=None))
    c = cases[0]; c.V.shape, c.handles.shape, c.targets.shape
    # -> ((43243, 3), (120,), (120, 3))"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import List, Optional  # OmegaConf 2.3 reads typing's generics

import numpy as np

from defaust import highres  # the module: tests replace highres.subdivide_remesh by a fast one
from defaust.fixed_order import cross3, dot3, eigh3, matmul, norm3, rotvec_to_matrix, sum_ascending
from eval.datasets.dataset_options import DatasetOptions
from eval.datasets.dataset_registry import register_dataset
from eval.datasets.deformation_case import DeformationCase
from eval.run.names import safe_name
from eval.run.paths import abs_path
from harness.checks import checked_field
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh, write_mesh

__all__ = ["ShapesOptions", "ShapeCase", "shape_cases", "principal_axes", "axis_landmarks", "axis_handles",
           "DEFAULT_SHAPES"]

log = logging.getLogger(__name__)

#: Stanford models of ../shared/data/classic (libigl tutorial data), the paper's S3D set.
DEFAULT_SHAPES = ("armadillo.obj", "bunny.off", "dragon.obj")


@dataclass
class ShapesOptions(DatasetOptions):
    """``conf/dataset/shapes.yaml``: the keys of :class:`DatasetOptions` and the shapes'
    own, checked when made (SShaDeError naming ``dataset.<key>``).

    Attributes
    ----------
    files : file names in ``root`` (None: :data:`DEFAULT_SHAPES`).
    vertex_range : None (native resolution) or ``[lo, hi]`` (4 <= lo <= hi): a high-res
        version first (LS3 Loop + isotropic remesh, :func:`defaust.highres.subdivide_remesh`).
    cache : folder of the high-res meshes (None: rebuilt every time), made absolute.
    n_per_group : int >= 1, region_radius : >= 0, rotate_deg, translate, seed : int >= 0:
        the edit, see :func:`axis_handles`.
    """

    name: str = "shapes"
    root: Optional[str] = "../shared/data/classic"
    files: Optional[List[str]] = field(default_factory=lambda: list(DEFAULT_SHAPES))
    vertex_range: Optional[List[int]] = checked_field(list[int], min=4, allow_none=True,
                                                      default_factory=lambda: [150000, 200000])
    cache: Optional[str] = "data/shapes"
    n_per_group: int = checked_field(int, min=1, default=30)
    region_radius: float = checked_field(float, min=0, default=0.06)
    rotate_deg: float = checked_field(float, default=20.0)
    translate: float = checked_field(float, default=0.05)
    seed: int = checked_field(int, min=0, default=0)

    def __post_init__(self):
        super().__post_init__()  # the declared fields (harness.checks.check_fields)
        vr = self.vertex_range
        if vr is not None and (len(vr) != 2 or vr[0] > vr[1]):
            raise SShaDeError(f"dataset.vertex_range must be [lo, hi] with 4 <= lo <= hi, got {vr}")
        if self.cache is not None:
            self.cache = abs_path(self.cache)


@dataclass
class ShapeCase(DeformationCase):
    """One user-defined deformation of one shape (fields of
    :class:`eval.datasets.deformation_case.DeformationCase`, plus the ones below).

    Attributes
    ----------
    name, subject : the file's stem; pose : 1. V, F : the high-res version when
    ``vertex_range`` is set. V_gt : None (no ground truth). group : region (0..3).
    seed : int; path : Path of the source file; n_source : int, its vertex count.
    """

    seed: int = 0
    path: Path | None = None
    n_source: int = 0


def _canonical_sign(u: list) -> np.ndarray:
    """``u`` (3,) with the sign that makes its largest-magnitude component (the first of
    equals) positive: an eigenvector's sign, fixed by the vector, not by the solver."""
    k = max(range(3), key=lambda i: abs(u[i]))
    return np.array(u if u[k] > 0 else [-x for x in u], np.float64)


def principal_axes(V: np.ndarray) -> tuple[np.ndarray, tuple]:
    """The centroid and principal axes of the points ``V``, the same bits on every machine
    (:mod:`defaust.fixed_order`: sums in ascending order, a Jacobi eigensolver).

    V : (n, 3) float64, n >= 1. Returns ``center`` (3,) and ``axes`` (a1, a2, a3): unit
    (3,) vectors along the covariance's eigenvectors by descending variance, a1 and a2
    with their largest-magnitude component positive, ``a3 = a1 x a2`` (right-handed).
    """
    n = len(V)
    center = np.array([float(sum_ascending(V[:, k])) / n for k in range(3)])
    D = V - center
    C = [[0.0] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i, 3):
            C[i][j] = C[j][i] = float(sum_ascending(D[:, i] * D[:, j]))
    _, vecs = eigh3(C)
    a1, a2 = _canonical_sign(vecs[0]), _canonical_sign(vecs[1])
    a3 = cross3(a1, a2)
    return center, (a1, a2, a3 / norm3(a3))


def axis_landmarks(V: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
    """Landmarks of the fixed edit: the vertices of smallest and largest coordinate along
    the first two principal axes (:func:`principal_axes`: the same on every machine).

    V : (n, 3) float64. Returns ``points`` (4, 3) in the order (min a1, max a1, min a2,
    max a2), ``center`` (3,) the centroid, ``axes`` (a1, a2, a3) unit (3,) vectors.
    """
    c, (a1, a2, a3) = principal_axes(V)
    D = V - c
    p1, p2 = dot3(D, a1), dot3(D, a2)
    pts = np.stack([V[p1.argmin()], V[p1.argmax()], V[p2.argmin()], V[p2.argmax()]])
    return pts, c, (a1, a2, a3)


def axis_handles(V: np.ndarray, landmarks: np.ndarray, center: np.ndarray, axes, *, n_per_group: int = 30,
                 region_radius: float = 0.06, rotate_deg: float = 20.0, translate: float = 0.05,
                 seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Handles and targets of the fixed edit (module docstring) on the mesh ``V``, the
    same bits on every machine (:mod:`defaust.fixed_order`'s arithmetic: no BLAS).

    Parameters
    ----------
    V : (n, 3) float64 mesh vertices. landmarks : (4, 3) points, center : (3,), axes :
        (a1, a2, a3), from :func:`axis_landmarks` (of ``V`` or of a coarser version of
        the same shape, so every resolution gets the same edit). Given (k, 3) landmarks,
        one region is picked per landmark in the same way; those past the fourth stay.
    n_per_group : vertices per region; region_radius : fraction of the bbox diagonal;
    rotate_deg : degrees; translate : fraction of the bbox diagonal; seed : int.

    Returns
    -------
    handles : (h,) int64, targets : (h, 3) float64, static : (h,) bool, group : (h,)
    int64 region (0..k-1) of each handle; regions in landmark order,
    ``min(n_per_group, free vertices in the region)`` handles each.

    Raises
    ------
    SShaDeError if a region holds no vertex (not already taken by an earlier region).
    """
    from scipy.spatial import cKDTree
    diag = float(norm3(V.max(0) - V.min(0)))
    tree = cKDTree(V)
    R = rotvec_to_matrix((float(rotate_deg) * math.pi / 180.0) * np.asarray(axes[2], np.float64))
    hs, ts, st = [], [], []
    taken: set = set()
    for g, p in enumerate(landmarks):
        cand = np.array(sorted(set(tree.query_ball_point(p, region_radius * diag)) - taken), np.int64)
        if len(cand) == 0:
            raise SShaDeError(f"axis handles: no free vertex within {region_radius} x diagonal of landmark {g}")
        rng = np.random.default_rng([seed, g])
        pick = rng.choice(cand, min(n_per_group, len(cand)), replace=False)
        taken.update(pick.tolist())
        P = V[pick]
        if g == 1:
            T = matmul(P - center, R.T) + center
        elif g == 3:
            T = P + (translate * diag) * np.asarray(axes[2], np.float64)
        else:
            T = P.copy()
        hs.append(pick)
        ts.append(T)
        st.append(np.full(len(pick), g in (0, 2)))
    group = np.repeat(np.arange(len(hs), dtype=np.int64), [len(x) for x in hs])
    return np.concatenate(hs), np.concatenate(ts), np.concatenate(st), group


def _highres(path: Path, V, F, vertex_range, cache: Path | None):
    lo, hi = (int(x) for x in vertex_range)
    # the whole file name: bunny.off and bunny.obj never share a cached version
    cached = None if cache is None else Path(cache) / f"{safe_name(path.name)}_{lo}-{hi}.ply"
    if cached is not None and cached.is_file():
        return read_mesh(cached)
    log.info("%s: LS3 Loop + isotropic remesh to [%d, %d] vertices (cached in %s)", path.name, lo, hi, cached)
    r = highres.subdivide_remesh(V, F, vertex_range=(lo, hi))
    if cached is not None:
        write_mesh(cached, r.V, r.F)
    return r.V, r.F


def _refuse_repeats(root: Path, names: list) -> None:
    """SShaDeError when two entries of ``names`` are the same file of ``root`` (the same
    name twice, or two spellings of one path such as ``x.off`` and ``./x.off``)."""
    seen: dict = {}
    for n in names:
        p = (root / str(n)).resolve()
        if p in seen:
            same = f"{n!r} twice" if str(seen[p]) == str(n) else f"{seen[p]!r} and {n!r}, the same file,"
            raise SShaDeError(f"shapes: dataset.files lists {same}: each file may be listed once")
        seen[p] = n


def shape_cases(root, options: ShapesOptions | None = None) -> list[ShapeCase]:
    """One deformation case per shape file in ``root``.

    Parameters
    ----------
    root : str or Path, a folder of meshes (any format :func:`sshade.mesh.io.read_mesh` reads).
    options : :class:`ShapesOptions` (None: its defaults): ``files`` (names in ``root``),
        ``vertex_range`` and ``cache`` (the high-res version), the edit (``n_per_group``,
        ``region_radius``, ``rotate_deg``, ``translate``, ``seed``: see
        :func:`axis_handles`), ``limit`` (keep the first ``limit`` files).

    Returns
    -------
    list of :class:`ShapeCase`, in ``files`` order, named by the file's stem (two
    files of one stem, e.g. ``bunny.off`` and ``bunny.obj``, get distinct names from
    :func:`eval.datasets.load_cases`).

    Raises
    ------
    SShaDeError on a missing folder or file, a file listed twice, an unreadable or
    invalid mesh (the message names it) or an empty selection.
    """
    o = ShapesOptions() if options is None else options
    root = Path(root)
    if not root.is_dir():
        raise SShaDeError(f"shapes: dataset.root is not a folder: {root}")
    names = list(DEFAULT_SHAPES if o.files is None else o.files)
    _refuse_repeats(root, names)  # the whole list, before limit
    if o.limit is not None:
        names = names[:o.limit]
    if not names:
        raise SShaDeError("shapes: no file selected (dataset.files is empty)")
    missing = [n for n in names if not (root / n).is_file()]
    if missing:
        raise SShaDeError(f"shapes: {missing} not found in {root}")
    cases = []
    for n in names:
        path = root / n
        V0, F0 = read_mesh(path, allow_components=True)  # the evaluator deforms each component
        lm, center, axes = axis_landmarks(V0)  # from the source shape: same edit at every resolution
        V, F = (V0, F0) if o.vertex_range is None else _highres(path, V0, F0, o.vertex_range, o.cache)
        h, T, st, group = axis_handles(V, lm, center, axes, n_per_group=o.n_per_group, region_radius=o.region_radius,
                                       rotate_deg=o.rotate_deg, translate=o.translate, seed=o.seed)
        cases.append(ShapeCase(name=path.stem, subject=path.stem, pose=1, V=V, F=F, handles=h, targets=T,
                               static=st, V_gt=None, group=group, seed=int(o.seed), path=path,
                               n_source=len(V0)))
    return cases


register_dataset("shapes", shape_cases, options=ShapesOptions)

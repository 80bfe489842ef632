"""What the suite's benchmarks share (no benchmark here): where the data and the cache
are, the two 200k meshes and their handles, a smooth handle path, libigl's local/global
iterations and the spokes-and-rims energy they minimise.

Nothing here imports ``eval`` or ``harness`` (they change across commits and may not
exist at old ones): the meshes are built with pymeshlab, trimesh and numpy only, the way
the scaling experiment builds them (``eval/experiments/scaling``: LS3 Loop subdivision
with ``threshold=PercentageValue(0)`` until the mesh has the size, then for the clean
mesh isotropic remeshing to it), and the handles are the scaling experiment's edit
(``eval.datasets.shapes.axis_handles``, copied below: four regions of 30 vertices at the
extremes of the base mesh's first two principal axes, two fixed, one turned 20 degrees
about the third axis, one moved 5 % of the diagonal along it).

Environment variables:

- ``SSHADE_SHARED_DATA``: the folder of the real meshes (default ``../shared/data``
  beside the repository: ``classic/armadillo.obj``, ``tosca/centaur0.off``);
- ``SSHADE_ASV_CACHE``: where built meshes are kept (default ``~/.cache/sshade-asv``),
  one ``.npz`` per mesh named by the hash of its source file and its recipe;
- ``SSHADE_ASV_QUICK=1``: about 20k-vertex meshes and shorter libigl runs, to check the
  suite and the environments quickly (its numbers are not the record's);
- ``SSHADE_DEFAUST``: a DeFAUST build (default ``data/defaust`` in the repository).
"""
from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path

import numpy as np

SUITE = Path(__file__).resolve().parent
REPO = SUITE.parents[1]
RECIPE_VERSION = 1  # bump when the mesh recipe below changes: the cache key changes with it

#: the benchmark meshes: source (relative to the shared data folder), whether it is
#: remeshed (clean) or only subdivided (hard), its size and its size under SSHADE_ASV_QUICK
MESHES = {
    "clean": {"name": "armadillo", "source": "classic/armadillo.obj", "remesh": True,
              "size": 200_000, "quick_size": 20_000},
    "hard": {"name": "centaur", "source": "tosca/centaur0.off", "remesh": False,
             "size": 200_000, "quick_size": 15_000},
}
#: SShaDe's parameters in every benchmark (paper §4.1)
SSHADE = {"n_low": 6000, "n_samplings": 5, "seed": 0}
PATH_FRAMES = 60  # benchmarks/frames.py's path: a prepared SShaDe's frames (prepared_frames)
FRAMES = PATH_FRAMES - 1  # timed frames, after one untimed first solve: frames 2-60, as results/frames


def quick() -> bool:
    """True under ``SSHADE_ASV_QUICK`` (set to anything but empty or 0)."""
    return os.environ.get("SSHADE_ASV_QUICK", "") not in ("", "0")


def shared_data() -> Path:
    """The folder of the real meshes (``SSHADE_SHARED_DATA`` or ``../shared/data``)."""
    env = os.environ.get("SSHADE_SHARED_DATA")
    return Path(env).expanduser().resolve() if env else REPO.parent / "shared" / "data"


def cache_dir() -> Path:
    """Where built meshes are kept (``SSHADE_ASV_CACHE`` or ``~/.cache/sshade-asv``)."""
    env = os.environ.get("SSHADE_ASV_CACHE")
    return Path(env).expanduser().resolve() if env else Path.home() / ".cache" / "sshade-asv"


def defaust_root() -> Path:
    """A DeFAUST build (``SSHADE_DEFAUST`` or ``data/defaust`` in the repository)."""
    env = os.environ.get("SSHADE_DEFAUST")
    return Path(env).expanduser().resolve() if env else REPO / "data" / "defaust"


def skip(why: str):
    """NotImplementedError, which asv reports as n/a (raised from a ``setup``)."""
    return NotImplementedError(why)


# ----------------------------------------------------------------------------- meshes


def _build(V0: np.ndarray, F0: np.ndarray, size: int, remesh: bool) -> tuple[np.ndarray, np.ndarray]:
    """The scaling experiment's ``build_mesh``: LS3 Loop (threshold 0 %, else short edges
    are skipped) until at least ``size`` vertices, then with ``remesh`` isotropic explicit
    remeshing (3 iterations) at the edge length that gives ``size`` vertices on that area."""
    import pymeshlab as ml
    ms = ml.MeshSet()
    ms.add_mesh(ml.Mesh(V0, F0))
    while ms.current_mesh().vertex_number() < size:
        ms.meshing_surface_subdivision_ls3_loop(iterations=1, threshold=ml.PercentageValue(0))
    if remesh:
        m = ms.current_mesh()
        Vc, Fc = m.vertex_matrix(), m.face_matrix()
        area = 0.5 * np.linalg.norm(np.cross(Vc[Fc[:, 1]] - Vc[Fc[:, 0]], Vc[Fc[:, 2]] - Vc[Fc[:, 0]]), axis=1).sum()
        L = float(np.sqrt(2 * area / (np.sqrt(3) * size)))
        ms.meshing_isotropic_explicit_remeshing(iterations=3, targetlen=ml.PureValue(L))
    m = ms.current_mesh()
    V = np.ascontiguousarray(m.vertex_matrix(), np.float64)
    F = np.ascontiguousarray(m.face_matrix(), np.int64)
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    if not used.all():  # drop unreferenced vertices (none expected)
        new = np.cumsum(used) - 1
        V, F = V[used], new[F]
    return V, F


def axis_landmarks(V: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple]:
    """The vertices of smallest and largest coordinate along the first two principal
    axes (min a1, max a1, min a2, max a2), the centroid and the axes (a1, a2, a3)."""
    c = V.mean(0)
    _, _, Wt = np.linalg.svd(V - c, full_matrices=False)
    a1, a2, a3 = Wt
    p1, p2 = (V - c) @ a1, (V - c) @ a2
    pts = np.stack([V[p1.argmin()], V[p1.argmax()], V[p2.argmin()], V[p2.argmax()]])
    return pts, c, (a1, a2, a3)


def axis_handles(V, landmarks, center, axes, *, n_per_group: int = 30, region_radius: float = 0.06,
                 rotate_deg: float = 20.0, translate: float = 0.05, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The scaling experiment's edit (eval.datasets.shapes.axis_handles): ``n_per_group``
    vertices drawn within ``region_radius`` x diagonal of each landmark; regions 0 and 2
    fixed, region 1 turned ``rotate_deg`` about the third axis through the centroid,
    region 3 moved ``translate`` x diagonal along it. Returns handles (h,) int64, targets
    (h, 3) float64."""
    from scipy.spatial import cKDTree
    from scipy.spatial.transform import Rotation
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    tree = cKDTree(V)
    R = Rotation.from_rotvec(np.deg2rad(rotate_deg) * axes[2]).as_matrix()
    hs, ts, taken = [], [], set()
    for g, p in enumerate(landmarks):
        cand = np.array(sorted(set(tree.query_ball_point(p, region_radius * diag)) - taken), np.int64)
        if len(cand) == 0:
            raise RuntimeError(f"axis handles: no free vertex near landmark {g}")
        pick = np.random.default_rng([seed, g]).choice(cand, min(n_per_group, len(cand)), replace=False)
        taken.update(pick.tolist())
        P = V[pick]
        if g == 1:
            T = (P - center) @ R.T + center
        elif g == 3:
            T = P + translate * diag * axes[2]
        else:
            T = P.copy()
        hs.append(pick)
        ts.append(T)
    return np.concatenate(hs).astype(np.int64), np.concatenate(ts)


def mesh_file(kind: str) -> str | None:
    """Build (once; cached) the ``kind`` ("clean" or "hard") benchmark mesh with its
    handles and targets; returns the cached ``.npz`` path, or None when the source mesh is
    not in the shared data folder. The file name holds a hash of the source file's bytes
    and of the recipe (size, remeshing, handle rule, RECIPE_VERSION), so a changed source
    or recipe builds a new file and never reuses a stale one."""
    spec = MESHES[kind]
    src = shared_data() / spec["source"]
    if not src.is_file():
        return None
    size = spec["quick_size"] if quick() else spec["size"]
    recipe = {"version": RECIPE_VERSION, "size": size, "remesh": spec["remesh"], "ls3_threshold_pct": 0,
              "remesh_iterations": 3, "handles": "axis_handles(30, 0.06, 20deg, 0.05, seed 0)"}
    h = hashlib.sha256(src.read_bytes())
    h.update(json.dumps(recipe, sort_keys=True).encode())
    out = cache_dir() / f"{spec['name']}_{'remesh' if spec['remesh'] else 'ls3'}_{size}_{h.hexdigest()[:16]}.npz"
    if out.is_file():
        return str(out)
    import trimesh
    t0 = time.perf_counter()
    m = trimesh.load(src, process=False, force="mesh")
    V0, F0 = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    V, F = _build(V0, F0, size, spec["remesh"])
    lm, center, axes = axis_landmarks(V0)  # the base mesh's landmarks, as the scaling experiment
    handles, targets = axis_handles(V, lm, center, axes)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + f".{os.getpid()}.tmp.npz")
    np.savez(tmp, V=V, F=F, handles=handles, targets=targets, recipe=json.dumps(recipe), source=str(src))
    os.replace(tmp, out)
    print(f"built {out.name}: {len(V)} vertices, {len(F)} faces, {len(handles)} handles "
          f"in {time.perf_counter() - t0:.1f} s")
    return str(out)


def mesh_files() -> dict:
    """``{kind: path or None}`` of both meshes (built when missing): a ``setup_cache``."""
    return {kind: mesh_file(kind) for kind in MESHES}


def load_mesh(files: dict, kind: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(V, F, handles, targets)`` of a built mesh; n/a (NotImplementedError) when its
    source was missing."""
    path = files.get(kind)
    if path is None:
        raise skip(f"{MESHES[kind]['source']} is not in {shared_data()} (set SSHADE_SHARED_DATA)")
    d = np.load(path)
    return d["V"], d["F"], d["handles"], d["targets"]


def smooth_path(rest: np.ndarray, final: np.ndarray, n: int) -> list[np.ndarray]:
    """``n`` targets from ``rest`` (excluded) to ``final`` along the smoothstep s(t) =
    3t^2 - 2t^3 (benchmarks/frames.py's path)."""
    out = []
    for i in range(1, n + 1):
        t = i / n
        s = t * t * (3 - 2 * t)
        out.append(rest + s * (final - rest))
    return out


_WARMED: set = set()


def warm_deform(V, F, handles, targets, key) -> None:
    """One untimed ``sshade.deform`` per process and ``key``: numba's compilation or cache
    loads (the first call of a process) stay out of the timed calls."""
    if key in _WARMED:
        return
    import sshade
    sshade.deform(V, F, handles, targets, **SSHADE)
    _WARMED.add(key)


def arap_deform(V, F, handles, targets, energy: str):
    """``sshade.arap.arap_deform`` of ``energy`` with its other options' defaults, called
    as the commit under test takes them: one ``ArapOptions`` where ``sshade.arap`` has it,
    else the keyword ``energy`` (asv runs older commits too)."""
    import sshade.arap as arap
    if hasattr(arap, "ArapOptions"):
        return arap.arap_deform(V, F, handles, targets, arap.ArapOptions(energy=energy))
    return arap.arap_deform(V, F, handles, targets, energy=energy)


def prepared_frames(V, F, handles, targets, n_frames: int = FRAMES) -> list[float]:
    """Seconds of each of ``n_frames`` solves of ``sshade.prepare(V, F, handles)`` after one
    untimed first solve: frames 2 to ``n_frames + 1`` of benchmarks/frames.py's path, the
    smoothstep from the rest positions to ``targets`` in ``PATH_FRAMES`` (60) frames; by
    default frames 2-60, the frames whose median results/frames reports and the target
    is set on (the first half alone is harder than the whole: in frames 2-4 the start's
    history is still short).
    n/a (NotImplementedError) where ``sshade.prepare`` is missing."""
    import sshade
    if not hasattr(sshade, "prepare"):
        raise skip("sshade.prepare does not exist at this commit")
    path = smooth_path(V[handles], targets, PATH_FRAMES)[:n_frames + 1]
    secs = []
    with sshade.prepare(V, F, handles, **SSHADE) as p:
        p.solve(path[0])
        for T in path[1:]:
            t0 = time.perf_counter()
            p.solve(T)
            secs.append(time.perf_counter() - t0)
    return secs


# ----------------------------------------------------------------------------- libigl


def rigid_fit(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation R and translation t with ``P @ R.T + t ~ Q`` (Kabsch)."""
    cp, cq = P.mean(0), Q.mean(0)
    U, _, Wt = np.linalg.svd((P - cp).T @ (Q - cq))
    d = np.sign(np.linalg.det(Wt.T @ U.T))
    R = Wt.T @ np.diag([1.0, 1.0, d]) @ U.T
    return R, cq - cp @ R.T


def rigid_start(V, handles, targets) -> np.ndarray:
    """The paper protocol's start: V moved by the rigid fit of the handles, handles at
    their targets."""
    R, t = rigid_fit(V[handles], targets)
    U = V @ R.T + t
    U[handles] = targets
    return U


def igl_precompute(V, F, handles):
    """libigl's ``arap_precomputation`` for the spokes-and-rims energy (Elastic), one
    iteration per ``arap_solve`` call (the paper protocol's baselines)."""
    import igl
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_SPOKES_AND_RIMS
    data.max_iter = 1
    igl.arap_precomputation(np.ascontiguousarray(V, np.float64), np.ascontiguousarray(F, np.int64), 3,
                            np.ascontiguousarray(handles, np.int32), data)
    return data


def igl_iterations(V, F, handles, targets, n: int) -> tuple[float, list[float]]:
    """libigl spokes-and-rims ARAP under the paper protocol: the seconds of the rigid
    start plus the precomputation, and the seconds of each of ``n`` ``arap_solve``
    iterations (one per call) from there."""
    import igl
    bc = np.ascontiguousarray(targets, np.float64)
    t0 = time.perf_counter()
    U = rigid_start(V, handles, bc)
    data = igl_precompute(V, F, handles)
    pre = time.perf_counter() - t0
    its = []
    for _ in range(n):
        t1 = time.perf_counter()
        U = igl.arap_solve(bc, data, U)
        its.append(time.perf_counter() - t1)
    return pre, its


class SpokesAndRims:
    """libigl's spokes-and-rims ARAP energy (Chao et al. 2010) of a mesh, evaluated with
    numpy (independent of the code benchmarked): each vertex's cell holds every edge of
    its incident triangles, weighted by libigl's ``cotmatrix_entries`` (half cotangents),
    and its rotation is the best fit (Procrustes, the local step's), so
    ``E(U) = sum_i min_R sum_(t ni i) sum_(e in t) w_te |U_e - R V_e|^2``."""

    def __init__(self, V, F):
        import igl
        V = np.ascontiguousarray(V, np.float64)
        F = np.ascontiguousarray(F, np.int64)
        self.F, self.n = F, len(V)
        self.w = np.asarray(igl.cotmatrix_entries(V, F))  # (m, 3): edges [1,2], [2,0], [0,1]
        self.ends = ((1, 2), (2, 0), (0, 1))
        self.dV = [V[F[:, b]] - V[F[:, a]] for a, b in self.ends]
        self.vv = sum(self.w[:, e] * (self.dV[e] ** 2).sum(1) for e in range(3))  # (m,)

    def __call__(self, U) -> float:
        F, w = self.F, self.w
        S = np.zeros((len(F), 3, 3))
        uu = np.zeros(len(F))
        for e, (a, b) in enumerate(self.ends):
            dU = U[F[:, b]] - U[F[:, a]]
            S += w[:, e, None, None] * self.dV[e][:, :, None] * dU[:, None, :]
            uu += w[:, e] * (dU ** 2).sum(1)
        Sv = np.zeros((self.n, 3, 3))
        for c in range(3):  # every corner's cell holds the whole triangle
            np.add.at(Sv, F[:, c], S)
        sig = np.linalg.svd(Sv, compute_uv=False)
        sig[:, 2] *= np.sign(np.linalg.det(Sv))
        return float(3 * (uu.sum() + self.vv.sum()) - 2 * sig.sum())


def igl_time_to_energy(V, F, handles, targets, energy: float, budget_s: float) -> tuple[float, int, bool]:
    """libigl spokes-and-rims local/global from the rigid fit of the handles (precomputation
    included, energy evaluations excluded) until its energy is at most ``energy`` or
    ``budget_s`` seconds have gone. Returns (seconds, iterations, reached)."""
    import igl
    E = SpokesAndRims(V, F)
    bc = np.ascontiguousarray(targets, np.float64)
    t0 = time.perf_counter()
    U = rigid_start(V, handles, bc)
    data = igl_precompute(V, F, handles)
    spent = time.perf_counter() - t0
    it = 0
    while spent < budget_s:
        t1 = time.perf_counter()
        U = igl.arap_solve(bc, data, U)
        spent += time.perf_counter() - t1
        it += 1
        if E(U) <= energy:
            return spent, it, True
    return spent, it, False

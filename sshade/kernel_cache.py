"""numba's on-disk cache of this package's kernels: where it is, whether it is cold, and
filling a cold one on two processes at once.

numba keys each cached kernel on its source file's modification time and size and on the
CPU, so a fresh install, an upgrade, a new machine or an empty ``NUMBA_CACHE_DIR`` leaves
it cold and the next call compiles every kernel (docs/deform.md, "The first call").
:func:`compile_kernels` fills it: with two cores or more and ``fork``, a forked child
compiles one half of the kernels (:data:`GROUPS`, and :data:`LARGE_GROUPS` but for a small
mesh's call at a cold cache) while this process compiles the other and then loads the child's;
processes that find it cold at once take turns (a lock file in numba's cache folder), so the
later ones load what the first compiled. :func:`notice` prints one line the first time a
process finds the cache cold. ``python -m sshade warmup`` does it ahead.
"""
from __future__ import annotations

import contextlib
import ctypes
import importlib
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from pathlib import Path

import numpy as np
from numba.core.registry import CPUDispatcher

from .arap.solver_kernels import warmup_lbfgs_kernels, warmup_step_kernels
from .closed_ball import warm_kernels as warm_closed_ball
from .cores import available_cores
from .lrf import decode_with_frames, encode, frame_functions
from .mesh.geodesic import VoronoiState, edge_graph_from_edges, locality_order
from .mesh.halfedge import boundary_loops, defer_kernels, halfedges, tetrahedron, vertex_fan_count, vertex_normals
from .mesh.halfedge import warm_kernels as warm_halfedges
from .mesh.validate import validate_mesh
from .mesh.validate import warm_kernels as warm_checks
from .projection import project_to_fans
from .smooth_transfer import smooth_decode

__all__ = ["KERNEL_MODULES", "GROUPS", "LARGE_GROUPS", "COLD_COMPILE_S", "TURN_WAIT_S", "LOCK_NAME",
           "kernel_dispatchers", "cache_folder", "lock_folder", "cold_kernels", "notice", "compile_kernels"]

#: The modules whose numba kernels one SShaDe call compiles.
KERNEL_MODULES = ("sshade.mesh.halfedge", "sshade.mesh.geodesic", "sshade.mesh.validate", "sshade.closed_ball",
                  "sshade.projection", "sshade.lrf", "sshade.smooth_transfer", "sshade.arap.kernels",
                  "sshade.arap.solver_kernels")
#: Seconds a cold first call of SShaDe spends compiling on 2 cores, kernels filled on two
#: processes (measured by benchmarks/cold_start.py; results/cold_start/table.md); the notice's estimate.
COLD_COMPILE_S = 15
#: Seconds the caller waits for the child at least (then three times its own group's time)
#: before it ends the child and compiles the child's group itself.
CHILD_MIN_WAIT_S = 60.0
#: Seconds a process waits at most for another one filling the same cold cache (then it
#: compiles alongside); the lock file's name in :func:`lock_folder`.
TURN_WAIT_S = 120.0
LOCK_NAME = "sshade-compile.lock"
_NOTICED = [False]
_FILLED: set = set()  # the parts filled in this process: "small" (GROUPS), "large" (LARGE_GROUPS)
_LOCK = threading.Lock()


def kernel_dispatchers() -> dict:
    """The module-level, cached numba kernels of :data:`KERNEL_MODULES` that numba compiles
    on their own (``inline="always"`` ones are compiled into their callers).

    Returns
    -------
    dict, ``"module.name" -> numba Dispatcher``.
    """
    out = {}
    for m in KERNEL_MODULES:
        mod = importlib.import_module(m)
        for name, d in vars(mod).items():
            if (isinstance(d, CPUDispatcher) and d.py_func.__module__ == m and d._cache is not None
                    and d.targetoptions.get("inline", "never") == "never"):
                out[f"{m}.{name}"] = d
    return out


def _first_cache_path() -> str | None:
    """numba's cache folder of this package's first kernel, or None when it keeps none."""
    for d in kernel_dispatchers().values():
        path = getattr(d._cache, "_cache_path", None)
        if path:
            return path
    return None


def cache_folder() -> Path | None:
    """The folder holding the kernels' cache files (``NUMBA_CACHE_DIR`` when set, else
    beside the sources or numba's user-wide fallback), or None when numba keeps none."""
    path = _first_cache_path()
    return Path(path).parent if path else None


def lock_folder() -> Path | None:
    """numba's own cache folder of this package's first kernel (``__pycache__`` beside its
    source, or its folder in ``NUMBA_CACHE_DIR``), made when missing as numba would: where
    :data:`LOCK_NAME` lives, never in a source folder. None when numba keeps no cache or
    the folder cannot be made."""
    path = _first_cache_path()
    if path is None:
        return None
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    return Path(path)


def _is_cached(d) -> bool:
    """Whether ``d``'s cache index holds an entry for its current source (any signature)."""
    try:
        return bool(d._cache._cache_file._load_index())
    except Exception:  # numba's private cache layout changed, or an unreadable index: say cached
        return True


def cold_kernels(large: bool = True) -> list[str]:
    """The kernels of :data:`GROUPS` (and of :data:`LARGE_GROUPS` when ``large``) whose cache
    holds nothing for the installed sources (sorted ``"module.name"``); empty when warm."""
    return _cold(GROUPS, LARGE_GROUPS) if large else _cold(GROUPS)


def _cold(*parts: dict) -> list[str]:
    names = {n for part in parts for g in part.values() for n in g[1]}
    return sorted(n for n, d in kernel_dispatchers().items() if n in names and not _is_cached(d))


def notice(cold: list[str], stream=None) -> None:
    """Print, once per process, that ``cold`` kernels are being compiled and how to do it ahead."""
    if not cold or _NOTICED[0]:
        return
    _NOTICED[0] = True
    share = len(cold) / max(1, sum(len(g[1]) for part in (GROUPS, LARGE_GROUPS) for g in part.values()))
    print(f"compiling SShaDe's kernels once (about {max(1, round(share * COLD_COMPILE_S))} s); "
          "python -m sshade warmup does it ahead", file=stream or sys.stderr, flush=True)


# ------------------------------------------------------------------ the two halves
def _warm_sampling() -> None:
    """Geodesic sampling (both queues, mesh and locality order), projection and the low-res
    ARAP's serial energy, local-step, right-hand-side and gradient kernels."""
    V, F = tetrahedron()
    E = np.unique(np.sort(np.stack([F, np.roll(F, -1, axis=1)], axis=2).reshape(-1, 2), axis=1), axis=0)
    project_to_fans(V, np.zeros(4, np.int64), V, F)
    order = locality_order(V)
    for queue in ("auto", "heap"):
        for graph, o in ((None, None), (edge_graph_from_edges(V, E, order), order)):
            st = VoronoiState(V, F, graph=graph, order=o, queue=queue)
            st.sample(2, 0)
            st.add([3])
    warmup_step_kernels()


def _warm_topology() -> None:
    """Mesh checks, half-edges, fans, normals, boundary loops (a small mesh's paths: nothing
    compiled), the closed-ball checks (full and local), both transfers' encoding and decoding,
    and L-BFGS's kernels."""
    V, F = tetrahedron()
    validate_mesh(V, F)
    warm_closed_ball()
    he = halfedges(F, 4)
    vertex_fan_count(F, he, 4)
    boundary_loops(F, he)
    vertex_normals(V, F)
    L = np.broadcast_to(np.eye(3), (4, 3, 3)).copy()
    for bary in (None, np.full((4, 3), 1 / 3)):
        decode_with_frames(L, np.zeros((4, 3)), np.arange(4), V, F, bary=bary)
        encode(V, np.arange(4), V, F, frame_functions(V, F), "normalized", bary)
        smooth_decode(V, np.arange(4), bary, V, V, F)
    warmup_lbfgs_kernels()


#: The kernels of a call on a small mesh in two halves of about equal compile time: name ->
#: (warm function, kernels it compiles). A cold :func:`compile_kernels` runs the first half in a
#: forked child.
GROUPS = {
    "sampling, projection and ARAP": (_warm_sampling, (
        "sshade.mesh.geodesic._csr_from_edges", "sshade.mesh.geodesic._fps",
        "sshade.mesh.geodesic._grow", "sshade.mesh.geodesic._propagate",
        "sshade.arap.kernels._local_serial", "sshade.arap.kernels._rhs_serial",
        "sshade.arap.solver_kernels._grad_serial", "sshade.projection._project")),
    "topology, transfer and L-BFGS": (_warm_topology, (
        "sshade.closed_ball.closed_ball_holds", "sshade.closed_ball._region_euler", "sshade.closed_ball._pair_ids",
        "sshade.closed_ball._link_faces", "sshade.closed_ball._repair_candidates", "sshade.closed_ball._touched",
        "sshade.closed_ball._local_euler", "sshade.closed_ball._local_pairs", "sshade.closed_ball._local_triples",
        "sshade.closed_ball._local_candidates", "sshade.closed_ball.vertex_faces",
        "sshade.lrf._decode_kernel", "sshade.lrf._encode_kernel", "sshade.smooth_transfer._smooth_kernel",
        "sshade.smooth_transfer._vertex_jacobians_kernel", "sshade.arap.solver_kernels.lbfgs_update",
        "sshade.arap.solver_kernels.lbfgs_direction")),
}
#: The kernels a call on a mesh of at least :data:`sshade.mesh.halfedge.KERNEL_MIN_FACES` faces
#: takes besides :data:`GROUPS`' (the compiled mesh checks, half-edges, fans, components and
#: normals), each half compiled with the group of the same name.
LARGE_GROUPS = {
    "sampling, projection and ARAP": (warm_checks, (
        "sshade.mesh.validate._vertex_pass", "sshade.mesh.validate._face_pass", "sshade.mesh.validate._twin_faces",
        "sshade.mesh.halfedge._pinched")),
    "topology, transfer and L-BFGS": (warm_halfedges, (
        "sshade.mesh.halfedge._halfedges", "sshade.mesh.halfedge._fan_count", "sshade.mesh.halfedge._components",
        "sshade.mesh.halfedge._vertex_normals")),
}


def _plan(large: bool) -> dict:
    """What this process has still to fill: group name -> its warm functions (the parts of
    :data:`GROUPS` and, when ``large``, :data:`LARGE_GROUPS` not filled yet)."""
    parts = [p for p, want in (("small", True), ("large", large)) if want and p not in _FILLED]
    plan = {}
    for name in GROUPS:
        fns = [src[name][0] for p, src in (("small", GROUPS), ("large", LARGE_GROUPS)) if p in parts and name in src]
        if fns:
            plan[name] = tuple(fns)
    return plan


def _child(warm: tuple, seconds) -> None:
    """Body of the forked child: die with the parent (Linux), run one group's warm functions,
    put its seconds in ``seconds`` (a shared ``multiprocessing.Value``), exit."""
    try:
        ctypes.CDLL(None).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG: never outlive the caller
    except Exception:  # not Linux: the parent's finally still reaps it
        pass
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C goes to the caller, which ends this child
    t = time.perf_counter()
    for fn in warm:
        fn()
    seconds.value = time.perf_counter() - t


def compile_kernels(*, large: bool = True, show_notice: bool = True, split: bool | None = None,
                    progress=None) -> float:
    """Compile (or load from numba's cache) every kernel of :data:`GROUPS` in this process,
    once per process; on a cold cache, half of them in a forked child at the same time.

    Parameters
    ----------
    large : also :data:`LARGE_GROUPS`' kernels, which a mesh of at least
        :data:`sshade.mesh.halfedge.KERNEL_MIN_FACES` faces takes (:func:`sshade.mesh.halfedge.large_mesh`).
        A call for a small mesh loads them too where numba's cache holds them; where it does
        not, it leaves them and small meshes take their NumPy twins in this process
        (:func:`sshade.mesh.halfedge.defer_kernels`) until a call for a large mesh fills them.
    show_notice : print :func:`notice`'s line when the cache is cold.
    split : run one group in a child; None: when the cache is cold, two or more cores are
        available (:func:`sshade.cores.available_cores`) and ``fork`` exists.
    progress : optional callable taking one line of text per finished group.

    Returns
    -------
    float, the seconds spent (0.0 when already done in this process). A child that fails,
    is killed or hangs past :data:`CHILD_MIN_WAIT_S` (or three times this process's own
    group) only costs time: this process then compiles its group itself. Thread-safe.
    """
    with _LOCK:  # two threads at a cold cache: one fills it, the other then finds it done
        if not large and not _FILLED:  # a process's first fill, for a small mesh: the large part if cached
            large = not _cold(LARGE_GROUPS)
        plan = _plan(large)
        defer_kernels(True)  # GROUPS' tiny meshes take the NumPy paths: LARGE_GROUPS' kernels only where listed
        try:
            return _compile(plan, large, show_notice, split, progress) if plan else 0.0
        finally:
            defer_kernels("large" not in _FILLED)


@contextlib.contextmanager
def _turn(cold: list[str], large: bool = True):
    """Hold the lock file in :func:`lock_folder` (:data:`LOCK_NAME`, ``flock``: released when the
    holder exits, however it exits) while this process fills a cold cache; another
    process filling it makes this one wait, at most :data:`TURN_WAIT_S`. Yields whether
    the cache is still cold. Without a cold cache, ``fcntl`` or a writable cache folder
    there is no turn to take."""
    folder = lock_folder() if cold else None
    try:
        import fcntl
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW | os.O_NONBLOCK
        # a link in its place is not followed, a FIFO not waited on (ENXIO), a folder refused: no turn
        fd = os.open(folder / LOCK_NAME, flags, 0o644) if folder is not None else None
    except (ImportError, OSError):
        fd = None
    if fd is None:
        yield bool(cold)
        return
    with os.fdopen(fd, "a") as fh:
        deadline, held = time.monotonic() + TURN_WAIT_S, False
        while not held:
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
                held = True
            except OSError:
                if time.monotonic() > deadline:
                    break
                time.sleep(0.1)
        try:
            yield bool(cold_kernels(large)) if held else True  # the other process may have filled it
        finally:
            if held:
                fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def _compile(plan: dict, large: bool, show_notice: bool, split: bool | None, progress) -> float:
    t0 = time.perf_counter()
    cold = cold_kernels(large)
    if show_notice:
        notice(cold)
    with _turn(cold, large) as still_cold:
        seconds = _fill(plan, t0, still_cold, split, progress)
    _FILLED.update(("small", "large") if large else ("small",))
    return seconds


def _fill(plan: dict, t0: float, cold: bool, split: bool | None, progress) -> float:
    names = list(plan)
    if split is None:
        split = bool(cold) and len(names) > 1 and available_cores() >= 2 and "fork" in mp.get_all_start_methods()
    child, child_s = None, None
    if split:
        ctx = mp.get_context("fork")
        child_s = ctx.Value("d", -1.0, lock=False)  # the child's own seconds, once it has compiled
        child = ctx.Process(target=_child, args=(plan[names[0]], child_s), daemon=True)
        child.start()
    try:
        for name in (names[1:] + names[:1]) if child else names:
            if child is not None and name == names[0]:
                # a child stuck (e.g. on a lock another thread held at the fork) is given up
                child.join(timeout=max(CHILD_MIN_WAIT_S, 3 * (time.perf_counter() - t0)))
            t = time.perf_counter()
            for fn in plan[name]:
                fn()
            if progress is not None:
                progress(_group_words(name, time.perf_counter() - t,
                                      child_s.value if child is not None and name == names[0] else -1.0))
    finally:
        if child is not None and child.is_alive():
            child.terminate()
            child.join()
    return time.perf_counter() - t0



def _group_words(name: str, seconds: float, child_s: float) -> str:
    """The progress line of one group: its seconds here, or, where a forked child compiled
    it (``child_s`` >= 0) and this process only loaded it, the child's seconds.

    >>> _group_words("topology", 27.46, -1.0), _group_words("sampling", 0.12, 25.03)
    ('topology: 27.5 s', 'sampling: 25.0 s in a second process, beside the first (0.1 s to load here)')
    """
    if child_s < 0:
        return f"{name}: {seconds:.1f} s"
    return f"{name}: {child_s:.1f} s in a second process, beside the first ({seconds:.1f} s to load here)"

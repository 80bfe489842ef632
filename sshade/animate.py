"""``python -m sshade animate``: deform one mesh through a sequence of handle targets with
SShaDe prepared once (:func:`sshade.prepared.prepare`) and solved per frame.

Usage::

    python -m sshade animate MESH (--sel F.sel | --dmat F.dmat | --handles F.json|F.csv)
        --frames FRAMES.npy -o OUT [--n-low N] [--k K] [--seed S] [--force]

- ``FRAMES.npy``: either (f, h, 3) float targets, one row per handle in the order of the
  handle selection (``--sel``/``--dmat``: the selected vertices in increasing order,
  :func:`sshade.mesh.handle_files.read_moving_handles`; ``--handles``: the file's order),
  or, with ``--sel``/``--dmat``, (f, 4, 4) affine matrices moving the handle region of each
  frame (fixed vertices stay), as a ``.def`` file moves it once.
- ``OUT``: a ``.npz`` file with ``V`` (f, n, 3) float64, ``F`` (m, 3) int64 and
  ``frame_s`` (f,) the seconds of each frame's solve; or a folder receiving
  ``frame_0000.obj`` ... (``--format obj|off|ply``), one mesh per frame. A folder must be
  new, empty, or hold only frame files that sshade wrote (then they are replaced); an
  ``OUT.npz`` must be new or an earlier animation's (``--force``: any file). Checked before
  any work; every file is written atomically.

Prints the prepare time and the per-frame median and range on stdout; a progress bar on
stderr when it is a terminal. Exit status 0, or 2 after one ``error:`` line.
"""
from __future__ import annotations

import io
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .clirun import ArgumentParser, run_command
from .errors import SShaDeError
from .mesh.handle_files import apply_def, check_affine, read_moving_handles
from .mesh.io import atomic_write, read_mesh, write_mesh, written_by_sshade
from .prepared import prepare

__all__ = ["build_parser", "animate_file", "NPZ_KEY"]

#: The key of an animation ``.npz`` that marks it as one (with ``V``, ``F``, ``frame_s``).
NPZ_KEY = "sshade_animation"
FORMATS = ("obj", "off", "ply")


def build_parser() -> ArgumentParser:
    """The argument parser of ``python -m sshade animate`` (module docstring)."""
    p = ArgumentParser(prog="python -m sshade animate",
                description="Deform a mesh through a sequence of handle targets (SShaDe prepared once).")
    p.add_argument("mesh", help="input mesh (.obj, .off, .ply)")
    g = p.add_argument_group("handles (one of)")
    g.add_argument("--sel", help="deformation-benchmark selection: 0 fixed, 1 free, 2 handle")
    g.add_argument("--dmat", help="libigl .dmat selection: -1 free, 0 fixed, >= 1 handle")
    g.add_argument("--handles", help=".json or .csv of handle indices (their targets there are not used)")
    p.add_argument("--frames", required=True, help=".npy of (f, h, 3) targets or (f, 4, 4) matrices")
    p.add_argument("-o", "--out", required=True, help="OUT.npz, or a folder for one mesh per frame")
    p.add_argument("--format", default="obj", choices=FORMATS, help="mesh format of a folder OUT (default obj)")
    p.add_argument("--n-low", default="auto", help="SShaDe's low-resolution vertex count (int or auto)")
    p.add_argument("--k", type=int, default=5, help="SShaDe's number of samplings (default 5)")
    p.add_argument("--seed", type=int, default=0, help="SShaDe's seed (default 0)")
    p.add_argument("--force", action="store_true", help="replace an OUT.npz that sshade did not write")
    return p


def _check_out(a) -> None:
    """The output checks of the module docstring, before any work."""
    out = Path(a.out)
    if out.suffix.lower() == ".npz":
        if out.is_dir():
            raise SShaDeError(f"output {out} is a folder; an .npz output is a file")
        if out.exists() and not a.force and not _is_animation(out):
            raise SShaDeError(f"output {out} exists and is not an animation sshade wrote; choose another -o path "
                              "(or pass --force to replace it)")
        folder = out.parent
    elif out.exists() and not out.is_dir():
        raise SShaDeError(f"output {out} is a file; give a folder (or an .npz path)")
    else:
        foreign = [q.name for q in out.iterdir() if not (q.name.startswith("frame_") and written_by_sshade(q))] \
            if out.is_dir() else []
        if foreign:
            raise SShaDeError(f"output folder {out} holds files sshade did not write ({', '.join(sorted(foreign)[:3])}"
                              f"{', ...' if len(foreign) > 3 else ''}); choose a new or empty folder")
        folder = out.parent
    if not folder.is_dir():
        raise SShaDeError(f"output folder {folder} does not exist")


def _is_animation(path: Path) -> bool:
    try:
        with np.load(path, allow_pickle=False) as z:
            return NPZ_KEY in z.files
    except (OSError, ValueError):
        return False


def _frames(a, V) -> tuple[np.ndarray, np.ndarray]:
    """(handles (h,), targets (f, h, 3)) from the handle file and ``--frames``."""
    try:
        X = np.load(a.frames, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise SShaDeError(f"{a.frames}: not a readable .npy array ({e})") from None
    if not isinstance(X, np.ndarray) or X.ndim != 3 or len(X) == 0 or not np.issubdtype(X.dtype, np.number):
        raise SShaDeError(f"{a.frames}: expected (f, h, 3) targets or (f, 4, 4) matrices, got "
                          f"{getattr(X, 'shape', None)} of {getattr(X, 'dtype', None)}")
    X = np.asarray(X, np.float64)
    handles, moved = read_moving_handles(len(V), sel=a.sel, dmat=a.dmat, handles=a.handles)
    rest = V[handles]
    if X.shape[1:] == (4, 4) and not a.handles:
        T = np.repeat(rest[None], len(X), axis=0)
        for i, M in enumerate(X):
            T[i, moved] = apply_def(check_affine(M, f"{a.frames} frame {i}"), rest[moved])
        return handles, T
    if X.shape[1:] != (len(handles), 3):
        what = (f"with --handles the frames are (f, {len(handles)}, 3) targets, one per handle of {a.handles}"
                if a.handles else f"expected (f, {len(handles)}, 3) targets (one per selected vertex) or "
                                  "(f, 4, 4) matrices")
        raise SShaDeError(f"{a.frames}: {what}; got {X.shape}")
    return handles, X


def animate_file(a, log=print) -> dict:
    """Run ``python -m sshade animate`` for parsed arguments ``a`` (:func:`build_parser`).

    Returns
    -------
    dict ``prepare_s`` (seconds), ``frame_s`` (f,) seconds per solve, ``n_frames``, ``out``.

    Raises
    ------
    SShaDeError on bad input (usage, files, frames, mesh, parameters), before any output
    is written; OSError when writing fails.
    """
    if sum(map(bool, (a.sel, a.dmat, a.handles))) != 1:
        raise SShaDeError("give exactly one of --sel F.sel, --dmat F.dmat, --handles F.json|F.csv")
    _check_out(a)
    V, F = read_mesh(a.mesh, validate=False)  # prepare validates it
    handles, T = _frames(a, V)
    t0 = time.perf_counter()
    with prepare(V, F, handles, n_low=a.n_low, n_samplings=a.k, seed=a.seed) as prepared:  # n_low checked there
        prepare_s = time.perf_counter() - t0
        out = np.empty((len(T), len(V), 3))
        frame_s = np.empty(len(T))
        for i in tqdm(range(len(T)), desc="sshade animate", unit="frame", file=sys.stderr, disable=None):
            t = time.perf_counter()
            out[i] = prepared.solve(T[i])
            frame_s[i] = time.perf_counter() - t
    _write(a, out, prepared.F, frame_s)
    log(f"SShaDe: {a.mesh} ({len(V)} vertices), {len(handles)} handles, {len(T)} frames -> {a.out}")
    log(f"  prepare  {prepare_s:8.3f} s")
    log(f"  frame    {np.median(frame_s):8.3f} s median ({frame_s.min():.3f}-{frame_s.max():.3f})")
    return {"prepare_s": prepare_s, "frame_s": frame_s, "n_frames": len(T), "out": Path(a.out)}


def _write(a, out: np.ndarray, F: np.ndarray, frame_s: np.ndarray) -> None:
    """The frames into ``a.out`` (module docstring), each file atomically."""
    path = Path(a.out)
    if path.suffix.lower() == ".npz":
        buf = io.BytesIO()
        np.savez(buf, V=out, F=F, frame_s=frame_s, **{NPZ_KEY: np.array(1)})
        with atomic_write(path, "wb") as fh:
            fh.write(buf.getvalue())
        return
    path.mkdir(exist_ok=True)
    for q in path.glob("frame_*"):  # an earlier animation's frames (checked: sshade's)
        if q.is_file():
            q.unlink()
    for i, U in enumerate(out):
        write_mesh(path / f"frame_{i:04d}.{a.format}", U, F)


def main(argv: list[str]) -> int:
    """``python -m sshade animate ...`` with ``argv`` (the words after ``animate``);
    returns the exit status."""
    a = build_parser().parse_args(argv)
    return run_command(lambda: animate_file(a), where=a.out)

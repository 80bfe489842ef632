"""``python -m sshade animate``: deform one mesh through a sequence of handle targets with
SShaDe prepared once (:func:`sshade.prepared.prepare`) and solved per frame.

Usage::

    python -m sshade animate MESH (--sel F.sel | --dmat F.dmat | --handles F.json|F.csv)
        --frames FRAMES.npy -o OUT.npz|OUT.glb|FOLDER [--format obj|off|ply] [--fps FPS]
        [--n-low N] [--k K] [--seed S] [--force]

Frames, outputs and their rules: docs/implementation.md ("Implementation notes: sshade/animate.py").
"""
from __future__ import annotations

import os
import shutil
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .command_errors import ArgumentParser, run_command
from .errors import SShaDeError
from .files import atomic_write
from .json_file import regular_file
from .mesh.gltf import GlbAnimationWriter, check_glb_output, frames_tempfile, glb_extras
from .mesh.handle_files import apply_def, check_affine, read_moving_handles
from .mesh.io import read_mesh, write_mesh, written_by_sshade
from .mesh.validate import check_faces
from .prepared import prepare

__all__ = ["build_parser", "animate_file", "read_animation_npz", "NPZ_KEY", "DEFAULT_FPS"]

#: The key of an animation ``.npz`` that marks it as one (with ``V``, ``F``, ``frame_s``),
#: and of a ``.glb``'s ``asset.extras``.
NPZ_KEY = "sshade_animation"
FORMATS = ("obj", "off", "ply")
#: Frames per second of an animation's playback when ``--fps`` is not given (and of an
#: ``.npz`` written before it stored ``fps``).
DEFAULT_FPS = 24.0
#: The playback rates accepted (frames per second): keyframe times ``i / fps`` stay distinct
#: and finite in a ``.glb``'s float32 for a million frames.
FPS_RANGE = (1e-3, 1e4)


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
    p.add_argument("-o", "--out", required=True,
                   help="OUT.npz, OUT.glb (glTF 2.0, morph targets), or a folder for one mesh per frame")
    p.add_argument("--format", default="obj", choices=FORMATS, help="mesh format of a folder OUT (default obj)")
    p.add_argument("--fps", type=float, default=DEFAULT_FPS,
                   help=f"frames per second: a .glb's keyframe times, an .npz's playback rate "
                        f"(default {DEFAULT_FPS:g})")
    p.add_argument("--n-low", default="auto", help="SShaDe's low-resolution vertex count (int or auto)")
    p.add_argument("--k", type=int, default=5, help="SShaDe's number of samplings (default 5)")
    p.add_argument("--seed", type=int, default=0, help="SShaDe's seed (default 0)")
    p.add_argument("--force", action="store_true", help="replace an OUT.npz or OUT.glb that sshade did not write")
    return p


def _check_out(a) -> None:
    """The output checks (docs/implementation.md, "Implementation notes: sshade/animate.py"), before any work."""
    out = Path(a.out)
    if not FPS_RANGE[0] <= a.fps <= FPS_RANGE[1]:  # NaN fails too
        raise SShaDeError(f"--fps must be a number in [{FPS_RANGE[0]:g}, {FPS_RANGE[1]:g}], got {a.fps}")
    if out.suffix.lower() in (".npz", ".glb"):
        if out.is_dir():
            raise SShaDeError(f"output {out} is a folder; an {out.suffix.lower()} output is a file")
        if out.exists() and not a.force and not _is_animation(out):
            raise SShaDeError(f"output {out} exists and is not an animation sshade wrote; choose another -o path "
                              "(or pass --force to replace it)")
        folder = out.parent
    elif out.exists() and not out.is_dir():
        raise SShaDeError(f"output {out} is a file; give a folder (or an .npz or .glb path)")
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
    if path.suffix.lower() == ".glb":
        return NPZ_KEY in (glb_extras(path) or {})
    try:
        with np.load(path, allow_pickle=False) as z:
            return NPZ_KEY in z.files
    except (OSError, ValueError, EOFError):
        return False


def read_animation_npz(path) -> tuple[np.ndarray, np.ndarray, float]:
    """The frames of an ``.npz`` that :func:`animate_file` wrote.

    Returns
    -------
    V : (f, n, 3) float64, the frames (held in memory: 24 f n bytes). F : (m, 3) int64.
    fps : float, the playback rate it stores (:data:`DEFAULT_FPS` when it has none).

    Raises
    ------
    SShaDeError naming the file and the array: not a readable ``.npz``, not an animation
    (no ``sshade_animation`` mark), shapes, face indices out of range, a frame with NaN or
    inf (the first one named), a bad ``fps``.
    """
    regular_file(path, "animation")
    try:
        with np.load(path, allow_pickle=False) as z:
            if NPZ_KEY not in z.files:
                raise SShaDeError(f"{path}: not an animation of python -m sshade animate (no {NPZ_KEY!r} array; "
                                  f"it holds {', '.join(z.files[:5]) or 'nothing'})")
            V, F = z["V"], z["F"]
            fps = float(z["fps"]) if "fps" in z.files else DEFAULT_FPS
    except (OSError, ValueError, EOFError, KeyError, TypeError, zipfile.BadZipFile) as e:
        raise SShaDeError(f"{path}: not a readable animation .npz ({type(e).__name__}: {e})") from None
    if V.ndim != 3 or V.shape[0] == 0 or V.shape[2] != 3 or V.dtype.kind != "f":
        raise SShaDeError(f"{path}: V: expected (f, n, 3) floats, got {V.shape} of {V.dtype}")
    F = check_faces(F, V.shape[1], name=f"{path}: F")
    bad = np.flatnonzero(~np.isfinite(V).all(axis=(1, 2)))
    if len(bad):
        raise SShaDeError(f"{path}: V: frame {bad[0]} holds NaN or inf ({len(bad)} such frame(s))")
    if not FPS_RANGE[0] <= fps <= FPS_RANGE[1]:
        raise SShaDeError(f"{path}: fps: expected a number in [{FPS_RANGE[0]:g}, {FPS_RANGE[1]:g}], got {fps}")
    return V, F, fps


def _frames(a, V) -> tuple[np.ndarray, np.ndarray]:
    """(handles (h,), targets (f, h, 3)) from the handle file and ``--frames``."""
    regular_file(a.frames, "--frames file")
    try:
        with open(a.frames, "rb") as fh:
            head = fh.read(6)
    except OSError as e:
        raise SShaDeError(f"{a.frames}: cannot read it ({e.strerror or type(e).__name__})") from None
    if head != b"\x93NUMPY" and not head.startswith(b"PK\x03\x04"):  # a .npy, or an .npz refused below
        raise SShaDeError(f"{a.frames}: not a .npy file (it starts with {head!r}); --frames takes one array of "
                          "(f, h, 3) targets or (f, 4, 4) matrices written by numpy.save")
    try:
        X = np.load(a.frames, allow_pickle=False, mmap_mode="r")
    except (OSError, ValueError, EOFError) as e:
        raise SShaDeError(f"{a.frames}: not a readable .npy array ({e})") from None
    if isinstance(X, np.lib.npyio.NpzFile):  # an archive: its members are not read
        names = ", ".join(X.files[:5]) + (", ..." if len(X.files) > 5 else "")
        X.close()
        raise SShaDeError(f"{a.frames}: an .npz archive (arrays {names or 'none'}); --frames takes one .npy array "
                          "of (f, h, 3) targets or (f, 4, 4) matrices (np.save it)")
    if X.ndim != 3 or len(X) == 0 or X.dtype.kind not in "iuf":
        raise SShaDeError(f"{a.frames}: expected (f, h, 3) targets or (f, 4, 4) matrices of real numbers, got "
                          f"{X.shape} of {X.dtype}")
    X = np.array(X, np.float64)
    bad = np.argwhere(~np.isfinite(X))
    if len(bad):
        f, r = int(bad[0][0]), int(bad[0][1])
        raise SShaDeError(f"{a.frames}: frame {f}, row {r} is not finite ({X[f, r].tolist()}); "
                          f"{len(np.unique(bad[:, 0]))} frame(s) hold NaN or inf")
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

    Each frame is written as soon as it is solved (:class:`_FrameSink`): memory holds one
    frame, not the animation. Interrupted (Ctrl-C, SIGTERM) or failing after ``k`` frames,
    the output holds frames ``0 .. k-1``, whole, marked incomplete (an ``.npz``'s
    ``complete`` is False), and one stderr line says so; with no frame done nothing is
    written.

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
    if Path(a.out).suffix.lower() == ".glb":
        check_glb_output(a.out, len(V), len(F), len(T))
    t0 = time.perf_counter()
    frame_s = np.empty(len(T))
    with prepare(V, F, handles, n_low=a.n_low, n_samplings=a.k, seed=a.seed) as prepared:  # n_low checked there
        prepare_s = time.perf_counter() - t0
        with _FrameSink(a.out, a.format, prepared.F, len(T), len(V), log, rest=prepared.V, fps=a.fps) as sink:
            for i in tqdm(range(len(T)), desc="sshade animate", unit="frame", file=sys.stderr, disable=None):
                t = time.perf_counter()
                U = prepared.solve(T[i])
                frame_s[i] = time.perf_counter() - t
                sink.add(U, frame_s[i])
    log(f"SShaDe: {a.mesh} ({len(V)} vertices), {len(handles)} handles, {len(T)} frames -> {a.out}")
    log(f"  prepare  {prepare_s:8.3f} s")
    log(f"  frame    {np.median(frame_s):8.3f} s median ({frame_s.min():.3f}-{frame_s.max():.3f})")
    return {"prepare_s": prepare_s, "frame_s": frame_s, "n_frames": len(T), "out": Path(a.out)}


class _FrameSink:
    """The frames into ``out`` as they are solved (the outputs: docs/implementation.md,
    "Implementation notes: sshade/animate.py"); a context manager that finishes the output
    on leaving, marked incomplete when left by an exception after at least one frame (and
    says so on stderr), removed when no frame was done.

    An ``.npz``: frames appended to a temporary file beside it, packed at the end into
    the ``.npz`` (``V`` streamed in 1 MiB blocks, never held whole) written atomically.
    A ``.glb``: the same through :class:`~sshade.mesh.gltf.GlbAnimationWriter` (base: the
    rest positions ``rest``, keyframes every ``1 / fps`` s). A folder: ``frame_0000.<fmt>``
    ... each written atomically as its frame ends; an earlier animation's frames there are
    removed first, with a ``replacing`` line.

    Parameters
    ----------
    out : the output path. fmt : a folder's mesh format. F : (m, 3) int faces.
    n_frames : the frames planned. n : vertices per frame. log : the stdout printer.
    rest : (n, 3) float, the rest positions (a ``.glb``'s base; needed for one).
    fps : float > 0, frames per second (stored in an ``.npz``, a ``.glb``'s keyframes).
    """

    def __init__(self, out, fmt: str, F: np.ndarray, n_frames: int, n: int, log, *, rest=None,
                 fps: float = DEFAULT_FPS):
        self.path, self.fmt, self.F, self.n_frames, self.n, self.fps = Path(out), fmt, F, n_frames, n, float(fps)
        self.frame_s: list = []
        self.kind = self.path.suffix.lower() if self.path.suffix.lower() in (".npz", ".glb") else "folder"
        if self.kind == ".glb":
            self.glb = GlbAnimationWriter(self.path, rest, F, fps=self.fps)
            return
        if self.kind == ".npz":
            fd, self.tmp = frames_tempfile(self.path)
            self.fh = os.fdopen(fd, "wb")
            return
        old = [q for q in self.path.glob("frame_*") if q.is_file()] if self.path.is_dir() else []
        if old:  # an earlier animation's frames (checked: sshade's)
            log(f"replacing {len(old)} frame file(s) of an earlier animation in {self.path}")
            for q in old:
                q.unlink()
        self.path.mkdir(exist_ok=True)

    def add(self, U: np.ndarray, seconds: float) -> None:
        """Frame ``len(frame_s)``: (n, 3) float64 positions, solved in ``seconds``."""
        if self.kind == ".glb":
            self.glb.add(U)
        elif self.kind == ".npz":
            np.ascontiguousarray(U, "<f8").tofile(self.fh)
        else:
            write_mesh(self.path / f"frame_{len(self.frame_s):04d}.{self.fmt}", U, self.F)
        self.frame_s.append(float(seconds))

    def __enter__(self) -> _FrameSink:
        return self

    def __exit__(self, kind, exc, tb) -> bool:
        k, complete = len(self.frame_s), kind is None
        try:
            if self.kind == ".glb" and k:
                self.glb.finish({NPZ_KEY: 1, "complete": complete, "n_frames_planned": self.n_frames,
                                 "frame_s": self.frame_s, "fps": self.fps, "base": "the rest mesh"})
            elif self.kind == ".npz":
                self.fh.close()
                if k:
                    self._pack(complete)
        finally:
            if self.kind == ".glb":
                self.glb.close()
            elif self.kind == ".npz":
                Path(self.tmp).unlink(missing_ok=True)
        if k and not complete:
            mark = {".npz": " (its .npz says complete=False)", ".glb": " (its .glb says complete: false in "
                    "asset.extras)"}.get(self.kind, "")
            print(f"{self.path}: {k} of {self.n_frames} frames written (frames 0-{k - 1}, whole), the animation "
                  "stopped there" + mark, file=sys.stderr)
        return False

    def _pack(self, complete: bool) -> None:
        """The ``.npz``: ``V`` (k, n, 3) copied from the temporary file, ``F``, ``frame_s``,
        ``complete``, ``n_frames_planned``, ``fps`` and the :data:`NPZ_KEY` mark."""
        k = len(self.frame_s)
        small = {"F": np.asarray(self.F, np.int64), "frame_s": np.array(self.frame_s), "complete": np.array(complete),
                 "n_frames_planned": np.array(self.n_frames), "fps": np.array(self.fps), NPZ_KEY: np.array(1)}
        with atomic_write(self.path, "wb") as out, zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as z:
            with z.open("V.npy", "w", force_zip64=True) as m, open(self.tmp, "rb") as src:
                np.lib.format.write_array_header_1_0(m, {"descr": "<f8", "fortran_order": False,
                                                         "shape": (k, self.n, 3)})
                shutil.copyfileobj(src, m, 1 << 20)
            for name, arr in small.items():
                with z.open(f"{name}.npy", "w") as m:
                    np.lib.format.write_array(m, arr, allow_pickle=False)


def main(argv: list[str]) -> int:
    """``python -m sshade animate ...`` with ``argv`` (the words after ``animate``);
    returns the exit status."""
    a = build_parser().parse_args(argv)
    return run_command(lambda: animate_file(a), where=a.out)

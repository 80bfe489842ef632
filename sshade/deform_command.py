"""``python -m sshade deform`` (and :func:`main`, the entry point of ``python -m sshade``):
deform one mesh file with handles read from a file.

Usage::

    python -m sshade deform MESH -o OUT (--sel F.sel --def F.def | --dmat F.dmat --def F.def
        | --handles F.json|F.csv) [--method NAME] [--n-low N] [--k K] [--seed S]
        [--param KEY=VALUE ...] [--timeout SECONDS] [--repair] [--force]

Files, methods, checks and exit statuses: docs/implementation.md ("Implementation notes: sshade/deform_command.py").
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .animate import main as animate_main
from .command_errors import run_command
from .components import drop_unreferenced
from .errors import SShaDeError
from .guard import check_timeout, handle_error, handles_not_reached, run_method
from .mesh.handle_files import read_def, read_dmat_selection, read_handle_file, read_sel, selection_handles
from .mesh.io import read_mesh, write_mesh, written_by_sshade
from .mesh.repair import repair_mesh
from .params import check_params
from .pipeline import SShaDe
from .refine import SShaDeRefine
from .view import main as view_main
from .warmup_command import main as warmup_main

__all__ = ["main", "deform_main", "build_parser", "deform_file", "parse_param", "sshade_method"]

OUT_EXTS = (".obj", ".off", ".ply")


class _Parser(argparse.ArgumentParser):
    """argparse with usage errors on one line (``error: ...``) and exit status 2."""

    def error(self, message):  # noqa: D102 -- argparse hook
        print(f"error: {message} ({self.prog} --help)", file=sys.stderr)
        raise SystemExit(2)


def build_parser(prog: str = "python -m sshade") -> argparse.ArgumentParser:
    """The argument parser of ``<prog> deform`` (module docstring)."""
    p = _Parser(prog=f"{prog} deform",
                description="Deform one mesh with handles read from a file (SShaDe by default).")
    p.add_argument("mesh", help="input mesh (.obj, .off, .ply)")
    p.add_argument("-o", "--out", required=True, help="output mesh (.obj, .off, .ply), written atomically")
    g = p.add_argument_group("handles (one of)")
    g.add_argument("--sel", help="deformation-benchmark selection: one line per vertex, 0 fixed, 1 free, 2 handle")
    g.add_argument("--dmat", help="libigl .dmat selection: -1 free, 0 fixed, >= 1 handle")
    g.add_argument("--def", dest="def_", metavar="DEF", help="4x4 matrix applied to the handle vertices")
    g.add_argument("--handles", help=".json {handles: [...], targets: [[x,y,z],...]} or .csv rows index,x,y,z")
    p.add_argument("--method", default="SShaDe",
                   help="SShaDe (default) or SShaDe+refine; python -m harness deform also ARAP, Elastic, "
                        "ARAP-SR, ... or a plug-in pkg.module.Class")
    p.add_argument("--n-low", help="SShaDe's low-resolution vertex count (int or auto; default auto)")
    p.add_argument("--k", type=int, help="SShaDe's number of samplings (default 5)")
    p.add_argument("--seed", type=int, help="SShaDe's seed (default 0)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="any other parameter of the method (repeatable), e.g. --param workers=1")
    p.add_argument("--timeout", metavar="SECONDS",
                   help="limit of the method's run in seconds (main thread, Python code; sshade/guard.py); "
                        "a longer run is an error and no output is written")
    p.add_argument("--repair", action="store_true",
                   help="apply pymeshlab's vertex-preserving repair filters first and report what changed")
    p.add_argument("--force", action="store_true",
                   help="allow OUT to be the input mesh or an existing file that sshade did not write")
    return p


def parse_param(text: str) -> tuple[str, object]:
    """``"key=value"`` -> ``(key, value)`` with value an int, float, bool, None
    (``null``/``none``) or str. Raises SShaDeError on a missing ``=`` or key."""
    key, sep, val = str(text).partition("=")
    if not sep or not key.strip():
        raise SShaDeError(f"--param {text!r}: expected KEY=VALUE")
    v = val.strip()
    low = v.lower()
    if low in ("null", "none"):
        return key.strip(), None
    if low in ("true", "false"):
        return key.strip(), low == "true"
    for cast in (int, float):
        try:
            return key.strip(), cast(v)
        except ValueError:
            pass
    return key.strip(), v


def _check_args(a) -> None:
    """Usage checks that need no file: one handle source, output extension."""
    sources = [bool(a.sel), bool(a.dmat), bool(a.handles)]
    if sum(sources) != 1:
        raise SShaDeError("give exactly one of --sel F.sel --def F.def, --dmat F.dmat --def F.def, "
                          "--handles F.json|F.csv")
    if (a.sel or a.dmat) and not a.def_:
        raise SShaDeError(f"--{'sel' if a.sel else 'dmat'} needs --def F.def (the matrix moving the handles)")
    if a.handles and a.def_:
        raise SShaDeError("--def goes with --sel or --dmat, not with --handles (which holds the targets)")
    if Path(a.out).suffix.lower() not in OUT_EXTS:
        raise SShaDeError(f"output {a.out}: unsupported format {Path(a.out).suffix or '(none)'!r}; "
                          f"use one of {list(OUT_EXTS)}")
    if Path(a.mesh).suffix.lower() == ".stl":
        raise SShaDeError(f"{a.mesh}: an STL file has no vertex indices (a triangle soup, merged on reading), so "
                          "the vertex indices of --sel/--dmat/--handles would land on other vertices; convert "
                          "the mesh to OBJ, OFF or PLY first and make the handle file for that")
    _check_out(a)


def _same_file(a_path: Path, b_path: Path) -> bool:
    try:
        return a_path.resolve() == b_path.resolve() or os.path.samefile(a_path, b_path)
    except OSError:
        return False


def _check_out(a) -> None:
    """Checks of ``-o OUT`` before any work: its folder exists and takes a new file; OUT
    is not an input file, nor an existing file sshade did not write, unless ``--force``.
    Sets ``a.replacing`` when OUT exists (and may be replaced)."""
    out = Path(a.out)
    force = getattr(a, "force", False)
    a.replacing = out.exists()
    if out.is_dir():
        raise SShaDeError(f"output {out} is a folder; give a file path")
    inputs = [(k, getattr(a, k, None)) for k in ("mesh", "sel", "dmat", "def_", "handles")]
    for k, path in inputs:
        if path and a.replacing and _same_file(out, Path(path)) and not force:
            raise SShaDeError(f"output {out} is the input {'mesh' if k == 'mesh' else k.rstrip('_') + ' file'} "
                              "itself; choose another -o path (or pass --force to overwrite it)")
    if a.replacing and not force and not written_by_sshade(out):
        raise SShaDeError(f"output {out} exists and was not written by sshade; choose another -o path (or pass "
                          "--force to replace it)")
    folder = out.parent
    if not folder.is_dir():
        raise SShaDeError(f"output folder {folder} does not exist")
    try:  # the real test of "can a file be created there" (permissions, read-only mounts)
        fd, probe = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".probe", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise SShaDeError(f"output folder {folder} is not writable ({e.strerror or type(e).__name__})") from None


def sshade_method(name: str, params: dict):
    """The method of ``--method`` in ``python -m sshade deform``: ``SShaDe`` or
    ``SShaDe+refine`` (case-insensitive) with ``params`` over the defaults of
    :class:`sshade.params.SShaDeParams`, but ``n_low`` auto.

    Raises
    ------
    SShaDeError for another name (it names ``python -m harness deform``, which runs every
    method) or a parameter the method does not have; what the method's checks raise.
    """
    key = str(name).strip().lower()
    if key not in ("sshade", "sshade+refine"):
        raise SShaDeError(f"--method {name}: python -m sshade deform runs SShaDe and SShaDe+refine; "
                          f"python -m harness deform runs every method (the same options)")
    refine = {k: params.pop(k) for k in ("refine_etol", "refine_gtol", "refine_max_iter") if k in params}
    if refine and key == "sshade":
        raise SShaDeError(f"SShaDe has no parameter {sorted(refine)[0]!r} (SShaDe+refine has)")
    label = "SShaDe" if key == "sshade" else "SShaDe+refine"
    try:
        p = check_params({"n_low": "auto"}, **params)  # the commands' n_low, as conf/config.yaml's sshade.n_low
    except SShaDeError as e:
        raise SShaDeError(str(e).replace("SShaDe: ", f"{label}: ", 1)) from None
    return SShaDe.from_params(p) if key == "sshade" else SShaDeRefine.from_params(p, **refine)


def _method(a, resolve):
    """The method of ``--method`` with ``--n-low``/``--k``/``--seed``/``--param``."""
    params = dict(parse_param(t) for t in a.param)
    for key, val in (("n_low", a.n_low), ("n_samplings", a.k), ("seed", a.seed)):
        if val is not None:
            params[key] = parse_param(f"x={val}")[1] if key == "n_low" else val
    return resolve(a.method, params)


def _read_handles(a, V):
    """(handles, targets) of the chosen handle files, for the mesh as read."""
    if a.handles:
        return read_handle_file(a.handles, len(V))
    M = read_def(a.def_)
    status = read_sel(a.sel, len(V)) if a.sel else read_dmat_selection(a.dmat, len(V))
    return selection_handles(V, status, M)


def _carry(origin, handles, targets, n_old):
    """Handles of the input's vertices carried to new vertices (``origin[i]``: the input
    vertex of new vertex ``i``): a new vertex is a handle when its origin is one."""
    tgt = np.full((n_old, 3), np.nan)
    tgt[handles] = targets
    is_h = np.zeros(n_old, bool)
    is_h[handles] = True
    new_h = np.flatnonzero(is_h[origin]).astype(np.int64)
    return new_h, tgt[origin[new_h]]


def deform_file(a, log=print, warn=None, resolve=sshade_method) -> dict:
    """Run ``python -m sshade deform`` for parsed arguments ``a`` (:func:`build_parser`).

    Parameters
    ----------
    a : argparse.Namespace. log : callable printing a line (stage times, report).
    warn : callable printing a warning line (default: ``warning: ...`` on stderr).
    resolve : callable ``(name, params) -> method`` building ``--method``
        (:func:`sshade_method`; the harness passes its registry's).

    Returns
    -------
    dict with ``times`` (stage -> seconds), ``n_vertices``, ``n_faces``, ``n_handles``,
    ``info`` (the method's info, with ``n_components`` for several components), ``out``.

    Raises
    ------
    SShaDeError on bad input (files, handles, mesh), before the output is written.
    """
    warn = warn or (lambda s: print(f"warning: {s}", file=sys.stderr))
    _check_args(a)
    method = _method(a, resolve)  # a bad method or parameter fails before any file is read
    timeout_s = check_timeout(getattr(a, "timeout", None), "--timeout")
    times: dict[str, float] = {}
    stages = ["read", "handles", *(["repair"] if a.repair else []), "deform", "write"]
    bar = tqdm(total=len(stages), desc="sshade deform", unit="stage", file=sys.stderr, disable=None, leave=False)

    def stage(name):
        bar.set_postfix_str(name)
        return time.perf_counter()

    def done(name, t0):
        times[name] = time.perf_counter() - t0
        bar.update(1)

    with bar:
        t = stage("read")
        V, F = read_mesh(a.mesh, validate=False)
        done("read", t)
        n_in = len(V)
        t = stage("handles")
        handles, targets = _read_handles(a, V)
        done("handles", t)
        origin = np.arange(n_in)
        if a.repair:
            t = stage("repair")
            V, F, origin, report = repair_mesh(V, F)
            done("repair", t)
            changes = [f"{what}: {abs(dv) if dv else abs(df)}" for what, dv, df in report if dv or df]
            log(f"repair: {'; '.join(changes) if changes else 'nothing to repair'} "
                f"({n_in} -> {len(V)} vertices, {len(F)} faces)")
        V, F, kept = drop_unreferenced(V, F)
        if len(kept) < len(origin):
            lost = np.setdiff1d(handles, origin[kept]).size
            warn(f"dropped {len(origin) - len(kept)} unreferenced vertices (on no face)"
                 f"{f', {lost} of them handles' if lost else ''}; {a.out} has {len(V)} vertices, not {n_in}")
        origin = origin[kept]
        if len(V) != n_in or not np.array_equal(origin, np.arange(n_in)):
            handles, targets = _carry(origin, handles, targets, n_in)
            if len(handles) == 0:
                raise SShaDeError("no handle is left on the mesh's faces")
        t = stage("deform")
        try:  # guarded: read-only inputs, exceptions and time-out, output checked (sshade/guard.py)
            res = run_method(method, V, F, handles, targets, timeout_s=timeout_s)
        except SShaDeError as e:
            hint = " (--repair applies pymeshlab's safe repair filters)" if not a.repair and str(e).startswith(
                "mesh:") and any(w in str(e) for w in ("non-manifold", "duplicate", "degenerate")) else ""
            raise SShaDeError(f"{e}{hint}") from None
        Vd, info = res.U, res.info
        miss = handles_not_reached(handle_error(Vd, handles, targets, float(np.linalg.norm(np.ptp(V, axis=0)))))
        if miss:
            raise SShaDeError(f"{method.name}: {miss}")
        done("deform", t)
        for w in res.warnings:
            warn(w)
        t = stage("write")
        if getattr(a, "replacing", False):
            log(f"replacing {a.out}")
        try:
            write_mesh(a.out, Vd, F)
        except OSError as e:
            raise SShaDeError(f"cannot write {a.out} ({e.strerror or e})") from None
        done("write", t)
    ncomp = info.get("n_components", 1)
    log(f"{method.name}: {a.mesh} ({len(V)} vertices, {len(F)} faces, {ncomp} component"
        f"{'s' if ncomp > 1 else ''}), {len(handles)} handles -> {a.out}")
    for k, v in times.items():
        log(f"  {k:<8} {v:8.3f} s")
    log(f"  {'total':<8} {sum(times.values()):8.3f} s")
    return {"times": times, "n_vertices": len(V), "n_faces": len(F), "n_handles": len(handles), "info": info,
            "out": Path(a.out)}


def main(argv=None) -> int:
    """Entry point of ``python -m sshade``: ``deform ...`` (module docstring), ``animate ...``
    (:mod:`sshade.animate`), ``view ...`` (:mod:`sshade.view`) or ``warmup``
    (:mod:`sshade.warmup_command`).

    Returns the exit status (0 success, 2 bad input, usage or an OSError, after one
    ``error:`` line on stderr; 130 after ``interrupted`` on Ctrl-C).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: python -m sshade deform MESH -o OUT (--sel F.sel --def F.def | --dmat F.dmat --def F.def | "
              "--handles F.json|F.csv) [--method NAME] [--n-low N] [--k K] [--seed S] [--param KEY=VALUE] "
              "[--repair]\n       python -m sshade animate MESH (--sel F.sel | --dmat F.dmat | --handles F.json) "
              "--frames FRAMES.npy -o OUT.npz|OUT.glb|FOLDER [--fps FPS]\n"
              "       python -m sshade view MESH (--sel F.sel | --dmat F.dmat | --handles F.json)\n"
              "       python -m sshade view ANIMATION.npz|ANIMATION.glb\n"
              "       python -m sshade warmup\n"
              "(python -m sshade deform|animate|view|warmup --help for details)",
              file=sys.stderr if not argv else sys.stdout)
        return 2 if not argv else 0
    if argv[0] == "animate":
        return animate_main(argv[1:])
    if argv[0] == "view":
        return view_main(argv[1:])
    if argv[0] == "warmup":
        return warmup_main(argv[1:])
    if argv[0] != "deform":
        print(f"error: unknown command {argv[0]!r}; the commands are `python -m sshade deform MESH -o OUT ...`, "
              "`python -m sshade animate MESH ... --frames FRAMES.npy -o OUT`, `python -m sshade view MESH ...` "
              "and `python -m sshade warmup`",
              file=sys.stderr)
        return 2
    return deform_main(argv[1:])


def deform_main(argv, *, prog: str = "python -m sshade", resolve=sshade_method, run=run_command) -> int:
    """``<prog> deform ARGS`` (module docstring) for the arguments after ``deform``:
    ``--method`` built by ``resolve`` (:func:`sshade_method`; ``python -m harness deform``
    passes :func:`harness.method_registry.named_or_plugin`), the work run by ``run``
    (:func:`sshade.command_errors.run_command`: its exit statuses)."""
    a = build_parser(prog).parse_args(argv)
    return run(lambda: deform_file(a, resolve=resolve), where=a.out)

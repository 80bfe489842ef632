"""The first call of a fresh process, for the scaling benchmark: what a command-line user
pays for one :func:`sshade.deform` on a mesh, numba's on-disk cache already warm (the
benchmark's in-process warm-up fills it) but nothing compiled or loaded in the process.

``python -m eval.experiments.scaling.probe MESH HANDLES.npz PARAMS.json [--t0 EPOCH]``
prints one JSON line (:func:`first_call`'s dict, plus ``import_s`` when ``--t0`` gives
the wall-clock time at which the parent launched it). :func:`probe_first_call` is the
parent's side: it writes the handles and parameters, runs this module with
``subprocess.run`` and never raises.
"""
from __future__ import annotations

import json
import logging
import math
import os
import subprocess
import sys
import tempfile
import time
from argparse import ArgumentParser
from pathlib import Path

import numpy as np

from sshade import deform
from sshade.mesh.io import read_mesh

log = logging.getLogger(__name__)

__all__ = ["first_call", "probe_first_call", "main"]

_ROOT = Path(__file__).resolve().parents[2]  # the checkout holding eval/ and sshade/
_NAN = {"first_call_s": math.nan, "first_call_import_s": math.nan, "first_call_read_s": math.nan,
        "first_call_compile_s": math.nan}


def first_call(mesh_path, handles_npz, params_json) -> dict:
    """Time the first :func:`sshade.deform` call of this process.

    Parameters
    ----------
    mesh_path : str or Path, the mesh (read without validation, so that no numba kernel
        is loaded before the call; ``deform`` validates it).
    handles_npz : str or Path, an ``.npz`` with ``handles`` (h,) int64 and ``targets``
        (h, 3) float64.
    params_json : str or Path, a JSON object of :func:`sshade.deform`'s keyword
        parameters (:func:`sshade.pipeline.check_params`'s output).

    Returns
    -------
    dict: ``first_call_s`` (seconds of the call, numba's cache loads included),
    ``compile_s`` (the part of it ``deform`` reports as compilation / cache loads),
    ``read_s`` (seconds to read the mesh, handles and parameters, not in ``first_call_s``),
    ``vertices``.

    Raises
    ------
    SShaDeError (bad mesh, handles or parameter), OSError / ValueError (unreadable files).
    """
    t0 = time.perf_counter()
    V, F = read_mesh(mesh_path, validate=False)
    with np.load(handles_npz) as z:
        h, T = np.asarray(z["handles"], np.int64), np.asarray(z["targets"], np.float64)
    params = json.loads(Path(params_json).read_text())
    t1 = time.perf_counter()
    _, info = deform(V, F, h, T, return_info=True, **params)
    t2 = time.perf_counter()
    return {"first_call_s": t2 - t1, "compile_s": float(info["compile_s"]), "read_s": t1 - t0,
            "vertices": int(len(V))}


def probe_first_call(mesh_path, handles: np.ndarray, targets: np.ndarray, params: dict, *,
                     timeout_s: float = 600.0) -> dict:
    """Run :func:`first_call` in a fresh Python process (this checkout first on its path).

    Parameters
    ----------
    mesh_path : str or Path, the mesh file. handles : (h,) int; targets : (h, 3) float64.
    params : dict, JSON-serialisable keyword parameters of :func:`sshade.deform`.
    timeout_s : float, seconds before the child is killed.

    Returns
    -------
    dict ``first_call_s``, ``first_call_import_s`` (interpreter start and imports),
    ``first_call_read_s``, ``first_call_compile_s``: seconds; all NaN, with a logged
    warning, when the child fails, times out or prints no result (never raises).
    """
    path = os.pathsep.join([str(_ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env = dict(os.environ, PYTHONPATH=path)
    try:
        with tempfile.TemporaryDirectory(prefix="sshade-probe-") as d:
            hp, pp = Path(d) / "handles.npz", Path(d) / "params.json"
            np.savez(hp, handles=np.asarray(handles, np.int64), targets=np.asarray(targets, np.float64))
            pp.write_text(json.dumps(params))
            cmd = [sys.executable, "-m", "eval.experiments.scaling.probe", str(mesh_path), str(hp), str(pp),
                   "--t0", repr(time.time())]
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, env=env, check=False)
        if p.returncode != 0:
            tail = (p.stderr.strip().splitlines() or ["no output"])[-1]
            raise RuntimeError(f"exit status {p.returncode}: {tail}")
        r = json.loads(p.stdout.strip().splitlines()[-1])
        return {"first_call_s": float(r["first_call_s"]), "first_call_import_s": float(r.get("import_s", math.nan)),
                "first_call_read_s": float(r["read_s"]), "first_call_compile_s": float(r["compile_s"])}
    except subprocess.TimeoutExpired:
        log.warning("scaling: first-call probe on %s ran past %gs; first_call_s is NaN", mesh_path, timeout_s)
    except (OSError, RuntimeError, ValueError, KeyError, IndexError, TypeError) as e:
        log.warning("scaling: first-call probe on %s failed (%s); first_call_s is NaN", mesh_path, e)
    return dict(_NAN)


def main(argv=None) -> int:
    """Command line of the probe: print :func:`first_call`'s dict as one JSON line
    (with ``import_s`` when ``--t0`` is given); exit status 0, or 2 after one
    ``error: ...`` line on stderr."""
    t_main = time.time()
    ap = ArgumentParser(prog="python -m eval.experiments.scaling.probe", description=__doc__.split("\n\n")[0])
    ap.add_argument("mesh")
    ap.add_argument("handles_npz")
    ap.add_argument("params_json")
    ap.add_argument("--t0", type=float, default=None, help="the parent's time.time() at launch")
    a = ap.parse_args(argv)
    try:
        r = first_call(a.mesh, a.handles_npz, a.params_json)
    except Exception as e:  # noqa: BLE001 - reported to the parent as one line
        print(f"error: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    r["import_s"] = (t_main - a.t0) if a.t0 is not None else math.nan
    print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())

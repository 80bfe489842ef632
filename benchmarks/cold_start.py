"""The first call of a fresh process, on a cold numba cache and on a filled one, for this
code and for an earlier commit's.

Each probe is a new Python process with its own ``NUMBA_CACHE_DIR``: first on an empty
folder (cold: a fresh install, an upgrade, a new node), then again on the folder the cold
probe filled (warm). A probe times its import of sshade, its first call and a second call
in the same process. The cases:

- ``bunny (API)``: the README's Python API example (``sshade.deform``, 3,485 vertices,
  n_low 1000, k 5, seed 0);
- ``bunny (command)``: ``python -m sshade deform`` on the same mesh and handles (the whole
  command's wall time; no second call);
- ``bunny ARAP`` / ``Elastic`` / ``ARAP-SR``: the baselines' ``deform`` (converged protocol);
- ``centaur (hard)``: SShaDe (n_low 6000, k 5) on the LS3 centaur at about 200k vertices
  (``eval.experiments.scaling``'s hard mesh and edit, built once into ``--cache``).

    python benchmarks/cold_start.py [--before COMMIT] [--cache data/scaling] [--out DIR]

``--before COMMIT`` also runs every probe on that commit's code (``git archive`` into a
temporary folder, put first on the probes' ``PYTHONPATH``). With ``--out`` it writes
table.md and table.csv into a folder that is new, empty or this benchmark's earlier output.
"""
import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the repository, as the other benchmarks

from eval.datasets.shapes import axis_handles, axis_landmarks  # noqa: E402
from eval.experiments.scaling.mesh_set import MeshEntry  # noqa: E402
from eval.experiments.scaling.scaling_experiment import size_mesh  # noqa: E402
from eval.run.outdir import claim_output_dir  # noqa: E402
from eval.run.runinfo import git_info  # noqa: E402
from harness.command import run_command  # noqa: E402
from sshade.cores import available_cores  # noqa: E402
from sshade.errors import SShaDeError  # noqa: E402
from sshade.mesh.io import read_mesh  # noqa: E402

BUNNY = ROOT.parent / "shared" / "data" / "classic" / "bunny.off"
CENTAUR = ROOT.parent / "shared" / "data" / "tosca" / "centaur0.off"

#: The code the probes run in their own processes (PROBE and ``python -m sshade``), which
#: no import of this file names: held with its imports by eval.run.stale_runs
CODE_ROOTS = ("sshade.deform", "sshade.__main__", "baselines.ARAP", "baselines.Elastic", "baselines.ARAPSR")

# One probe: python -c PROBE CASE NPZ -> one JSON line (import_s, first_s, second_s, module)
PROBE = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy as np
import sshade
from sshade import deform
case, npz = sys.argv[1], np.load(sys.argv[2])
V, F, h, T = npz["V"], npz["F"], npz["handles"], npz["targets"]
if case.startswith("sshade"):
    run = lambda: deform(V, F, h, T, n_low=int(npz["n_low"]), n_samplings=5, seed=0)
else:
    import baselines
    cls = {"ARAP": baselines.ARAP, "Elastic": baselines.Elastic, "ARAP-SR": baselines.ARAPSR}[case]
    run = lambda: cls().deform(V, F, h, T)
t1 = time.perf_counter()
run()
t2 = time.perf_counter()
run()
t3 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "first_s": t2 - t1, "second_s": t3 - t2, "module": sshade.__file__}))
"""


def _bunny_problem():
    """The README's API example: 50 lowest vertices fixed, 50 highest moved 15 % of the diagonal."""
    V, F = read_mesh(BUNNY)
    diag = np.linalg.norm(V.max(0) - V.min(0))
    order = np.argsort(V[:, 1])
    h = np.r_[order[:50], order[-50:]]
    T = V[h].copy()
    T[50:] += [0.15 * diag, 0, 0]
    return V, F, h, T


def _centaur_problem(cache: Path):
    """The scaling experiment's hard centaur at about 200k vertices and its edit."""
    entry = MeshEntry("centaur", str(CENTAUR), False)
    V0, F0 = read_mesh(CENTAUR)
    _, V, F, _ = size_mesh(entry, V0, F0, 200_000, cache)
    lm, center, axes = axis_landmarks(V0)
    h, T, _, _ = axis_handles(V, lm, center, axes)
    return V, F, h, T


def _probe(case: str, npz: Path, code: Path | None, numba_cache: Path, cli: list | None) -> dict:
    """One fresh process on ``numba_cache``; ``cli``: time that command instead of PROBE."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(numba_cache))
    if code is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(code), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    t = time.perf_counter()
    cmd = cli if cli else [sys.executable, "-c", PROBE, case, str(npz)]
    r = subprocess.run(cmd, cwd=npz.parent, env=env, capture_output=True, text=True, timeout=1800)
    wall = time.perf_counter() - t
    if r.returncode != 0:
        raise SShaDeError(f"probe {case} ({code or 'this code'}) failed: {r.stderr.strip().splitlines()[-1:]}")
    if cli:
        return {"first_s": wall, "import_s": float("nan"), "second_s": float("nan"), "notice": "compiling" in r.stderr}
    out = json.loads(r.stdout.strip().splitlines()[-1])
    want = str(code) if code is not None else str(ROOT)
    if not out["module"].startswith(want):
        raise SShaDeError(f"probe {case}: imported {out['module']}, not the code under test ({want})")
    return dict(out, notice="compiling" in r.stderr)


def _cases(tmp: Path, cache: Path) -> list:
    """(label, probe case, npz, command or None) for every case of the module docstring."""
    bunny = tmp / "bunny.npz"
    V, F, h, T = _bunny_problem()
    np.savez(bunny, V=V, F=F, handles=h, targets=T, n_low=1000)
    (tmp / "bunny.json").write_text(json.dumps({"handles": h.tolist(), "targets": T.tolist()}))
    cli = [sys.executable, "-m", "sshade", "deform", str(BUNNY), "--handles", str(tmp / "bunny.json"),
           "--n-low", "1000", "-o", str(tmp / "out.obj"), "--force"]
    cen = tmp / "centaur.npz"
    V, F, h, T = _centaur_problem(cache)
    np.savez(cen, V=V, F=F, handles=h, targets=T, n_low=6000)
    nb = len(_bunny_problem()[0])
    return [(f"bunny (API), {nb} v", "sshade", bunny, None),
            ("bunny (command)", "sshade-cli", bunny, cli),
            ("bunny ARAP", "ARAP", bunny, None), ("bunny Elastic", "Elastic", bunny, None),
            ("bunny ARAP-SR", "ARAP-SR", bunny, None),
            (f"centaur (hard), {len(V)} v", "sshade", cen, None)]


def _rows(tmp: Path, codes: dict, cases: list) -> list:
    rows = []
    for label, case, npz, cli in cases:
        for name, code in codes.items():
            nb = Path(tempfile.mkdtemp(dir=tmp, prefix="numba-"))
            cold = _probe(case, npz, code, nb, cli)
            warm = _probe(case, npz, code, nb, cli)
            row = {"case": label, "code": name, "cold_first_s": cold["first_s"], "warm_first_s": warm["first_s"],
                   "second_s": cold["second_s"], "import_s": cold["import_s"], "cold_notice": cold["notice"],
                   "warm_notice": warm["notice"]}
            print(json.dumps(row), flush=True)
            rows.append(row)
    return rows


def _s(x: float) -> str:
    return "-" if x != x else f"{x:.2f}"


def _table(rows: list) -> str:
    head = ("| Case | Code | Cold first call (s) | Warm first call, fresh process (s) | Second call (s) | Cold / warm "
            "| Notice (cold / warm) |\n|---|---|---:|---:|---:|---:|---|\n")
    body = "".join(f"| {r['case']} | {r['code']} | {r['cold_first_s']:.2f} | {r['warm_first_s']:.2f} | "
                   f"{_s(r['second_s'])} | "
                   f"{r['cold_first_s'] / r['warm_first_s']:.1f}x | {'yes' if r['cold_notice'] else 'no'} / "
                   f"{'yes' if r['warm_notice'] else 'no'} |\n" for r in rows)
    return head + body


def main(a) -> int:
    for p in (BUNNY, CENTAUR):
        if not p.is_file():
            raise SShaDeError(f"{p} not found (../shared/data)")
    claim = claim_output_dir(a.out, "cold_start", option="", name="--out") if a.out else None
    gi = git_info()
    with claim or contextlib.nullcontext(), tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        codes = {f"this ({str(gi.get('commit'))[:7]}{', dirty' if gi.get('dirty') else ''})": None}
        if a.before:
            old = tmp / "before"
            old.mkdir()
            arch = subprocess.run(["git", "-C", str(ROOT), "archive", a.before], capture_output=True, check=False)
            if arch.returncode != 0:
                raise SShaDeError(f"--before {a.before}: git archive failed ({arch.stderr.decode().strip()})")
            subprocess.run(["tar", "-x", "-C", str(old)], input=arch.stdout, check=True)
            codes = {f"before ({a.before[:7]})": old, **codes}
        rows = _rows(tmp, codes, _cases(tmp, Path(a.cache)))
        table = _table(rows)
        print("\n" + table)
        if claim is not None:
            import pandas as pd
            pd.DataFrame(rows).to_csv(claim.path / "table.csv", index=False, float_format="%.4g")
            (claim.path / "table.md").write_text(
                f"### The first call of a fresh process: cold numba cache, then filled\n\n{table}\n"
                f"Made by `python benchmarks/cold_start.py{' --before ' + a.before if a.before else ''}` at git "
                f"commit {gi.get('commit')} (dirty: {gi.get('dirty')}) on {available_cores()} cores. Each probe is "
                "a new process; cold: an empty NUMBA_CACHE_DIR, warm: the one the cold probe filled; second call: "
                "the same call again in the cold process. Notice: whether the probe printed the cold-cache line. "
                "The cases: the benchmark's docstring.\n")
    return 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", help="also probe this commit's code (e.g. the commit before a change)")
    ap.add_argument("--cache", default="data/scaling", help="where built meshes are kept (the scaling experiment's)")
    ap.add_argument("--out", help="also write table.md and table.csv into this folder")
    args = ap.parse_args()
    raise SystemExit(run_command(lambda: main(args), where=args.out))

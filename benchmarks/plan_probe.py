"""What the plan's probe says against what the solvers do, on this machine: the numbers
that calibrate ``eval/run/machine_speed.py`` across machines, measured in one run.

    python benchmarks/plan_probe.py [--rounds 5] [--copies 2] [--build]

Each line is one kind of work, timed as its wall seconds, the least of ``--rounds`` rounds
after an untimed one (numba's cache loaded, or compiled once there):

- ``probe, runs`` and ``probe, build``: ``probe_seconds()`` as the plan runs it (``--copies``
  spawned processes at once, ``harness.jobs.run_jobs``, one core each, as the evaluator runs
  its pairs; the plan's factors are these over ``PROBE_REFERENCE_S``), the least of
  ``--rounds`` calls;
- the same with 1 copy: the work alone;
- ``ARAP-SR paper, twisted bar``: ``baselines.ARAPSR(alpha=0.01, alpha_scaling="valence",
  protocol="paper", max_iter=30)`` on ``sshade.arap.problems`` ``twisted_bar`` (5,136
  vertices), in this process at the default threads (as the asv benchmark
  ``fullres.ArapSrPaper`` times it), then in ``--copies`` spawned processes at once;
- ``Elastic, twisted bar``: ``baselines.Elastic()`` (converged) on the same case, the same two
  ways (its iterations are printed: they may differ by a few across machines);
- with ``--build``, the work the build probe stands for: ``python -m defaust`` of subjects 0
  and 1 into a temporary folder (every core, as the README's main job builds them; about
  90-110 s on 2 cores), timed whole, beside the plan's prior for it (``BUILD_START_S`` plus
  one round of ``BUILD_S_PER_SUBJECT``): their ratio is the build's speed, and the build
  probe's least reading over it is what ``PROBE_REFERENCE_S["build"]`` would be on this
  machine (the runs' counterpart needs a DeFAUST pair: the README's main job, its
  ``run.json``).

A process line is the slowest copy's least round, every round started by all copies
together at a barrier (as the probe starts its rounds). Run it quiet; record: benchmarks/records/machine_speed.md.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import platform
import subprocess
import threading
import time

from harness.jobs import run_jobs

_STATE: dict = {}


def _solver(kind: str):
    from baselines import ARAPSR, Elastic
    from sshade.arap.problems import CASES
    V, F, h, T = CASES["twisted_bar"]()
    if kind == "srpaper":
        method = ARAPSR(alpha=0.01, alpha_scaling="valence", protocol="paper", max_iter=30)
    else:
        method = Elastic()

    def run():
        method.deform(V, F, h, T)
        return method.info.get("iterations")
    return run


def _setup(kind: str, barrier=None) -> None:
    """A worker's ``init``: its work made ready and run once, untimed."""
    _STATE["run"] = _solver(kind)
    _STATE["barrier"] = barrier
    _STATE["run"]()


def _rounds(rounds: int) -> list[float]:
    """A worker's job: ``rounds`` timed rounds, each started with the other copies at the
    barrier (a broken or absent barrier: alone), as the probe starts its rounds."""
    out = []
    for _ in range(rounds):
        if _STATE["barrier"] is not None:
            try:
                _STATE["barrier"].wait(120.0)
            except threading.BrokenBarrierError:
                pass
        t = time.perf_counter()
        _STATE["run"]()
        out.append(time.perf_counter() - t)
    return out


def in_processes(kind: str, copies: int, rounds: int) -> float:
    """The slowest copy's least round of ``copies`` spawned workers running ``kind``, every
    round started together (module docstring)."""
    got: list = []
    run_jobs(_rounds, [(rounds,)] * copies, workers=copies, init=_setup,
             init_args=(kind, mp.get_context("spawn").Barrier(copies)), on_result=lambda i, r: got.append(r))
    return max(min(r) for r in got)


def here(kind: str, rounds: int) -> tuple[float, object]:
    """The least round of ``kind`` in this process (default threads), after an untimed one,
    and the iterations its run reported."""
    _setup(kind)
    return min(_rounds(rounds)), _STATE["run"]()


def build_seconds(subjects=(0, 1)) -> float:
    """Wall seconds of ``python -m defaust`` building ``subjects`` into a temporary folder
    (removed after), every core; exits with the builder's last line when it fails."""
    import sys
    import tempfile
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "defaust", f"out={d}/defaust",
                            f"subjects=[{','.join(map(str, subjects))}]", "progress=false"],
                           capture_output=True, text=True)
        took = time.perf_counter() - t
    if r.returncode:
        last = (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
        raise SystemExit(f"error: python -m defaust failed: {last.removeprefix('error: ')}")
    return took


def _cpu() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, timeout=10).stdout
        return next(ln.split(":", 1)[1].strip() for ln in out.splitlines() if ln.startswith("Model name"))
    except (OSError, StopIteration, subprocess.SubprocessError):
        return platform.processor() or "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--copies", type=int, default=2)
    ap.add_argument("--build", action="store_true", help="also time a 2-subject DeFAUST build (about 100 s)")
    a = ap.parse_args()
    from eval.run import machine_speed as ms
    commit = subprocess.run(["git", "rev-parse", "--short=8", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"machine: {_cpu()}; commit {commit}; PROBE_REFERENCE_S {ms.PROBE_REFERENCE_S}")
    rows, probe = [], {}  # probe: copies -> kind -> the least reading
    for copies in (a.copies, 1):
        got = [ms.probe_seconds(copies=copies) for _ in range(a.rounds)]
        probe[copies] = {k: min(g[k] for g in got) for k in ms.PROBE_KINDS}
        rows += [(f"probe, {k}, {copies} cop{'ies' if copies > 1 else 'y'}", v) for k, v in probe[copies].items()]
    for kind, label in (("srpaper", "ARAP-SR paper, twisted bar"), ("elastic", "Elastic, twisted bar")):
        seconds, iterations = here(kind, a.rounds)
        rows.append((f"{label}, this process ({iterations} iterations)", seconds))
        rows.append((f"{label}, processes", in_processes(kind, a.copies, a.rounds)))
    if a.build:
        from eval.run.plan import BUILD_START_S, build_stage
        from sshade.cores import available_cores
        prior = build_stage(2, workers=available_cores(), start_s=BUILD_START_S)["seconds"]  # as the builder runs
        took = build_seconds()
        rows.append(("DeFAUST build, subjects 0 and 1 (python -m defaust)", took))
        rows.append(("the plan's prior for it at factor 1", prior))
        rows.append(("the build probe over the build's speed (PROBE_REFERENCE_S on this machine)",
                     probe[a.copies]["build"] / (took / prior)))
    print("| work | seconds |\n|---|---:|")
    for label, s in rows:
        print(f"| {label} | {s:.4f} |")


if __name__ == "__main__":
    main()

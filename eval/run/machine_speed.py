"""How fast this machine runs the evaluator's work against the machine its priors were
measured on: a short probe, once per process, that calibrates the plan.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

:func:`probe_seconds` times two kinds of work, each as the evaluator runs it (one spawned
process per core, all at once, :func:`harness.jobs.run_jobs`): ``runs``, the solver of the
full-resolution baselines and references (:class:`sshade.arap.ArapSolver`, prepared once)
for a fixed number of iterations on a synthetic bar past the caches' size, and ``build``, the
DeFAUST builder's own kernels (pymeshlab's isotropic remesh, the fixed-order skinning blend).
:func:`machine_speed` divides each by :data:`PROBE_REFERENCE_S`, what it took where the priors
of conf/method/*.yaml and :mod:`eval.run.plan` were measured: the runs' priors and references
are multiplied by the ``runs`` factor, the build's by the ``build`` one; :data:`SPEED_ENV` fixes both.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import threading
import time

import numpy as np

from defaust.fixed_order import blend
from defaust.highres import isotropic_remesh, meshset
from harness.checks import env_positive
from harness.jobs import JobOptions, run_jobs
from sshade.arap import ArapOptions, ArapSolver
from sshade.arap.problems import box_surface, twisted_bar
from sshade.cores import available_cores
from sshade.errors import SShaDeError

__all__ = ["PROBE_KINDS", "PROBE_REFERENCE_S", "MAX_PROBE_COPIES", "PROBE_COPY_BYTES", "SPEED_ENV", "SPEED_RANGE",
           "PROBE_MIN_PLAN_S",
           "probe_copies", "probe_seconds", "machine_speed", "speed_words"]

#: The kinds of work the probe times: the solvers' (the runs and references) and the builder's.
PROBE_KINDS = ("runs", "build")
#: Seconds :func:`probe_seconds` takes for each kind (the slowest copy's least round, 2
#: copies) on the 2-core machine the priors were measured on (an Intel Xeon VM) at the priors'
#: speed: the mean of its readings over that speed in five runs' plans (four for the build;
#: benchmarks/records/machine_speed.md, "The solvers' probe").
PROBE_REFERENCE_S = {"runs": 0.40, "build": 0.71}
#: The most copies of the probe's work run at once (:func:`probe_copies`).
MAX_PROBE_COPIES = 8
#: Memory set aside for each copy (its process peaks at about 0.65 GB: the 91k-vertex solver's
#: factor, pymeshlab): no more copies run than the free memory holds.
PROBE_COPY_BYTES = 1 << 30
#: Environment variable that fixes both factors (a positive number; 1: the priors as they
#: are) instead of running the probe.
SPEED_ENV = "SSHADE_PLAN_SPEED"
#: A plan with no build whose runs take less than this at the priors (seconds) runs no probe
#: (``eval.experiments.cases.case_plan.plan_speed``): it costs 6-8 s per process, and a 30 %
#: error on such a plan is under 20 s.
PROBE_MIN_PLAN_S = 60.0
#: The factors the plan takes: a probe outside them is clipped (and says so).
SPEED_RANGE = (0.125, 8.0)

_BAR_H = 0.014      # the runs' bar: 91,308 vertices (a factor of about 100 MB, as at 169k: past the caches)
_ITERATIONS = 8     # fixed iterations of the solve (it does not converge in them)
_BOX_H = 0.03       # the build's mesh: a 19,736-vertex box, remeshed at about the same size
_REMESH = (0.025, 1)  # target edge, iterations
_BLEND = (170_000, 24, 0.3)  # vertices, bones, fraction of non-zero weights (a DeFAUST body's size)
_WAIT_S = 120.0     # the longest a copy waits for the others at a round's start
_STATE: dict = {}


def _runs_work():
    V, F, handles, targets = twisted_bar(h=_BAR_H)
    solver = ArapSolver(V, F, handles, ArapOptions(energy="spokes_and_rims", max_iter=_ITERATIONS))

    def work():
        return float(solver.solve(targets).V[0, 0])
    return work


def _build_work():
    V, F = box_surface((4.0, 1.0, 1.0), _BOX_H)
    n, k, p = _BLEND
    rng = np.random.default_rng(0)
    W = rng.random((n, k))
    W[W > p] = 0.0
    T = rng.standard_normal((k, 3, 4))

    def work():
        ms = meshset(V, F)
        isotropic_remesh(ms, _REMESH[0], _REMESH[1], check_distance=False)
        return ms.current_mesh().vertex_number() + float(blend(W, T)[0, 0, 0])
    return work


_WORK = {"runs": _runs_work, "build": _build_work}


def _setup(kinds: tuple, barrier) -> None:
    """A worker's ``init``: each kind's work made ready and run once, untimed (numba's
    cache loaded, pymeshlab's plugins)."""
    _STATE["barrier"] = barrier
    _STATE["work"] = {k: _WORK[k]() for k in kinds}
    for w in _STATE["work"].values():
        w()


def _rounds(repeats: int) -> dict:
    """A worker's job: ``repeats`` rounds of each kind, every one started with the other
    copies (a broken barrier: alone); kind -> list of seconds."""
    out: dict = {}
    for _ in range(repeats):
        for kind, work in _STATE["work"].items():
            try:
                _STATE["barrier"].wait(_WAIT_S)
            except threading.BrokenBarrierError:
                pass
            t = time.perf_counter()
            work()
            out.setdefault(kind, []).append(time.perf_counter() - t)
    return out


def _free_bytes() -> int | None:
    """The machine's free physical memory in bytes, None where the OS does not say."""
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def probe_copies() -> int:
    """How many copies of the probe's work run at once: every core this process may use
    (as many as the evaluator's ``jobs=auto`` runs side by side), at most
    :data:`MAX_PROBE_COPIES` and no more than the free memory holds at
    :data:`PROBE_COPY_BYTES` each (at least 1)."""
    free = _free_bytes()
    by_memory = MAX_PROBE_COPIES if free is None else free // PROBE_COPY_BYTES
    return max(1, min(available_cores(), MAX_PROBE_COPIES, by_memory))


def probe_seconds(kinds=PROBE_KINDS, repeats: int = 2, copies: int | None = None) -> dict:
    """Each kind's seconds: the slowest copy's least of ``repeats`` rounds, after one
    untimed round, with ``copies`` spawned processes running the same work at once (module
    docstring). About 6-8 s for both kinds on the priors' machine, the processes' start-up
    and the solver's set-up included (docs/implementation.md).

    Parameters
    ----------
    kinds : sequence of :data:`PROBE_KINDS` names, at least one.
    repeats : int >= 1.
    copies : int >= 1 or None (:func:`probe_copies`).

    Returns
    -------
    dict kind -> float, seconds (> 0).

    Raises
    ------
    SShaDeError when ``repeats`` or ``copies`` is not an int >= 1, a kind is unknown, or a
    worker could not start or died.
    """
    copies = probe_copies() if copies is None else copies
    for name, v in (("repeats", repeats), ("copies", copies)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise SShaDeError(f"probe {name} must be an int >= 1, got {v!r}")
    kinds = tuple(dict.fromkeys(kinds))
    if not kinds or any(k not in PROBE_KINDS for k in kinds):
        raise SShaDeError(f"probe kinds must be some of {PROBE_KINDS}, got {kinds!r}")
    got: list = []
    run_jobs(_rounds, [(repeats,)] * copies, workers=copies, init=_setup,
             init_args=(kinds, mp.get_context("spawn").Barrier(copies)), on_result=lambda i, r: got.append(r),
             options=JobOptions(what="plan probe", advice=f"set {SPEED_ENV}=1 to plan without the probe"))
    return {k: max(max(min(r[k]) for r in got), 1e-9) for k in kinds}


_PROBE_LOCK = threading.Lock()
_READINGS: dict = {}  # kind -> every reading in this process (empty: its probe failed)
_ERRORS: list = []    # what each failed probe said


def _probed(kinds: tuple, again: tuple = ()) -> tuple[dict, dict]:
    """``(seconds, readings)`` of each kind: the mean of its readings in this process
    (None when it has none: its probe failed) and how many; a kind is probed when it was
    not yet, or is in ``again``. Two threads asking at once get the same ones (the second
    waits for the first's)."""
    with _PROBE_LOCK:
        todo = tuple(k for k in kinds if k in again or k not in _READINGS)
        if todo:
            try:
                for k, v in probe_seconds(todo).items():
                    _READINGS.setdefault(k, []).append(v)
            except Exception as e:  # noqa: BLE001 - a failed probe leaves the priors as they are, said in the plan
                for k in todo:
                    _READINGS.setdefault(k, [])
                _ERRORS.append(str(e).splitlines()[0] if str(e) else type(e).__name__)
        got = {k: _READINGS[k] for k in kinds}
        return {k: sum(r) / len(r) if r else None for k, r in got.items()}, {k: len(r) for k, r in got.items()}


def machine_speed(build: bool = False, again: bool = False, probe: bool = True) -> dict:
    """This machine's time factors against the priors' machine, once per process.

    Parameters
    ----------
    build : bool, probe the builder's work too (a build is ahead); else ``build_factor``
        is the ``runs`` one unless it was probed before in this process.
    again : bool, probe the runs' work again (e.g. after minutes of a build: a VM's speed
        moves over tens of seconds) and take the mean of this process's readings.
    probe : bool, run the probe where this process has no reading yet; False (a plan
        under :data:`PROBE_MIN_PLAN_S` at the priors: the probe would cost more than the
        error it corrects) takes the readings there are, else the priors as they are
        (``source`` ``"short"``).

    Returns
    -------
    dict: ``factor`` (float, what the runs' and references' priors are multiplied by: > 1
    on a slower machine, within :data:`SPEED_RANGE`), ``build_factor`` (the same for the
    build), ``source`` (``"probe"``, ``"env"``, ``"short"``: not probed, or ``"none"``: the
    probe failed; the priors as they are for the last two), ``probe_s`` (kind -> the probe's seconds, the mean of its
    ``readings``, kind -> how many; None from the environment), ``reference_s``
    (:data:`PROBE_REFERENCE_S`), ``clipped`` (bool: a probe's factor was outside
    :data:`SPEED_RANGE`), and ``error`` when the probe failed.

    Raises
    ------
    SShaDeError when :data:`SPEED_ENV` is set to anything but a positive number.
    """
    env = env_positive(SPEED_ENV, "a number > 0 (1: the priors as measured)")
    out = {"source": "env", "probe_s": None, "reference_s": dict(PROBE_REFERENCE_S)}
    if env is not None:
        raw = {"runs": env, "build": env}
    else:
        with _PROBE_LOCK:
            had_build, had_runs = bool(_READINGS.get("build")), "runs" in _READINGS
        if not (probe or had_runs):
            return {"factor": 1.0, "build_factor": 1.0, **out, "source": "short", "clipped": False}
        seconds, readings = _probed(PROBE_KINDS if (build and probe) or had_build else ("runs",),
                                    ("runs",) if again and probe else ())
        if any(v is None for v in seconds.values()):
            out.update(source="none", error=_ERRORS[0] if _ERRORS else "")
            raw = {"runs": 1.0, "build": 1.0}
        else:
            out.update(source="probe", probe_s={k: round(v, 4) for k, v in seconds.items()}, readings=readings)
            raw = {k: v / PROBE_REFERENCE_S[k] for k, v in seconds.items()}
            raw.setdefault("build", raw["runs"])
    lo, hi = SPEED_RANGE
    f = {k: min(max(v, lo), hi) for k, v in raw.items()}
    return {"factor": round(f["runs"], 4), "build_factor": round(f["build"], 4), **out,
            "clipped": any(f[k] != raw[k] for k in f)}


def speed_words(speed: dict) -> str:
    """The factors in words for the plan line.

    >>> speed_words({"factor": 1.3, "build_factor": 1.6, "source": "probe", "probe_s": {"runs": 0.8, "build": 1.0},
    ...              "reference_s": {"runs": 0.62, "build": 0.62}, "clipped": False})
    'times for this machine: the runs x1.3 the priors, the build x1.6 (probe 0.8 s and 1 s against 0.62 s and 0.62 s)'
    >>> speed_words({"factor": 2.0, "build_factor": 2.0, "source": "env", "probe_s": None, "reference_s": {},
    ...              "clipped": False})
    'times for this machine: x2 the priors (SSHADE_PLAN_SPEED)'
    """
    f, b = speed["factor"], speed.get("build_factor", speed["factor"])
    if speed["source"] == "env":
        return f"times for this machine: x{f:.2g} the priors ({SPEED_ENV})"
    if speed["source"] == "short":
        return (f"times for this machine: the priors as measured (not probed: the plan is under "
                f"{PROBE_MIN_PLAN_S:g} s at them)")
    if speed["source"] == "none":
        return f"times for this machine: the priors as measured (the probe failed: {speed.get('error', '')})"
    probe, ref = speed["probe_s"], speed["reference_s"]
    kinds = [k for k in PROBE_KINDS if k in probe]
    why = (f"probe {' and '.join(f'{probe[k]:.2g} s' for k in kinds)} against "
           f"{' and '.join(f'{ref[k]:.2g} s' for k in kinds)}")
    if speed.get("clipped"):
        why += f", clipped to {SPEED_RANGE[0]:g}-{SPEED_RANGE[1]:g}"
    words = f"the runs x{f:.2g} the priors" + (f", the build x{b:.2g}" if "build" in probe else "")
    return f"times for this machine: {words} ({why})"

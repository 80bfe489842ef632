"""How fast this machine runs the evaluator's work against the machine its priors were
measured on: a short probe, once per process, that calibrates the plan.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

:func:`probe_seconds` times a fixed piece of the solvers' work (a sparse Cholesky
factorisation and its 3-column solves, sparse products, batched 3x3 SVDs, streaming
vector updates), one copy per core at once; :func:`machine_speed` divides it by
:data:`PROBE_REFERENCE_S`, what it took where the priors of conf/method/*.yaml and
:mod:`eval.run.plan` were measured. The plan's priors are multiplied by that factor;
:data:`SPEED_ENV` fixes it instead (a cluster whose nodes differ from the submitting one).
"""
from __future__ import annotations

import functools
import math
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp

from harness.checks import env_positive
from sshade.arap.linear import LaplacianSolver
from sshade.cores import available_cores
from sshade.errors import SShaDeError

__all__ = ["PROBE_REFERENCE_S", "MAX_PROBE_THREADS", "SPEED_ENV", "SPEED_RANGE", "probe_threads", "probe_seconds",
           "machine_speed", "speed_words"]

#: Seconds :func:`probe_seconds` took (the least of its rounds, 2 threads) on the 2-core
#: machine the priors were measured on, quiet (benchmarks/records/machine_speed.md).
PROBE_REFERENCE_S = 0.37
#: The most copies of the probe's work run at once (:func:`probe_threads`).
MAX_PROBE_THREADS = 8
#: Environment variable that fixes the factor (a positive number; 1: the priors as they are)
#: instead of running the probe.
SPEED_ENV = "SSHADE_PLAN_SPEED"
#: The factors the plan takes: a probe outside them is clipped (and says so).
SPEED_RANGE = (0.125, 8.0)

_GRID = 150  # the probe's grid: 150 x 150 vertices (22,500 unknowns)
_SOLVES = 20
_SVDS = 30_000
_STREAM = 1_000_000  # 8 MB per vector: past the caches, 16 MB of inputs per copy


def _grid_laplacian(k: int) -> sp.csc_matrix:
    """The ``k*k`` grid's 5-point Laplacian plus a small shift: symmetric positive definite."""
    d = sp.diags([-np.ones(k - 1), 2.0 * np.ones(k), -np.ones(k - 1)], [-1, 0, 1])
    eye = sp.identity(k)
    return (sp.kron(d, eye) + sp.kron(eye, d) + 1e-3 * sp.identity(k * k)).tocsc()


def _inputs() -> tuple:
    """The probe's fixed inputs (seeded): the matrix, right-hand sides, 3x3 matrices, vectors."""
    rng = np.random.default_rng(0)
    A = _grid_laplacian(_GRID)
    return (A, rng.standard_normal((A.shape[0], 3)), rng.standard_normal((_SVDS, 3, 3)),
            rng.standard_normal(_STREAM), rng.standard_normal(_STREAM))


def _work(inputs: tuple) -> float:
    """One pass of the probe's work on :func:`_inputs`; returns a number that depends on
    all of it (so none of it can be skipped). No BLAS call: its threads would make the
    probe depend on the machine's load in another way than the solvers' kernels do."""
    A, B, M, x, y = inputs
    lin = LaplacianSolver(A)
    Ac = A.tocsr()
    acc = 0.0
    for _ in range(_SOLVES):
        X = lin.solve(B)
        B = Ac @ X + 0.5 * B
        acc += float(X[0, 0])
    u, s, vt = np.linalg.svd(M)
    acc += float(s[:, 0].sum()) + float(np.einsum("nij,njk->nik", u, vt)[:, 0, 0].sum())
    y = y.copy()
    for _ in range(16):
        y += 0.25 * x
        acc += float(np.einsum("i,i->", x, y)) * 1e-9
    return acc


def probe_threads() -> int:
    """How many copies of the probe's work run at once: every core this process may use,
    at least 2 (the priors' machine's count) and at most :data:`MAX_PROBE_THREADS`."""
    return max(2, min(available_cores(), MAX_PROBE_THREADS))


def probe_seconds(repeats: int = 2, threads: int | None = None) -> float:
    """The least wall seconds of ``repeats`` rounds of the probe, after one untimed round;
    a round runs ``threads`` copies of its work at once, one per thread (the evaluator's
    runs share the machine the same way, so its load counts too). About ``0.37 *
    (repeats + 1)`` s on the priors' machine at 2 threads.

    Parameters
    ----------
    repeats : int >= 1.
    threads : int >= 1 or None (:func:`probe_threads`).

    Returns
    -------
    float, seconds (> 0).

    Raises
    ------
    SShaDeError when ``repeats`` or ``threads`` is not an int >= 1.
    """
    threads = probe_threads() if threads is None else threads
    for name, v in (("repeats", repeats), ("threads", threads)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise SShaDeError(f"probe {name} must be an int >= 1, got {v!r}")
    inputs = [_inputs() for _ in range(threads)]
    best = math.inf
    with ThreadPoolExecutor(threads, thread_name_prefix="sshade-probe") as pool:
        list(pool.map(_work, inputs))
        for _ in range(repeats):
            t = time.perf_counter()
            list(pool.map(_work, inputs))
            best = min(best, time.perf_counter() - t)
    return max(best, 1e-9)


_PROBE_LOCK = threading.Lock()


@functools.lru_cache(maxsize=1)
def _probe_once() -> tuple[float, float]:
    s = probe_seconds()
    return s, s / PROBE_REFERENCE_S


def _probed() -> tuple[float, float]:
    """The probe's seconds and factor, measured once per process (two threads asking at
    once get the same one: the second waits for the first's)."""
    with _PROBE_LOCK:
        return _probe_once()


def machine_speed() -> dict:
    """This machine's time factor against the priors' machine, once per process.

    Returns
    -------
    dict: ``factor`` (float, what the priors' seconds are multiplied by: > 1 on a slower
    machine, within :data:`SPEED_RANGE`), ``source`` (``"probe"`` or ``"env"``),
    ``probe_s`` (the probe's seconds, None from the environment), ``reference_s``
    (:data:`PROBE_REFERENCE_S`), ``clipped`` (bool: the probe's factor was outside
    :data:`SPEED_RANGE`).

    Raises
    ------
    SShaDeError when :data:`SPEED_ENV` is set to anything but a positive number.
    """
    env = env_positive(SPEED_ENV, "a number > 0 (1: the priors as measured)")
    if env is not None:
        raw, probe_s, source = env, None, "env"
    else:
        probe_s, raw = _probed()
        source = "probe"
    lo, hi = SPEED_RANGE
    factor = min(max(raw, lo), hi)
    return {"factor": round(factor, 4), "source": source,
            "probe_s": None if probe_s is None else round(probe_s, 4),
            "reference_s": PROBE_REFERENCE_S, "clipped": factor != raw}


def speed_words(speed: dict) -> str:
    """The factor in words for the plan line.

    >>> speed_words({"factor": 1.3, "source": "probe", "probe_s": 0.325, "reference_s": 0.25, "clipped": False})
    'times for this machine: x1.3 the priors (probe 0.33 s against 0.25 s)'
    >>> speed_words({"factor": 2.0, "source": "env", "probe_s": None, "reference_s": 0.25, "clipped": False})
    'times for this machine: x2 the priors (SSHADE_PLAN_SPEED)'
    """
    f = f"x{speed['factor']:.2g}"
    if speed["source"] == "env":
        why = SPEED_ENV
    else:
        why = f"probe {speed['probe_s']:.2g} s against {speed['reference_s']:.2g} s"
        if speed.get("clipped"):
            why += f", clipped to {SPEED_RANGE[0]:g}-{SPEED_RANGE[1]:g}"
    return f"times for this machine: {f} the priors ({why})"

"""One guarded way to run any deformation method on one input (:func:`run_method`), used
by the evaluator and ``python -m sshade deform``.

The method gets read-only copies of its inputs, each connected component apart
(:func:`sshade.components.deform_components`); what it raises or does (an exception,
``sys.exit``, ``os._exit`` from its thread, a time-out) becomes a :class:`MethodFailure`
(``KeyboardInterrupt`` stops the run), and its result is checked
(:func:`sshade.mesh.validate.validate_deformed`). What cannot be caught (crashes,
time-outs off the main thread): docs/implementation.md ("Implementation notes: sshade/guard.py").
"""
from __future__ import annotations

import contextlib
import math
import os
import signal
import threading
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .components import deform_components, n_components
from .errors import SShaDeError
from .mesh.checked import checked_mesh
from .mesh.halfedge import large_mesh
from .mesh.halfedge import warm_kernels as warm_mesh_kernels
from .mesh.validate import check_points, validate_deformed, validate_handles, validate_mesh
from .method_interface import is_plugin
from .warmup_base import WARMED, warm_once

__all__ = ["MethodFailure", "MethodRun", "run_method", "check_timeout", "check_positive", "handle_error",
           "handles_not_reached", "HANDLE_ERROR_MAX_PCT", "MAX_TIMEOUT_S"]

#: Default largest handle error (% of the rest bounding-box diagonal, the
#: ``handle_err_pct`` of :func:`eval.metrics.measures.deformation_metrics`) of a successful run.
HANDLE_ERROR_MAX_PCT = 1.0
#: The longest time-out accepted (s, about 116 days): ``setitimer`` refuses 1e10 s with an
#: OverflowError on a 64-bit Linux.
MAX_TIMEOUT_S = 1e7


class MethodFailure(SShaDeError):
    """A method failed on one input: it raised, exited, timed out or returned an
    unusable result. The message (one line) is what the evaluator's ``error`` column
    and the command line's ``error:`` line say."""


class _Timeout(BaseException):
    """Raised in the method by the alarm; a BaseException so that a method's
    ``except Exception`` does not swallow it."""


class _ProcessExit(BaseException):
    """Raised in place of ``os._exit(code)`` called by a plug-in (:func:`_no_process_exit`)."""

    def __init__(self, code):
        super().__init__(code)
        self.code = code


_EXIT_GUARD = {"lock": threading.Lock(), "active": set(), "real": None}
_REAL_EXIT = os._exit


def _guarded_exit(code):
    """``os._exit`` while :func:`_no_process_exit` is active somewhere in this process:
    raises :class:`_ProcessExit` in a thread that runs a plug-in, else exits."""
    if (os.getpid(), threading.get_ident()) in _EXIT_GUARD["active"]:
        raise _ProcessExit(code)
    (_EXIT_GUARD["real"] or _REAL_EXIT)(code)


@contextlib.contextmanager
def _no_process_exit(active: bool):
    """While the block runs (``active``: a plug-in's code), ``os._exit`` called from this
    thread of this process raises :class:`_ProcessExit`; other threads, and a child the
    plug-in forks (same thread id, another pid), exit as usual. ``os._exit`` is restored
    once no such block is left."""
    if not active:
        yield
        return
    g, me = _EXIT_GUARD, (os.getpid(), threading.get_ident())
    with g["lock"]:
        if not g["active"]:
            g["real"], os._exit = os._exit, _guarded_exit
        nested = me in g["active"]
        g["active"].add(me)
    try:
        yield
    finally:
        with g["lock"]:
            if not nested:
                g["active"].discard(me)
            if not g["active"] and g["real"] is not None:
                os._exit, g["real"] = g["real"], None


@dataclass(frozen=True)
class MethodRun:
    """What :func:`run_method` returns; unpacks as ``U, seconds = run_method(...)``.

    Attributes
    ----------
    U : (n, 3) float64, the checked deformed positions (a new array).
    seconds : float, wall seconds of the ``deform`` call minus the compilation it
        reported in ``info['compile_s']`` (the evaluator's ``time_s``).
    compile_s : float, seconds of the method's ``warmup()`` plus that reported
        compilation (the evaluator's ``compile_s``; never part of ``seconds``).
    info : dict, the method's ``info`` after the call (components merged,
        :func:`sshade.components.deform_components`); ``{}`` when it is not a mapping.
    warnings : list of str, the distinct warning messages the call issued.
    """
    U: np.ndarray
    seconds: float
    compile_s: float = 0.0
    info: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)

    def __iter__(self):
        return iter((self.U, self.seconds))


def check_positive(value, where: str, most: float = math.inf) -> float:
    """``value`` as a positive finite float of at most ``most``.

    Raises SShaDeError naming ``where``: a bool, a non-number, zero, negative, NaN, inf,
    more than ``most``.
    """
    try:
        if isinstance(value, bool):
            raise TypeError
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (math.isfinite(v) and 0 < v <= most):
        bound = f", at most {most:g}" if math.isfinite(most) else ""
        raise SShaDeError(f"{where} must be a positive number{bound}, got {value!r}")
    return v


def check_timeout(value, where: str = "timeout_s"):
    """``value`` as a positive finite float of at most :data:`MAX_TIMEOUT_S`, or None for
    None (no limit).

    Raises SShaDeError naming ``where``: a bool, a non-number, zero, negative, NaN, inf,
    more than :data:`MAX_TIMEOUT_S` (the system's interval timer takes no more).
    """
    if value is None:
        return None
    try:
        return check_positive(value, where, MAX_TIMEOUT_S)
    except SShaDeError:
        raise SShaDeError(f"{where} must be a positive number of seconds, at most {MAX_TIMEOUT_S:g} (or null for no "
                          f"limit), got {value!r}") from None


def handle_error(Vd, handles, targets, diag: float) -> float:
    """Largest handle-to-target distance, in % of a bounding-box diagonal.

    ``100 max_i ||Vd[handles[i]] - targets[i]|| / diag``. Not a paper equation: it
    checks that the handle constraints of §4.1 are met (:func:`handles_not_reached`;
    the evaluator's ``handle_err_pct``, :func:`eval.metrics.measures.deformation_metrics`).

    Parameters
    ----------
    Vd : (n, 3) float, deformed vertices.
    handles : (h,) int, unique vertex indices in ``[0, n)``.
    targets : (h, 3) float, target positions, same unit as ``Vd``.
    diag : float > 0, reference length (usually the rest bounding-box diagonal).

    Returns
    -------
    float, percent of ``diag``.

    Raises
    ------
    SShaDeError on bad handles (see :func:`sshade.mesh.validate.validate_handles`), NaN
    coordinates, or a non-positive / non-finite ``diag``.

    Examples
    --------
    >>> Vd = np.zeros((3, 3))
    >>> handle_error(Vd, [1], [[0., 0.5, 0]], 10.0)
    5.0
    """
    Vd = check_points(Vd, "Vd (deformed)")
    h, T = validate_handles(Vd, handles, targets)
    try:
        diag = float(diag)
    except (TypeError, ValueError):
        raise SShaDeError(f"diag must be a number, got {diag!r}") from None
    if not np.isfinite(diag) or diag <= 0:
        raise SShaDeError(f"diag must be a positive finite length, got {diag}")
    return float(100.0 * np.linalg.norm(Vd[h] - T, axis=1).max() / diag)


def handles_not_reached(handle_err_pct, max_pct=HANDLE_ERROR_MAX_PCT) -> str | None:
    """The failure message of a result whose handle error (``handle_err_pct``: largest
    handle-to-target distance in % of the rest bounding-box diagonal,
    :func:`handle_error`) exceeds ``max_pct`` (None: no limit), else None."""
    if max_pct is None or handle_err_pct is None:
        return None
    e = float(handle_err_pct)
    if not (e > float(max_pct)) and not math.isnan(e):
        return None
    return f"handles not reached: handle error {e:.3g}% of the diagonal > {float(max_pct):g}%"


def run_method(method, V, F, handles, targets, *, timeout_s=None) -> MethodRun:
    """Run ``method`` (a :class:`sshade.method_interface.Deformer`) on one input, guarded.

    Parameters
    ----------
    method : object with ``name``, ``deform(V, F, handles, targets)``, optional
        ``warmup(n_vertices)`` and ``info``.
    V : (n, 3) float rest positions (any unit); F : (m, 3) int triangles (several
        connected components allowed: each is deformed apart); handles : (h,) int
        vertex indices; targets : (h, 3) float positions. Never modified.
    timeout_s : positive float or None, the wall-clock limit of each of the
        ``warmup`` and ``deform`` calls (main thread only: docs/implementation.md,
        "Implementation notes: sshade/guard.py").

    Returns
    -------
    :class:`MethodRun` (``U, seconds = run_method(...)`` also works).

    Raises
    ------
    SShaDeError (not a MethodFailure) on an invalid mesh or handles, before the method
    runs (:func:`sshade.mesh.validate.validate_mesh`, ``validate_handles``). The mesh is
    checked there once: the method's own ``validate_mesh`` of the read-only arrays it is
    handed returns at once (:func:`sshade.mesh.checked.checked_mesh`; a mesh of several
    components is deformed per component, each checked by the method).
    MethodFailure on anything the method raises or does: our methods' SShaDeError
    (its message), a plug-in's exception (``Type: message``), SystemExit and other
    BaseException (``SystemExit: 0 (...)``), a plug-in's ``os._exit`` (``os._exit(0)
    called (...)``; not a crash), ``timed out after N s``, or
    an output :func:`sshade.mesh.validate.validate_deformed` refuses.
    KeyboardInterrupt, unchanged; any other exception of one of our own methods (a bug,
    :func:`sshade.method_interface.is_plugin`), unchanged.
    """
    name = str(getattr(method, "name", type(method).__name__))
    timeout_s = check_timeout(timeout_s)
    V, F, he = validate_mesh(V, F, allow_components=True, return_halfedges=True)
    handles, targets = validate_handles(V, handles, targets)
    n = len(V)
    Vr, Fr, hr, tr = (_read_only(a) for a in (V, F, handles, targets))
    plugin = is_plugin(method)
    split = n_components(F, n) > 1
    compile_s = _guarded(lambda: _warm(method, n, large_mesh(F)), timeout_s, plugin)
    checked = _Checked(method, name)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        if split:
            raw, info = _guarded(lambda: deform_components(checked, Vr, Fr, hr, tr, return_info=True),
                                 timeout_s, plugin)
        else:
            with checked_mesh(Vr, Fr, he, single_component=True):  # checked above: not again inside
                raw = _guarded(lambda: method.deform(Vr, Fr, hr, tr), timeout_s, plugin)
            info = getattr(method, "info", None)
        elapsed = time.perf_counter() - t0
    info = dict(info) if isinstance(info, Mapping) else {}
    late = min(_info_compile_s(info), elapsed)  # compiled inside deform after all (a new code path)
    try:
        U = validate_deformed(raw, n, V=V, name=name)
    except SShaDeError as e:
        raise MethodFailure(str(e)) from None
    return MethodRun(U=U, seconds=elapsed - late, compile_s=compile_s + late, info=info,
                     warnings=list(dict.fromkeys(str(w.message) for w in caught)))


class _Checked:
    """``method`` whose every ``deform`` output is checked (one component's, when
    :func:`sshade.components.deform_components` splits the mesh)."""

    def __init__(self, method, name: str):
        self.method, self.name = method, name

    @property
    def info(self):
        info = getattr(self.method, "info", None)
        return info if isinstance(info, Mapping) else {}

    def deform(self, V, F, handles, targets):
        U = self.method.deform(_read_only(V), _read_only(F), _read_only(handles), _read_only(targets))
        return validate_deformed(U, len(V), V=V, name=self.name)


def _read_only(a) -> np.ndarray:
    """A read-only C-contiguous copy of ``a`` (no copy when ``a`` already is one)."""
    a = np.asarray(a)
    if a.flags.writeable or not a.flags.c_contiguous:
        a = np.array(a, order="C", copy=True)
        a.flags.writeable = False
    return a


def _describe(e: BaseException) -> str:
    """``Type: message`` on one line; never raises (a broken ``__str__`` included)."""
    try:
        msg = str(e)
    except Exception:  # noqa: BLE001 -- a plug-in's exception may fail to print
        msg = "(message unavailable)"
    return " ".join(f"{type(e).__name__}: {msg}".split()).rstrip(": ")


def _guarded(fn, timeout_s, plugin: bool):
    """``fn()``, with every way out but a return or KeyboardInterrupt turned into a
    :class:`MethodFailure` (see :func:`run_method`)."""
    limit = f"timed out after {timeout_s:g} s" if timeout_s is not None else ""
    try:
        with _alarm(timeout_s) as fired:
            try:
                with _no_process_exit(plugin):
                    out = fn()
            except (KeyboardInterrupt, _Timeout):
                raise
            except MethodFailure:
                raise
            except _ProcessExit as e:
                raise MethodFailure(f"os._exit({e.code!r}) called (a method must return, not end the "
                                    "program)") from None
            except SShaDeError as e:
                raise MethodFailure(" ".join(str(e).split()) or type(e).__name__) from None
            except Exception as e:
                if not plugin:
                    raise
                raise MethodFailure(_describe(e)) from None
            except BaseException as e:  # SystemExit, GeneratorExit, ...: the run goes on
                raise MethodFailure(f"{_describe(e)} (a method must return, not end the program)") from None
    except _Timeout:
        raise MethodFailure(limit) from None
    if fired[0]:  # the method swallowed the alarm and returned
        raise MethodFailure(limit)
    return out


@contextlib.contextmanager
def _alarm(timeout_s):
    """Raise :class:`_Timeout` in this thread after ``timeout_s`` seconds (then again
    every 0.5 s, in case the method swallows it); yields a one-item list, True once it
    fired. No-op for None; a RuntimeWarning where SIGALRM cannot be used."""
    fired = [False]
    usable = hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
    if timeout_s is None or not usable:
        if timeout_s is not None:
            warnings.warn(f"timeout of {timeout_s:g} s not enforced: time-outs need SIGALRM in the main thread",
                          RuntimeWarning, stacklevel=4)
        yield fired
        return

    def handler(signum, frame):
        fired[0] = True
        raise _Timeout()

    old = signal.signal(signal.SIGALRM, handler)
    t0, old_delay = time.monotonic(), 0.0
    try:  # armed inside: an alarm that fires at once is cleaned up too
        old_delay = signal.setitimer(signal.ITIMER_REAL, timeout_s, 0.5)[0]
        yield fired
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        if old_delay > 0:  # someone else's alarm: re-armed with what is left of it
            signal.setitimer(signal.ITIMER_REAL, max(old_delay - (time.monotonic() - t0), 1e-3))


def _warm(method, n_vertices: int, large: bool = False) -> float:
    """Seconds of ``method.warmup(n_vertices)`` (the optional first-call compilation of a
    method, :class:`sshade.method_interface.Deformer`; 0.0 when it has none or is already warm,
    or reports something that is not a finite number >= 0), after, on a ``large`` mesh
    (:func:`sshade.mesh.halfedge.large_mesh`), the mesh kernels a method may call on it
    (normals, fans: while they are deferred, a warm-up on a tiny mesh takes their NumPy paths)."""
    s = warm_once(WARMED, ("mesh", "large"), lambda *_: warm_mesh_kernels()) if large else 0.0
    warm = getattr(method, "warmup", None)
    if not callable(warm):
        return s
    return s + _seconds(warm(n_vertices))


def _info_compile_s(info) -> float:
    """``compile_s`` a method reported in its ``info`` for its last call (e.g.
    :func:`sshade.deform`'s kernel loads), 0.0 when none or not a finite number >= 0."""
    return _seconds(info.get("compile_s", 0.0))


def _seconds(v) -> float:
    try:
        v = float(v or 0.0)
    except (TypeError, ValueError, OverflowError):
        return 0.0
    return v if math.isfinite(v) and v > 0 else 0.0

"""One (case, method) run of the ``cases`` experiment (:func:`run_pair`): the method
through :func:`sshade.guard.run_method`, its metrics, its reference columns and its info
as table cells; and the guard options of the config (:func:`guard_options`)."""
from __future__ import annotations

import json
import logging
import math
import time

import numpy as np

from eval.datasets.deformation_case import case_label
from eval.metrics.measures import deformation_metrics, ground_truth_metrics
from eval.metrics.meshes import CaseMeshes
from eval.run.jsonsafe import json_safe
from eval.run.result_store import cell_problem
from eval.run.spec import GuardOptions
from sshade.errors import SShaDeError
from sshade.guard import HANDLE_ERROR_MAX_PCT, check_positive, check_timeout, handles_not_reached, run_method

__all__ = ["run_pair", "run_and_store", "guard_options"]

log = logging.getLogger("eval")

_SKIP = object()

#: Info keys whose values feed the tables (eval.tables.stop_lines): kept under their
#: name only with a value of the expected type, else renamed ``info_<key>``.
_TYPED_INFO = {
    "iterations": lambda v: v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)),
    "converged": lambda v: v is None or isinstance(v, (bool, int, float)),
    "protocol": lambda v: v is None or isinstance(v, str),
    "status": lambda v: v is None or isinstance(v, str),
    "handles": lambda v: v is None or isinstance(v, str),
    "handle_pre_pct": lambda v: v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)),
}
#: Column names of the summary tables an info key must not take (eval.tables.summarize).
_RESERVED = ("n_cases", "n_failed", "warnings", "error", "method", "case")


def _scalar(v):
    """Method info value -> a CSV cell (no value may break cases.csv or a
    table): bools, ints (beyond int64: as float, or left empty when not finite), finite
    floats (NaN/inf: empty), strings on one line (at most 200 characters), flat
    lists/arrays of such scalars as JSON (NaN -> null; e.g. SShaDe's per-sampling
    seeds); nested structures (per-sampling dicts) and other objects are left out
    (their sums are separate info keys)."""
    if isinstance(v, np.generic):
        v = v.item()
    if v is None or isinstance(v, bool):
        return v
    if isinstance(v, int):
        if abs(v) < 2 ** 63:
            return v
        try:
            v = float(v)
        except OverflowError:
            return None
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, str):
        return " ".join(v.split())[:200]
    if isinstance(v, np.ndarray) and v.ndim == 1:
        v = v.tolist()
    if isinstance(v, (list, tuple)):
        items = [_scalar(x) if x is None or isinstance(x, (bool, int, float, str, np.generic)) else _SKIP for x in v]
        return _SKIP if any(x is _SKIP for x in items) else json.dumps(items)
    return _SKIP


def _info_columns(info, taken) -> dict:
    """The cells of a method's ``info`` for its row: keys made safe column names
    (letters, digits, ``_``; at most 64 characters; non-string keys by their text),
    values by :func:`_scalar`; a key clashing with ``taken`` (the row's columns), a
    summary column, a typed key with a value of another type (:data:`_TYPED_INFO`) or a
    value its name does not allow in a stored row (:func:`eval.run.result_store.cell_problem`, e.g. a
    text in ``*_pct``) becomes ``info_<key>``; ``compile_s`` (already in the row) is left out."""
    import re
    out: dict = {}
    for k, v in info.items():
        key = re.sub(r"[^A-Za-z0-9_]+", "_", k if isinstance(k, str) else str(k)).strip("_")[:64]
        v = _scalar(v)
        if not key or k == "compile_s" or v is _SKIP:
            continue
        if (key in taken or key in _RESERVED or not _TYPED_INFO.get(key, lambda _: True)(v)
                or cell_problem(key, v)):
            key = f"info_{key}"
        if key not in taken and key not in out:
            out[key] = v
    return out


def guard_options(timeout_s=None, handle_error_max_pct=HANDLE_ERROR_MAX_PCT) -> GuardOptions:
    """``timeout_s`` (positive seconds or null: the limit of each method call,
    :func:`sshade.guard.run_method`) and ``handle_error_max_pct`` (positive, % of the
    bounding-box diagonal, or null: the largest handle error of a successful run),
    checked; SShaDeError naming the key."""
    hmax = handle_error_max_pct
    if hmax is not None:
        try:
            hmax = check_positive(hmax, "handle_error_max_pct")
        except SShaDeError:
            raise SShaDeError(f"handle_error_max_pct must be a positive number (% of the bounding-box diagonal) "
                              f"or null for no limit, got {hmax!r}") from None
    return GuardOptions(timeout_s=check_timeout(timeout_s, "timeout_s"), handle_error_max_pct=hmax)


def run_pair(m, name: str, case, refs, guard: dict, meshes: CaseMeshes | None = None):
    """One (case, method) run: :func:`sshade.guard.run_method`, the metrics (what they need
    of the rest mesh and the ground truth kept in ``meshes`` for the next pairs on them,
    :mod:`eval.metrics.meshes`), the method's info; returns ``(row, U, info)`` (``U`` None
    and ``info`` empty when the method failed). A failure (the
    method's, or a handle error above ``guard['handle_error_max_pct']``: its metrics
    stay in the row) is the row's ``error``; the run goes on."""
    row = {"case": case.name, "subject": case.subject, "pose": case.pose, "method": name,
           "n_vertices": len(case.V), "n_faces": len(case.F), "n_handles": len(case.handles),
           "n_static": int(case.static.sum()), "n_dynamic": int((~case.static).sum()),
           "case_seed": getattr(case, "seed", None), "n_handles_dropped": getattr(case, "n_dropped", None), "error": ""}
    try:
        _tell_case(m, case)
        r = run_method(m, case.V, case.F, case.handles, case.targets, timeout_s=guard["timeout_s"])
        row["compile_s"], row["time_s"] = r.compile_s, r.seconds  # compilation: never inside time_s
        if "reported_time_s" in r.info:  # computed elsewhere: its own time, never the time to read it
            row["read_s"], row["time_s"], row["time_reported"] = r.seconds, _reported(r.info), True
        for w in r.warnings:  # e.g. sshade.pipeline.LowResSkippedWarning: logged and recorded
            log.warning("%s %s: %s", case.name, name, w)
        if r.warnings:
            row["warnings"] = " | ".join(" ".join(w.split()) for w in r.warnings)
        meshes = meshes or CaseMeshes()
        row.update(deformation_metrics(case.V, r.U, case.F, case.handles, case.targets,
                                       rest=meshes.rest(case.V, case.F)))
        row.update(refs.metrics(m, r.U))
        if getattr(case, "V_gt", None) is not None:
            row.update(ground_truth_metrics(r.U, case.F, case.V_gt, target=meshes.target(case.V_gt, case.F)))
    except SShaDeError as e:  # the method failed (sshade.guard.MethodFailure), or a metric refused its result
        row["error"] = " ".join(str(e).split()) or type(e).__name__
        log.warning("%s %s failed: %s", case.name, name, row["error"])
        return row, None, {}
    row.update(_info_columns(r.info, row))
    miss = handles_not_reached(row.get("handle_err_pct"), guard["handle_error_max_pct"]) or ""
    soft = r.info.get("handles") == "soft" and math.isfinite(float(row.get("handle_err_pct", math.nan)))
    if miss and soft:  # a penalty method's handle error is a measure of its result, not a failure
        row["handles_missed"] = True
        log.warning("%s %s: soft %s (kept: its Handle column says how far)", case.name, name, miss)
        miss = ""
    row["error"] = miss
    if row["error"]:
        log.warning("%s %s failed: %s", case.name, name, row["error"])
    return row, r.U, r.info


def _log_row(row: dict) -> None:
    """One log line of a stored row: its case, method, seconds and three measures."""
    log.info("%s %-8s %7.2fs  vol %.2f%%  EL %.2f%%  FA %.3f deg", row["case"], row["method"],
             math.nan if row.get("time_s") is None else row["time_s"],
             row.get("volume_err_pct", math.nan), row.get("edge_err_pct", math.nan),
             row.get("angle_err_deg", math.nan))


def _tell_case(m, case) -> None:
    """Set a case-aware method's ``case`` attribute (it has one) to what it may know of
    ``case`` (:func:`eval.datasets.deformation_case.case_label`: never the true shape)."""
    try:
        aware = "case" in vars(m) or hasattr(type(m), "case")
    except TypeError:  # an object without __dict__
        aware = hasattr(type(m), "case")
    if aware:
        try:
            m.case = case_label(case)
        except Exception as e:  # noqa: BLE001 -- a plug-in's setter: its failure is the case's
            raise SShaDeError(f"setting the method's case failed: {type(e).__name__}: {e}") from None


def _reported(info) -> float | None:
    """The seconds a method reported for itself (``info['reported_time_s']``), or None
    (empty Time cell) when it reported none or something other than seconds >= 0."""
    v = info.get("reported_time_s")
    try:
        t = float(v)
    except (TypeError, ValueError):
        return None
    return t if math.isfinite(t) and t >= 0 and not isinstance(v, bool) else None


def run_and_store(m, name: str, case, refs, guard: dict, meshes, store, key: str, fields: dict, *,
                  extra: dict | None = None):
    """:func:`run_pair`, timed, logged (one line: its seconds and three measures), then stored at
    once (:meth:`eval.run.result_store.ResultStore.save`; a store that cannot be written is logged
    and the run goes on). ``extra``: cells added to
    the row before it is stored (e.g. a worker's ``cores``).

    Returns
    -------
    ``(record, U, wall_s, cost_s)``: the record as the store holds it (its row, info,
    names and key), the deformed
    vertices (n, 3) or None, the pair's wall seconds, and those less the method's one-off
    compilation (``compile_s``: not a cost of the later runs; for the cost model).
    """
    t0 = time.perf_counter()
    row, U, info = run_pair(m, name, case, refs, guard, meshes)
    if U is not None:  # a failure has logged its warning
        _log_row(row)
    row.update(extra or {})
    wall = time.perf_counter() - t0
    c = row.get("compile_s")
    cost_s = wall - (c if isinstance(c, (int, float)) and c == c else 0.0)
    rec = {"row": json_safe(row), "info": json_safe(info), "case": case.name, "method": name, "key": key}
    try:
        store.save(case.name, name, key, fields, row, info, U)
    except (OSError, SShaDeError) as e:  # SShaDeError: a link placed in runs/ during the run
        log.warning("%s %s: result not stored (%s); a resume will run it again", case.name, name, e)
    return rec, U, wall, cost_s

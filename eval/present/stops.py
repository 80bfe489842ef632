"""How each method stopped, in words, from the per-case rows (:func:`stop_lines`): its
protocol, iteration range, how many runs met their criterion, how the others stopped,
its preset, what its handles and reference columns mean; the lines under every
``table.md`` and on the run's page."""
from __future__ import annotations

from typing import TYPE_CHECKING

from eval.present.rows import methods_in, ok_mask
from harness.method_registry import builtin_methods, method_meta

if TYPE_CHECKING:  # pandas is imported where a table is built
    import pandas as pd

__all__ = ["PROTOCOL_TEXT", "HANDLE_TEXT", "STATUS_TEXT", "stop_lines"]

#: How a method stopped, per protocol (``protocol`` column of the rows).
PROTOCOL_TEXT = {
    "converged": "converged protocol: L-BFGS-accelerated local/global (Laplacian as initial Hessian) until the "
                 "relative energy decrease and "
                 "the scale-free gradient norm are both below their thresholds",
    "paper": "paper protocol (§4.1): libigl local/global until the largest vertex move of one iteration is "
             "below tol x diagonal, at most 1000 iterations; a stop counts as converged only if the scale-free "
             "gradient norm is below the converged protocol's gtol, else as stalled",
    "converged-sr": "converged protocol (ARAP-SR): Gauss-Seidel local step, Anderson-accelerated, until the "
                    "relative energy decrease and the scale-free gradient norm are both below their thresholds",
    "move-rule": "move rule (ARAP-SR): Open3D's plain iteration until the largest vertex move of one iteration "
                 "is below tol x diagonal; converged only if the gradient norm is below gtol, else stalled",
    "paper-sr": "paper protocol (§4.1, ARAP-SR): Open3D's plain iteration (Jacobi local step) until the relative "
                "energy change of one iteration is below etol, at most 1000 iterations; converged only if the "
                "scale-free gradient norm is below gtol too, else stalled",
}


def _elsewhere_words(g) -> str:
    """How a scored method (results computed elsewhere) stopped, as far as the harness knows."""
    machines = sorted({str(x) for x in g.get("time_machine", []) if isinstance(x, str) and x})
    timed = int(g["time_s"].notna().sum()) if "time_s" in g.columns else 0
    told = any(c in g.columns and g[c].notna().any() for c in ("iterations", "converged"))
    return ("computed elsewhere: results read from files (eval.exchange.scored), "
            + ("how it stopped as the method reported it (its times file)" if told else
               "how the method stopped is not known here (a times file can say: iterations, converged)")
            + f"; Time as the method reported it on {len(g)} run(s): {timed} with a time"
            + (f" (machine: {', '.join(machines)})" if machines else ""))


def stop_lines(df: pd.DataFrame, *, short: bool = False) -> list[str]:
    """One line per method saying how it stopped, from the per-case rows: its protocol
    (``protocol`` column, :data:`PROTOCOL_TEXT`), the iteration range and how many of its
    successful runs met their stopping criterion (``iterations``, ``converged``), e.g.
    ``"Elastic: converged protocol: ...; 58-69 iterations; converged on 2/2 runs"``.
    ``short``: protocol names and ``"it."`` only (for the LaTeX footnote). Empty when
    the rows carry none of these columns."""
    if "method" not in df.columns or not {"iterations", "converged", "protocol", "preset",
                                          "time_reported"} & set(df.columns):
        return []
    ok = ok_mask(df)
    lines = []
    for m in methods_in(df):
        g = df[(df["method"] == m) & ok]
        if not len(g):
            continue
        parts = []
        if "protocol" in g.columns and g["protocol"].notna().any():
            protos = sorted({str(p) for p in g["protocol"].dropna()})
            parts.append("/".join(protos) + " protocol" if short
                         else "; ".join(PROTOCOL_TEXT.get(p, p) for p in protos))
        if "iterations" in g.columns and g["iterations"].notna().any():
            it = g["iterations"].dropna().astype(float)
            word = "it." if short else "iterations"
            parts.append(f"{int(it.min())}-{int(it.max())} {word}" if it.min() != it.max()
                         else f"{int(it.min())} {word}")
            note = method_meta(m)["iterations"]
            if note and not short:
                parts[-1] += f" ({note})"
        if "converged" in g.columns and g["converged"].notna().any():
            c = _flags(g["converged"].dropna())
            if short:
                parts.append(f"{int(c.sum())}/{len(c)} converged")
            else:
                parts.append(f"converged on {int(c.sum())}/{len(c)} runs" + _other_stops(g, c))
        if "time_reported" in g.columns and g["time_reported"].fillna(False).astype(bool).any():
            parts.append("computed elsewhere" if short else _elsewhere_words(g))
        parts += _preset_words(g, short)
        if not short:
            parts += _handle_words(g) + _reference_words(g, ours=m in builtin_methods())
        if parts:
            lines.append(f"{m}: " + (", " if short else "; ").join(parts))
    return lines


def _flags(col: pd.Series) -> pd.Series:
    """A boolean column of ``cases.csv`` as bools: True, 1 or 1.0 (as read back, text or
    number) is True, anything else (False, empty, NaN) False."""
    return col.map(lambda x: str(x).strip().lower() in ("true", "1", "1.0"))


#: What a method's ``handles`` column says, in words (the Handle column's meaning per row).
HANDLE_TEXT = {"hard": "handles are hard constraints (Handle is 0 by construction)",
               "overwritten": "handle vertices overwritten with their targets after averaging (Handle is 0 by "
                              "construction; Handle pre: the error before the overwrite)",
               "soft": "soft handles (a penalty term: Handle is what it reached)"}


def _handle_words(g: pd.DataFrame) -> list[str]:
    """The method's handle kind (``handles`` column, :data:`HANDLE_TEXT`), if stated."""
    if "handles" not in g.columns or not g["handles"].notna().any():
        return []
    words = "/".join(HANDLE_TEXT.get(str(k), str(k)) for k in sorted({str(x) for x in g["handles"].dropna()}))
    if "handles_missed" in g.columns:
        missed = _flags(g["handles_missed"])
        if missed.any():
            worst = g.loc[missed, "handle_err_pct"].astype(float).max()
            words += (f"; {int(missed.sum())} of {len(g)} runs above the handle bound (handle_error_max_pct), "
                      f"kept in the means with their Handle (largest {worst:.2f} %)")
    return [words]


def _reference_words(g: pd.DataFrame, *, ours: bool = True) -> list[str]:
    """Which minimiser Ref mean / Ref max / E gap measure against (``ref_energy_type``,
    ``ref_own_energy`` columns): the method's own energy, or one it does not minimise
    (``ours``: one of our methods; of another, one it is not known to minimise)."""
    if "ref_energy_type" not in g.columns or not g["ref_energy_type"].notna().any():
        return []
    e = "/".join(sorted({str(x) for x in g["ref_energy_type"].dropna()}))
    own = "ref_own_energy" in g.columns and _flags(g["ref_own_energy"].dropna()).all()
    return [f"Ref/E gap against the minimiser of its own energy ({e})" if own else
            f"Ref/E gap: distance to the full-resolution {e} minimiser, an energy it "
            f"{'does not minimise' if ours else 'is not known to minimise'}"]


#: How a run that did not converge stopped (``status`` column), in words.
STATUS_TEXT = {"stalled": "stalled (the stop rule fired with the gradient above gtol)",
               "max_iter": "hit the iteration cap", "time_budget": "hit the time budget"}


def _other_stops(g: pd.DataFrame, conv: pd.Series) -> str:
    """``" (stalled on 3, hit the iteration cap on 1)"``: how the runs of ``g`` that did
    not converge (``conv`` False) stopped, from the ``status`` column; empty when all
    converged."""
    if conv.all():
        return ""
    if "status" not in g.columns:
        return " (the others stopped without meeting it)"
    st = g.loc[conv.index[~conv.to_numpy()], "status"].fillna("unknown").astype(str).value_counts()
    return " (" + ", ".join(f"{STATUS_TEXT.get(k, k)} on {v}" for k, v in st.items()) + ")"


def _preset_words(g: pd.DataFrame, short: bool) -> list[str]:
    """A method's preset (``preset`` column, e.g. Implicit-ARAP's ``cpu``) and, where the
    rows give them, its fixed step counts (``sdf_steps``, ``deform_steps``): such a method
    stops after a set number of optimiser steps, and its time includes its SDF fit."""
    if "preset" not in g.columns or not g["preset"].notna().any():
        return []
    words = "/".join(sorted({str(p) for p in g["preset"].dropna()})) + " preset"
    if short:
        return [words]
    steps = [f"{'/'.join(str(int(x)) for x in sorted(set(g[c].dropna())))} {what}"
             for c, what in (("sdf_steps", "SDF-fit steps"), ("deform_steps", "deformation steps"))
             if c in g.columns and g[c].notna().any()]
    if steps:
        words += f": a fixed {' + '.join(steps)}, no stopping criterion"
    if "sdf_fit_s" in g.columns and g["sdf_fit_s"].notna().any():
        words += f"; its Time includes the SDF fit (mean {g['sdf_fit_s'].mean():.1f} s)"
    return [words]

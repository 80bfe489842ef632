"""The evaluator's progress estimate weighted by each method's expected cost (issue 21).

Counting (case, method) runs makes the estimate jump: on DeFAUST a full-resolution
baseline takes minutes per case, SShaDe seconds, so after a few SShaDe runs the bar
promises minutes and after a baseline it says hours. :class:`CostModel` instead
estimates the seconds of each remaining run:

- before any run of a method has finished, a prior: a full-resolution method (every
  method but ``SShaDe``; a plug-in may say ``cost_scale = "const"`` or ``"vertices"``)
  costs ``prior_s_per_vertex`` x n_vertices (default 1e-3 s/vertex: ~2.5 min at 150k),
  ``SShaDe`` a constant ``prior_const_s`` (default 20 s: it works at ~6000 vertices);
- once runs of the method have finished, their measured wall seconds (the method, its
  metrics and references): the mean of ``seconds / n_vertices`` (full resolution) or
  of ``seconds`` (constant) over them, times the case's scale.

The bar (:func:`weighted_bar`) counts seconds: after each run it advances by the run's
measured wall time and its total becomes done + the estimate of what remains, so its
remaining time is the weighted estimate. Runs restored from the result store
(:mod:`eval.store`) are not counted, but their stored ``time_s`` feed the model.
"""
from __future__ import annotations

__all__ = ["CostModel", "weighted_bar"]


class CostModel:
    """Per-method cost estimates (seconds) from priors and measured runs (module docstring)."""

    def __init__(self, scales: dict[str, str] | None = None, *, prior_s_per_vertex: float = 1e-3,
                 prior_const_s: float = 20.0):
        self.scales = dict(scales or {})
        self.prior_s_per_vertex = float(prior_s_per_vertex)
        self.prior_const_s = float(prior_const_s)
        self.seen: dict[str, list[float]] = {}

    @staticmethod
    def scale_of(method) -> str:
        """``"const"`` or ``"vertices"``: a method's ``cost_scale`` attribute when it has
        a valid one, else ``"const"`` for ``SShaDe`` (low-resolution work) and
        ``"vertices"`` for every other method (full resolution)."""
        s = getattr(method, "cost_scale", None)
        if s in ("const", "vertices"):
            return s
        return "const" if getattr(method, "name", "") == "SShaDe" else "vertices"

    def _unit(self, method: str, n_vertices: int) -> float:
        return 1.0 if self.scales.get(method, "vertices") == "const" else max(int(n_vertices), 1)

    def observe(self, method: str, n_vertices: int, seconds: float) -> None:
        """Record a finished run of ``method`` on a mesh of ``n_vertices`` that took ``seconds``."""
        if seconds is not None and seconds == seconds and seconds >= 0:
            self.seen.setdefault(method, []).append(float(seconds) / self._unit(method, n_vertices))

    def estimate(self, method: str, n_vertices: int) -> float:
        """Expected seconds of ``method`` on a mesh of ``n_vertices`` (>= 0).

        >>> cm = CostModel({"SShaDe": "const", "ARAP": "vertices"})
        >>> cm.estimate("ARAP", 150_000), cm.estimate("SShaDe", 150_000)
        (150.0, 20.0)
        >>> cm.observe("ARAP", 100_000, 50.0); cm.estimate("ARAP", 150_000)
        75.0
        """
        unit = self._unit(method, n_vertices)
        seen = self.seen.get(method)
        if seen:
            return sum(seen) / len(seen) * unit
        if self.scales.get(method, "vertices") == "const":
            return self.prior_const_s
        return self.prior_s_per_vertex * unit


def weighted_bar(total_s: float, n_runs: int, **kw):
    """A tqdm bar counting estimated seconds (stderr; its count of runs goes in the
    postfix, set by the caller). ``total_s``: the first estimate of all runs."""
    import sys

    from tqdm import tqdm
    return tqdm(total=max(total_s, 1e-9), desc=f"{n_runs} runs", file=sys.stderr, dynamic_ncols=True,
                bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}] {postfix}", **kw)

"""The evaluator's progress estimate weighted by each method's expected cost.
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/implementation.md.

:func:`default_cost_model` is the evaluator's model: the methods' priors plus the
per-pair overhead of the metrics (:data:`OVERHEAD_S_PER_VERTEX`); the up-front plan
(:mod:`eval.run.plan`) uses it too."""
from __future__ import annotations

from harness.method_registry import method_meta
from sshade.errors import SShaDeError

__all__ = ["CostModel", "weighted_bar", "default_cost_model", "size_factor", "OVERHEAD_S_PER_VERTEX",
           "PRIOR_VERTICES"]

#: What a pair costs beyond the method's ``time_s`` (its metrics, the ground-truth metrics,
#: reading a cached reference, the store, cases.csv, the report's 3D views), in seconds per
#: vertex: mostly the ground-truth Hausdorff and Chamfer (two point-to-surface queries
#: against a tree built once per case); measured as the spacing of a run's pairs in its
#: eval.log minus their ``time_s`` (about 3.7 s per pair at 169k vertices in the README's main
#: job, 4.2 s with the end's imbalance of two workers, at the probe's reference speed;
#: benchmarks/records/machine_speed.md, "The solvers' probe").
OVERHEAD_S_PER_VERTEX = 2.5e-5
#: The mesh size the methods' priors hold at (DeFAUST's high resolution: results/defaust's
#: mean, 150k-200k vertices); a prior's ``exponent`` carries it to other sizes.
PRIOR_VERTICES = 168_864


def size_factor(n_vertices: int, exponent: float) -> float:
    """How much a cost measured at :data:`PRIOR_VERTICES` grows at ``n_vertices`` (at least
    1) when it grows as ``n ** exponent``: ``(n / PRIOR_VERTICES) ** exponent``.

    >>> size_factor(PRIOR_VERTICES, 1.5), round(size_factor(PRIOR_VERTICES // 4, 2.0), 4)
    (1.0, 0.0625)
    """
    return (max(int(n_vertices), 1) / PRIOR_VERTICES) ** exponent


class CostModel:
    """Per-method cost estimates (seconds) from priors and measured runs (module docstring)."""

    def __init__(self, scales: dict[str, str] | None = None, *, prior_s_per_vertex: float = 1e-3,
                 prior_const_s: float = 20.0, priors: dict[str, float] | None = None,
                 overhead_s_per_vertex: float = 0.0, exponents: dict[str, float] | None = None,
                 speed: float = 1.0):
        """``scales``: method -> ``"const"`` / ``"vertices"`` (:meth:`scale_of`);
        ``priors``: method -> its own prior in its unit, before ``prior_s_per_vertex`` /
        ``prior_const_s``; ``overhead_s_per_vertex``: added to a prior (not to a
        measured cost, which includes it); ``exponents``: method -> ``p``, its cost taken
        as growing as ``n ** p`` with the vertices ``n`` about :data:`PRIOR_VERTICES`,
        where its prior holds (none: ``p`` = 1 for ``"vertices"``, 0 for ``"const"``);
        ``speed``: this machine's time factor against the priors' machine
        (:func:`eval.run.machine_speed.machine_speed`), multiplying every prior and guess
        (not a measured cost, which is this machine's already)."""
        self.scales = dict(scales or {})
        self.prior_s_per_vertex = float(prior_s_per_vertex)
        self.prior_const_s = float(prior_const_s)
        self.priors = {str(k): float(v) for k, v in (priors or {}).items()}
        self.overhead_s_per_vertex = float(overhead_s_per_vertex)
        self.exponents = {str(k): float(v) for k, v in (exponents or {}).items()}
        self.speed = float(speed)
        self.seen: dict[str, list[float]] = {}

    @staticmethod
    def scale_of(method) -> str:
        """``"const"`` or ``"vertices"``: a method's ``cost_scale`` attribute when it has
        a valid one, else its file's ``cost.scale`` (:func:`harness.method_registry.method_meta`;
        ``"vertices"``, full resolution, for a plug-in)."""
        s = getattr(method, "cost_scale", None)
        if s in ("const", "vertices"):
            return s
        return method_meta(getattr(method, "name", ""))["cost"]["scale"]

    def _unit(self, method: str, n_vertices: int) -> float:
        """What ``method``'s cost is per: 1 (``"const"``) or the vertices, scaled by
        ``(n / PRIOR_VERTICES) ** (p - default p)`` where it has an exponent ``p``."""
        n, const = max(int(n_vertices), 1), self.scales.get(method, "vertices") == "const"
        p = self.exponents.get(method)
        if p is None:
            return 1.0 if const else float(n)
        return (1.0 if const else PRIOR_VERTICES) * size_factor(n, p)

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
        overhead = self.overhead_s_per_vertex * max(int(n_vertices), 1)
        if method in self.priors:
            prior = self.priors[method] * unit
        elif self.scales.get(method, "vertices") == "const":
            prior = self.prior_const_s
        else:
            prior = self.prior_s_per_vertex * unit
        return (prior + overhead) * self.speed

    def basis(self, method: str) -> str:
        """What ``method``'s estimate rests on: ``"measured"`` (runs it has observed),
        ``"prior"`` (a per-method prior measured earlier), ``"guess"`` (the generic one)."""
        if self.seen.get(method):
            return "measured"
        return "prior" if method in self.priors else "guess"


def default_cost_model(methods, speed: float = 1.0) -> CostModel:
    """The evaluator's :class:`CostModel` for ``methods`` (objects with ``name``): their
    scales (:meth:`CostModel.scale_of`), the ``cost.prior`` of their files
    (:func:`harness.method_registry.method_meta`; left out where the method's scale is not the
    prior's, or its ``preset`` attribute is not the prior's ``cost.preset``;
    ``cost.paper`` instead for a method whose ``protocol`` is ``"paper"``) with the
    prior's ``cost.exponent`` (how its cost grows with the vertices from
    :data:`PRIOR_VERTICES`; not for ``cost.paper``, a fixed count of iterations, linear in
    the vertices) and :data:`OVERHEAD_S_PER_VERTEX`, all times ``speed`` (this machine's
    factor, :func:`eval.run.machine_speed.machine_speed`; 1: the priors' machine).

    Raises
    ------
    SShaDeError naming the method's file for a ``cost.exponent`` that is not a number in
    [0, 3].

    >>> from types import SimpleNamespace as M
    >>> cm = default_cost_model([M(name="ARAP"), M(name="SShaDe")])
    >>> round(cm.estimate("ARAP", 100_000)), round(cm.estimate("SShaDe", 100_000))
    (25, 5)
    """
    scales = {m.name: CostModel.scale_of(m) for m in methods}
    priors, exponents = {}, {}
    for m in methods:
        cost = method_meta(m.name)["cost"]
        if cost.get("prior") is None or scales[m.name] != cost["scale"]:
            continue
        if "preset" in cost and getattr(m, "preset", cost["preset"]) != cost["preset"]:
            continue  # a prior measured on one preset says nothing of another
        paper = getattr(m, "protocol", None) == "paper" and cost.get("paper") is not None
        priors[m.name] = float(cost["paper"] if paper else cost["prior"])
        p = cost.get("exponent")
        if p is not None and not paper:
            if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0 <= p <= 3:
                raise SShaDeError(f"conf/method/{m.name}.yaml: cost.exponent must be a number in [0, 3], got {p!r}")
            exponents[m.name] = float(p)
    return CostModel(scales, priors=priors, overhead_s_per_vertex=OVERHEAD_S_PER_VERTEX, exponents=exponents,
                     speed=speed)


def weighted_bar(total_s: float, n_runs: int, **kw):
    """A tqdm bar counting estimated seconds (stderr; its count of runs goes in the
    postfix, set by the caller). ``total_s``: the first estimate of all runs. Its
    :meth:`retotal` takes a new estimate without the fraction shown ever going back."""
    import sys

    from tqdm import tqdm

    class MonotoneBar(tqdm):
        def retotal(self, total: float) -> None:
            """Set the estimated total (seconds): a longer estimate than the bar can take
            without its fraction going back holds the fraction instead (the runs left
            then fill it more slowly); never below what is counted."""
            f = self.n / self.total if self.total else 0.0
            total = max(float(total), float(self.n), 1e-9)
            if 0.0 < f <= 1.0 and self.n / total < f:
                total = self.n / f
            self.total = total

        def advance(self, seconds: float) -> None:
            """Count ``seconds`` more, the total raised first where they overfill it (the
            fraction then rises to 1, never past it: not :meth:`retotal`, which would hold
            the fraction before the count and leave the count above the total)."""
            self.total = max(float(self.total), self.n + seconds)
            self.update(seconds)

    return MonotoneBar(total=max(total_s, 1e-9), desc=f"{n_runs} runs", file=sys.stderr, dynamic_ncols=True,
                       bar_format="{desc}: {percentage:3.0f}%|{bar}| [{elapsed}<{remaining}] {postfix}", **kw)

"""The ``reference`` config section at work in the ``cases`` experiment
(:class:`CaseReferences`): which cases get reference solutions, computed once per
(case, energy) and cached (:mod:`eval.metrics.reference`), and a row's reference columns."""
from __future__ import annotations

import logging

from eval.metrics.reference import reference_solution, status_words
from eval.metrics.reference_scores import energy_operators, method_energy, reference_metrics, sr_alpha
from eval.run.spec import ReferenceOptions
from eval.run.subset import baseline_selection

__all__ = ["CaseReferences"]

log = logging.getLogger("eval")


class CaseReferences:
    """The ``reference`` section (``options``, checked) at work: for the cases it selects
    (``reference.cases``: ``baseline`` = the cases the full-resolution baselines run on,
    ``dataset.baseline_cases``; ``all``; ``none``; or a rule of its own, ``per_pose`` or
    an integer, as for ``dataset.baseline_cases``), the deep-converged full-resolution
    minimiser of the energy each method is compared with
    (:func:`eval.metrics.reference_scores.method_energy`), computed once per (case, energy), cached in
    ``reference.cache`` and reused by later runs; :meth:`metrics` gives a row's
    ``ref_mean_pct``, ``ref_max_pct``, ``energy_gap`` columns (none outside the selection).
    The reference's own solve is not part of any method's ``time_s``."""

    def __init__(self, options: ReferenceOptions):
        self.mode = options.cases if options.cases in ("baseline", "all", "none") else "rule"
        self.rule = options.cases  # a case rule of its own, as dataset.baseline_cases (eval/run/subset.py)
        self._sel = None  # (cases, indices) of the own rule, computed once per case list
        self.cache = options.cache
        self.max_iter = options.max_iter
        self.time_budget_s = options.time_budget_s
        self.case = None
        self.refs: dict = {}
        self.ops: dict = {}
        self.computed_s = 0.0  # seconds spent computing references (not read from the cache)

    def covers(self, ci: int, cases, base) -> bool:
        """Whether case ``ci`` of ``cases`` gets references: ``base`` is the baseline
        subset (indices, None = every case) that ``baseline`` follows; ``per_pose`` or an
        integer select as :func:`eval.run.subset.baseline_selection` does."""
        if self.mode in ("all", "none", "baseline"):
            return self.mode == "all" or (self.mode == "baseline" and (base is None or ci in base))
        if self._sel is None or self._sel[0] is not cases:
            self._sel = (cases, baseline_selection(cases, self.rule)[0])
        return self._sel[1] is None or ci in self._sel[1]

    def settings(self, on: bool) -> dict:
        """What of this section changes a row on a case (covered or not, :meth:`covers`):
        whether references are computed there and with which limits (:mod:`eval.run.result_store`)."""
        return {"on": True, "max_iter": self.max_iter, "time_budget_s": self.time_budget_s} if on else {"on": False}

    def start_case(self, ci: int, case, on: bool = True) -> None:
        """Case ``ci`` starts (``on``: :meth:`covers` it); earlier solutions dropped."""
        self.refs, self.ops = {}, {}
        self.case = case if on else None

    def metrics(self, method, Vd) -> dict:
        if self.case is None:
            return {}

        c, e = self.case, method_energy(method)
        if e not in self.refs:
            # a full-resolution solve of this very energy (ARAP, Elastic under the converged
            # protocol, from the rigid fit or their coarse start) is on the deep solve's own
            # path: continue from it
            # (ARAP-SR's converged protocol: the deep solve continues from its result and rotations)
            converged = getattr(method, "protocol", None) == "converged"
            same_path = converged and (getattr(method, "energy", None) == e or sr_alpha(e) is not None)
            self.refs[e] = reference_solution(c.V, c.F, c.handles, c.targets, energy=e, cache_dir=self.cache,
                                              max_iter=self.max_iter, time_budget_s=self.time_budget_s,
                                              U0=Vd if same_path else None,
                                              R0=getattr(method, "rotations", None) if same_path else None)
            self.ops[e] = energy_operators(c.V, c.F, e)
            ref = self.refs[e]
            if not ref.info.get("cached"):
                self.computed_s += float(ref.info.get("seconds") or 0.0)
            log.info("%s reference (%s): %s, %s iterations, %s", c.name, e,
                     "cached" if ref.info.get("cached") else f"computed in {ref.info.get('seconds')} s",
                     ref.info.get("iterations"), status_words(ref.info.get("status")))
        ref = self.refs[e]
        R = getattr(method, "rotations", None) if sr_alpha(e) is not None else None
        out = reference_metrics(c.V, Vd, c.F, ref, operators=self.ops[e], R0=R)
        out.update(ref_energy_type=e, ref_status=ref.info.get("status"), ref_iterations=ref.info.get("iterations"),
                   ref_own_energy=bool(getattr(method, "energy", None) == e or sr_alpha(e) is not None))
        return out

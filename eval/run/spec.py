"""What one evaluator run is asked to do, checked and typed: frozen objects made once at the
door (:func:`eval.config_check.check_config`) from the composed config, then handed down.
Floor 0 of eval/ (eval/run/, tests/test_layering.py); the config's types: eval/config_schema.py.

Below the commands no function takes the config itself: each takes the object it reads
(:class:`DatasetSpec`, :class:`MethodSpec`, :class:`ReferenceOptions`, ...), an experiment
the whole :class:`EvalSpec`."""
from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["MethodSpec", "DatasetSpec", "GuardOptions", "ReferenceOptions", "ReportOptions", "FigureOptions",
           "OutputOptions", "ExperimentSpec", "EvalSpec"]


@dataclass(frozen=True)
class MethodSpec:
    """One entry of ``methods``.

    Attributes
    ----------
    name : our method's name (:func:`harness.method_registry.canonical_name`), or None for a
        plug-in.
    definition : what it is built from, resolved: ours its definition ``method.<key>``
        (``_target_`` and parameters, :func:`eval.config_check.method_definition`), a
        plug-in its ``_target_`` mapping as given.
    where : its place in the config, for messages (``method.ARAP``, ``methods[1]``).
    """

    name: str | None
    definition: Mapping
    where: str


@dataclass(frozen=True)
class DatasetSpec:
    """The ``dataset`` section.

    Attributes
    ----------
    name : ``dataset.name``.
    root : ``dataset.root`` as given (None when not set).
    loader : the keyword options of its loader (:func:`eval.datasets.dataset_options`).
    section : the whole section as plain values, for the dataset's own steps (its
        ``prepare`` and ``outlook``, e.g. DeFAUST's ``build``).
    baseline_cases : the baselines' case rule (checked: ``all``, ``per_pose``, an int, None).
    seed : ``dataset.seed`` (None when it has none).
    sample, sample_seed : the run's seeded sample of cases (None: every case) and its seed
        (checked, :func:`eval.run.subset.sample_cases`).
    """

    name: str
    root: str | None
    loader: Mapping
    section: Mapping
    baseline_cases: Any = None
    seed: Any = None
    sample: int | None = None
    sample_seed: int = 0


@dataclass(frozen=True)
class GuardOptions:
    """``timeout_s`` (seconds, None: no limit) and ``handle_error_max_pct`` (% of the
    bounding-box diagonal, None: no limit), checked."""

    timeout_s: float | None = None
    handle_error_max_pct: float | None = None

    def as_dict(self) -> dict:
        """``{"timeout_s", "handle_error_max_pct"}``, as the result store keys them."""
        return {"timeout_s": self.timeout_s, "handle_error_max_pct": self.handle_error_max_pct}


@dataclass(frozen=True)
class ReferenceOptions:
    """The ``reference`` section: ``cases`` (``baseline``, ``all``, ``none``, ``per_pose`` or
    an int >= 0), the ``cache`` folder (absolute), the deep solve's ``max_iter`` and
    ``time_budget_s`` (None: no budget)."""

    cases: str | int = "baseline"
    cache: Path = Path("data/references")
    max_iter: int = 50000
    time_budget_s: float | None = 3600.0


@dataclass(frozen=True)
class ReportOptions:
    """The ``report`` section: ``enabled`` (``index.html`` at the end), the 3D views of the
    first ``view_cases`` cases with at most ``max_faces`` faces per mesh."""

    enabled: bool = True
    view_cases: int = 2  # as eval.config_schema.ReportSchema (tests/test_typed_config.py holds them equal)
    max_faces: int = 30000

    @property
    def views(self) -> int:
        """How many cases get a 3D view: ``view_cases``, none when the report is off."""
        return self.view_cases if self.enabled else 0


@dataclass(frozen=True)
class FigureOptions:
    """The ``figures`` section: ``enabled``, the figures of the first ``max_cases`` cases."""

    enabled: bool = False
    max_cases: int = 0


@dataclass(frozen=True)
class OutputOptions:
    """Where the run writes: ``out_dir`` (as given; the claimed folder once claimed),
    ``overwrite``, ``resume``, ``store_meshes`` (``store.meshes``) and ``compare_with``
    (earlier run folders, as given)."""

    out_dir: str = ""
    overwrite: bool = False
    resume: bool = False
    store_meshes: bool = False
    compare_with: tuple[str, ...] = ()


@dataclass(frozen=True)
class ExperimentSpec:
    """``experiment.name``, ``experiment.kind`` and the kind's own options (the typed
    object its registration makes of its section, None for a kind without one)."""

    name: str
    kind: str = "cases"
    options: Any = None


@dataclass(frozen=True)
class EvalSpec:
    """One evaluator run, checked and typed.

    Attributes
    ----------
    experiment, dataset (None without a ``dataset`` section), methods (``methods``, in
    table order), guard, reference, report, figures, output : see each class.
    definitions : every built-in method's resolved definition, by name (SShaDe's
        parameters for every experiment, Elastic's for the scaling one).
    jobs : worker processes, None for ``auto``.
    method_cases : a method's own case rule (``method_cases``), checked, or None.
    resolved : the whole config as plain values, resolved (``run.json``'s ``config``).
    composed : the whole config unresolved (``.hydra/config.yaml``).
    """

    experiment: ExperimentSpec
    dataset: DatasetSpec | None = None
    methods: tuple[MethodSpec, ...] = ()
    definitions: Mapping = field(default_factory=dict)
    guard: GuardOptions = field(default_factory=GuardOptions)
    reference: ReferenceOptions = field(default_factory=ReferenceOptions)
    report: ReportOptions = field(default_factory=ReportOptions)
    figures: FigureOptions = field(default_factory=FigureOptions)
    output: OutputOptions = field(default_factory=OutputOptions)
    jobs: int | None = None
    method_cases: Mapping | None = None
    resolved: Mapping = field(default_factory=dict)
    composed: Mapping = field(default_factory=dict)

    def definition(self, name: str) -> dict:
        """A copy of built-in method ``name``'s resolved definition (``_target_`` and
        parameters). Raises KeyError for a name that is none of them."""
        return copy.deepcopy(dict(self.definitions[name]))

    def record(self) -> dict:
        """A copy of :attr:`resolved`, for ``run.json`` (the experiment may note in it
        what it resolved itself, e.g. the dataset's root)."""
        return copy.deepcopy(dict(self.resolved))

    def with_out_dir(self, out_dir) -> EvalSpec:
        """This run writing into ``out_dir`` (the folder claimed), in the records too."""
        d = str(out_dir)
        return dataclasses.replace(self, output=dataclasses.replace(self.output, out_dir=d),
                                   resolved={**self.resolved, "out_dir": d}, composed={**self.composed, "out_dir": d})


"""What one evaluator run is asked to do, checked and typed: objects made once at the door
(:func:`eval.config_check.check_config`) from the composed config, then handed down; the
``reference``, ``report`` and ``figures`` sections are their own Hydra schemas (typed by
OmegaConf, checked when made). Floor 0 of eval/ (eval/run/, tests/test_layering.py); the
config's other types: eval/config_schema.py.

Below the commands no function takes the config itself: each takes the object it reads
(:class:`DatasetSpec`, :class:`MethodSpec`, :class:`ReferenceOptions`, ...), an experiment
the whole :class:`EvalSpec`."""
from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Optional  # OmegaConf 2.3 reads typing's generics

from eval.run.paths import abs_path
from eval.run.subset import check_baseline_cases
from harness.checks import check_fields, checked_field
from sshade.errors import SShaDeError
from sshade.params import SShaDeParams

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
    """The ``dataset`` section: its dataset's options object, read through the keys every
    dataset shares.

    Attributes
    ----------
    options : the section as its dataset's options dataclass (registered with the dataset,
        a subclass of :class:`eval.datasets.dataset_options.DatasetOptions`, e.g.
        :class:`eval.datasets.faust.FaustOptions`), made and checked at the door
        (:func:`eval.config_check.check_config`); what the dataset's loader, ``prepare`` and
        ``outlook`` take.
    """

    options: Any

    @property
    def name(self) -> str:
        """``dataset.name``."""
        return self.options.name

    @property
    def root(self) -> str | None:
        """``dataset.root`` as given (None when not set)."""
        return self.options.root

    @property
    def baseline_cases(self):
        """The baselines' case rule (checked: None for every case, ``per_pose`` or an int)."""
        return self.options.baseline_cases

    @property
    def seed(self):
        """``dataset.seed`` (None when the dataset has none)."""
        return getattr(self.options, "seed", None)

    @property
    def sample(self) -> int | None:
        """The run's seeded sample of cases (None: every case), :func:`eval.run.subset.sample_cases`."""
        return self.options.sample

    @property
    def sample_seed(self) -> int:
        """The sample's seed."""
        return self.options.sample_seed


@dataclass(frozen=True)
class GuardOptions:
    """``timeout_s`` (seconds, None: no limit) and ``handle_error_max_pct`` (% of the
    bounding-box diagonal, None: no limit), checked."""

    timeout_s: float | None = None
    handle_error_max_pct: float | None = None

    def as_dict(self) -> dict:
        """``{"timeout_s", "handle_error_max_pct"}``, as the result store keys them."""
        return {"timeout_s": self.timeout_s, "handle_error_max_pct": self.handle_error_max_pct}


@dataclass
class ReferenceOptions:
    """The ``reference`` section, typed (the Hydra schema of ``conf/config.yaml``'s
    ``reference``, eval/config_schema.py) and checked when made (:meth:`__post_init__`):
    ``cases`` (``baseline``, ``all``, ``none``, ``per_pose`` or an int >= 0), the ``cache``
    folder (made absolute), the deep solve's ``max_iter`` (>= 1) and ``time_budget_s``
    (seconds > 0, None: no budget; a float once made). SShaDeError naming the key."""

    cases: Any = "baseline"
    cache: str = "data/references"
    max_iter: int = checked_field(int, min=1, default=50000)
    time_budget_s: Any = checked_field(float, min=0, allow_none=True, default=3600)

    def __post_init__(self):
        cases = str(self.cases).strip()
        if cases not in ("baseline", "all", "none"):
            try:
                cases = check_baseline_cases(cases)
            except SShaDeError:
                raise SShaDeError(f"reference.cases must be baseline, all, none, per_pose or an integer >= 0, "
                                  f"got {self.cases!r}") from None
        check_fields(self, "reference")
        tb = self.time_budget_s
        if tb is not None and tb <= 0:
            raise SShaDeError(f"reference.time_budget_s must be a finite number > 0 (or null), got {tb!r}")
        self.cases, self.cache = cases, abs_path(self.cache)


@dataclass
class ReportOptions:
    """The ``report`` section, typed (the Hydra schema of ``conf/config.yaml``'s ``report``)
    and checked when made: ``enabled`` (``index.html`` at the end), the 3D views of the
    first ``view_cases`` cases (>= 0; None: none) with at most ``max_faces`` faces per mesh
    (in [100, 2,000,000]). SShaDeError naming the key."""

    enabled: bool = True
    view_cases: Optional[int] = checked_field(int, min=0, allow_none=True, default=2)
    max_faces: int = checked_field(int, min=100, max=2_000_000, default=30000)

    def __post_init__(self):
        check_fields(self, "report")
        self.view_cases = self.view_cases or 0

    @property
    def views(self) -> int:
        """How many cases get a 3D view: ``view_cases``, none when the report is off."""
        return self.view_cases if self.enabled else 0


@dataclass
class FigureOptions:
    """The ``figures`` section, typed (the Hydra schema of ``conf/config.yaml``'s
    ``figures``) and checked when made: ``enabled``, the figures of the first
    ``max_cases`` cases (>= 0; None: 4); ``rerun_restored``: a restored run of those
    cases (and of the 3D views' cases) whose record keeps no mesh is run again once
    every pair has run, and shown when it gives the stored vertices bit for bit (else
    the output is not drawn). SShaDeError naming the key."""

    enabled: bool = False
    max_cases: Optional[int] = checked_field(int, min=0, allow_none=True, default=4)
    rerun_restored: bool = True

    def __post_init__(self):
        check_fields(self, "figures")
        if self.max_cases is None:
            self.max_cases = FigureOptions.max_cases  # the field's default


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
    definitions : every built-in method's resolved definition, by name (Elastic's for the
        scaling experiment; what :func:`eval.method_config.make_methods` builds from).
    sshade : SShaDe's parameters, checked (:func:`sshade.params.check_params`), from its
        definition ``method.SShaDe`` (default: the ``sshade`` section): every experiment
        reads them here.
    jobs : worker processes, None for ``auto``.
    method_cases : a method's own case rule (``method_cases``), checked, or None.
    resolved : the whole config as plain values, resolved (``run.json``'s ``config``).
    composed : the whole config unresolved (``.hydra/config.yaml``).
    """

    experiment: ExperimentSpec
    dataset: DatasetSpec | None = None
    methods: tuple[MethodSpec, ...] = ()
    definitions: Mapping = field(default_factory=dict)
    sshade: Optional[SShaDeParams] = None
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


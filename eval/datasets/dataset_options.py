"""The keys every dataset's section shares (``dataset.name``, ``root``, ``limit``, ``sample``,
``sample_seed``, ``baseline_cases``): :class:`DatasetOptions`, which each dataset's own
options dataclass extends (e.g. :class:`eval.datasets.faust.FaustOptions`) and registers
with its loader (:func:`eval.datasets.register_dataset`): the type of ``conf/dataset/NAME.yaml``,
made at the door by :func:`eval.config_schema.typed_object`, its checks in ``__post_init__``.
Floor 2 of eval/ (eval/datasets/, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional  # OmegaConf 2.3 reads typing's generics

from omegaconf import MISSING

from eval.run.subset import check_baseline_cases, check_sample
from harness.checks import check_fields, checked_field

__all__ = ["DatasetOptions"]


@dataclass
class DatasetOptions:
    """The keys of every ``conf/dataset/NAME.yaml``, checked when made (SShaDeError naming
    ``dataset.<key>``); a dataset's own dataclass extends it with its keys (and its own
    defaults of these), in the order of its file, each number's or integer list's kind and
    bounds declared on its field (:func:`harness.checks.checked_field`): the one walk of
    :meth:`__post_init__` (:func:`harness.checks.check_fields`) checks them all.

    Attributes
    ----------
    name : ``dataset.name``, the registered dataset (the subclass sets it).
    root : its folder as given (None: not set), resolved by :func:`eval.datasets.dataset_root`.
    limit : the first ``limit`` cases only (>= 1; None: every case).
    sample, sample_seed : a seeded sample of ``sample`` cases (>= 1; None: every case) and
        its seed (>= 0), :func:`eval.run.subset.sample_cases`.
    baseline_cases : the full-resolution baselines' cases: None (every case, also for
        ``all``), ``per_pose`` or an int N >= 0 (the first N), :func:`eval.run.subset.baseline_selection`.
    """

    name: str = MISSING
    root: Optional[str] = None
    limit: Optional[int] = checked_field(int, min=1, allow_none=True, default=None)
    sample: Optional[int] = None
    sample_seed: int = 0
    baseline_cases: Any = None

    def __post_init__(self):
        check_fields(self, "dataset")  # every declared field, the subclass's own too
        self.baseline_cases = check_baseline_cases(self.baseline_cases)
        self.sample, self.sample_seed = check_sample(self.sample, self.sample_seed)

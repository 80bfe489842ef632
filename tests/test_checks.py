"""harness/checks.py: a field's kind and bounds declared once beside it, one walk
(``check_fields``) checking a record, and the value checkers a door uses on the keys it reads."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Optional

import pytest
from omegaconf import OmegaConf

from harness.checks import (
    MAX_INT,
    check_bool,
    check_fields,
    check_int_list,
    check_number,
    checked_field,
    config_value,
)
from sshade.errors import SShaDeError
from sshade.pipeline import MAX_SEED


@dataclass
class Toy:
    """A section with one field of each declared kind, and one left undeclared."""

    limit: Optional[int] = checked_field(int, min=1, allow_none=True, default=None)
    n_targets: int = checked_field(int, min=1, default=4)
    threshold: float = checked_field(float, min=0, default=0.02)
    seed: int = checked_field(int, min=0, default=0)
    subjects: Any = checked_field(list[int], allow_none=True, default=None)
    label: str = "free"  # not declared: the walk leaves it alone

    def __post_init__(self):
        check_fields(self, "dataset")


@dataclass(frozen=True)
class FrozenToy:
    """A frozen record: the walk sets its coerced values all the same."""

    timeout_min: int = checked_field(int, min=1, default=60)
    mem_gb: Optional[float] = checked_field(float, min=0.001, allow_none=True, default=None)
    sizes: Any = checked_field(list[int], min=4, allow_none=True, default_factory=list)

    def __post_init__(self):
        check_fields(self, "cluster")


@dataclass
class Nested:
    """A record holding another: the inner one's fields are walked under its name."""

    plane: Toy = field(default_factory=Toy)


def _message(fn) -> str:
    with pytest.raises(SShaDeError) as e:
        fn()
    return str(e.value)


def test_a_field_declared_once_is_checked_by_the_walk_with_the_message_of_before():
    assert _message(lambda: Toy(limit="abc")) == \
        "dataset.limit must be an integer in [1, 2147483647] (or null), got 'abc'"
    assert _message(lambda: Toy(n_targets=0)) == "dataset.n_targets must be an integer in [1, 2147483647], got 0"
    assert _message(lambda: Toy(threshold=float("nan"))) == "dataset.threshold must be a finite number >= 0, got nan"
    assert _message(lambda: Toy(subjects=[1, "a"])) == \
        "dataset.subjects must be a list of integers in [0, 2147483647], got 'a' in [1, 'a']"
    # the value checker a door uses on a key it read gives the same text
    assert _message(lambda: check_number("abc", "dataset.limit", min=1, allow_none=True)) == \
        "dataset.limit must be an integer in [1, 2147483647] (or null), got 'abc'"
    # a dataset's own options: the field's declaration, checked by the base class's one walk
    from eval.datasets.faust import FaustOptions
    assert _message(lambda: FaustOptions(root="x", n_per_landmark=0)) == \
        "dataset.n_per_landmark must be an integer in [1, 2147483647], got 0"


def test_a_field_named_seed_is_bounded_by_max_seed():
    assert Toy(seed=MAX_SEED).seed == MAX_SEED
    assert _message(lambda: Toy(seed=MAX_SEED + 1)) == \
        f"dataset.seed must be an integer in [0, {MAX_SEED}], got {MAX_SEED + 1}"
    assert _message(lambda: Toy(n_targets=MAX_INT + 1)).startswith("dataset.n_targets must be an integer in [1, ")


def test_a_frozen_record_is_coerced():
    r = FrozenToy(timeout_min=1e3, mem_gb=4, sizes=(5, 6.0))
    assert r.timeout_min == 1000 and type(r.timeout_min) is int
    assert r.mem_gb == 4.0 and type(r.mem_gb) is float
    assert r.sizes == [5, 6] and all(type(x) is int for x in r.sizes)
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.timeout_min = 2  # still frozen to everyone else
    assert _message(lambda: FrozenToy(mem_gb=0)) == "cluster.mem_gb must be a finite number >= 0.001 (or null), got 0"
    # the cluster section, a frozen record of harness/slurm_array.py, coerced the same way
    from harness.slurm_array import cluster_options
    good = {"executor": "slurm", "partition": None, "account": None, "qos": None, "timeout_min": 6e1,
            "cpus_per_task": 2, "mem_gb": 4, "array_parallelism": 8, "setup": None, "additional_parameters": {},
            "folder": "slurm", "poll_s": 10, "grace_polls": 2, "unreachable_s": 1800}
    got = cluster_options(good)
    assert got.timeout_min == 60 and type(got.timeout_min) is int and type(got.poll_s) is float


def test_a_bool_is_refused_where_a_number_is_expected():
    assert _message(lambda: Toy(n_targets=True)) == "dataset.n_targets must be an integer in [1, 2147483647], got True"
    assert _message(lambda: Toy(threshold=False)) == "dataset.threshold must be a finite number >= 0, got False"
    assert _message(lambda: Toy(subjects=[0, True])).startswith("dataset.subjects must be a list of integers")
    assert _message(lambda: check_bool(1, "resume")) == "resume must be true or false, got 1"


def test_an_absent_optional_key_keeps_its_default():
    t = Toy()
    assert (t.limit, t.n_targets, t.threshold, t.subjects, t.label) == (None, 4, 0.02, None, "free")
    # composed by OmegaConf from a section that leaves the keys out, as at the door
    made = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(Toy), {"n_targets": 7}))
    assert (made.limit, made.n_targets, made.subjects) == (None, 7, None)
    # a door's read of an absent key: its default, then checked
    cfg = OmegaConf.create({"dataset": {"n_targets": 7}})
    assert check_number(config_value(cfg, "dataset.limit", None), "dataset.limit", min=1, allow_none=True) is None
    assert check_int_list(config_value(cfg, "dataset.subjects", None), "dataset.subjects") is None


def test_the_walk_names_a_nested_record_by_its_field():
    inner = Toy()
    object.__setattr__(inner, "n_targets", -1)
    assert _message(lambda: check_fields(Nested(plane=inner), "convergence")) == \
        "convergence.plane.n_targets must be an integer in [1, 2147483647], got -1"


def test_a_kind_the_walk_cannot_check_is_refused_when_declared():
    with pytest.raises(ValueError, match="kind must be"):
        checked_field(str, default="x")

"""Each dataset's keys are written once, in the options dataclass its module registers
(eval/datasets/: ``FaustOptions``, ``DefaustOptions``, ``ShapesOptions``, over
``DatasetOptions``): ``conf/dataset/NAME.yaml`` sets exactly its fields to their defaults,
and a key added to a dataclass reaches Hydra's composition, the loader and the door's
error messages with no other edit."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import pytest
from omegaconf import OmegaConf

from eval import config_schema
from eval.app import CONF_DIR
from eval.config_check import check_config
from eval.config_schema import dataset_schemas, store_schemas
from eval.datasets import dataset_registry, datasets, load_cases, register_dataset
from eval.datasets.dataset_options import DatasetOptions
from eval.datasets.faust import FaustOptions
from harness.command import config_error_types, hydra_message
from sshade.errors import SShaDeError

from .conftest import ROOT


def _yaml(name: str) -> dict:
    """``conf/dataset/<name>.yaml``'s own keys (its defaults list left out), unresolved."""
    d = OmegaConf.to_container(OmegaConf.load(ROOT / "conf" / "dataset" / f"{name}.yaml"), resolve=False)
    d.pop("defaults", None)
    return d


def _default(f: dataclasses.Field):
    """A field's default as plain values (a dataclass default as its mapping)."""
    v = f.default if f.default is not dataclasses.MISSING else f.default_factory()
    return dataclasses.asdict(v) if dataclasses.is_dataclass(v) else v


def test_each_dataset_file_sets_exactly_its_options_fields_to_their_defaults():
    """Every key of conf/dataset/NAME.yaml is a field of the dataset's options dataclass and
    every field a key, in the same order, its value the field's default (``???`` for a key
    the user sets, FAUST's ``root``), so the YAML and the Python API cannot disagree."""
    found = datasets()
    assert sorted(found) == sorted(p.stem for p in (ROOT / "conf" / "dataset").glob("*.yaml"))
    for name, d in found.items():
        yaml = _yaml(name)
        assert issubclass(d.options, DatasetOptions) and dataset_schemas()[name] is d.options, name
        assert list(yaml) == list(d.keys) == [f.name for f in dataclasses.fields(d.options)], name
        for f in dataclasses.fields(d.options):
            assert yaml[f.name] == _default(f), f"{name}: dataset.{f.name}: {yaml[f.name]!r} vs {_default(f)!r}"
        assert yaml["name"] == name


def test_the_shared_keys_live_in_the_base_and_nowhere_else():
    """``limit``, ``sample``, ``sample_seed`` are declared once (DatasetOptions), not again
    in a dataset's own dataclass (those override a default only: ``name``, ``root``,
    ``baseline_cases``)."""
    shared = {f.name for f in dataclasses.fields(DatasetOptions)}
    for name, d in datasets().items():
        own = set(d.options.__dict__.get("__annotations__", {}))
        assert own & shared <= {"name", "root", "baseline_cases"}, (name, own & shared)


def test_a_bad_value_is_refused_by_the_options_naming_the_key():
    for kw, words in [({"limit": 0}, "dataset.limit"), ({"n_per_landmark": 0}, "dataset.n_per_landmark"),
                      ({"subjects": [0, "x"]}, "dataset.subjects"), ({"protocol": "sideways"}, "dataset.protocol"),
                      ({"baseline_cases": -1}, "dataset.baseline_cases"), ({"sample_seed": -1}, "dataset.sample_seed")]:
        with pytest.raises(SShaDeError, match=words.replace(".", r"\.")):
            FaustOptions(**kw)
    assert FaustOptions(subjects=3, baseline_cases="all").subjects == [3]


# ----------------------------------------------------------------------------- a toy dataset
@dataclass
class ToyOptions(FaustOptions):
    """FAUST's options with one key more, ``newkey`` (>= 0)."""

    name: str = "toy"
    newkey: int = 7

    def __post_init__(self):
        super().__post_init__()
        if self.newkey < 0:
            raise SShaDeError(f"dataset.newkey must be an integer >= 0, got {self.newkey!r}")


@pytest.fixture
def toy(monkeypatch, tmp_path):
    """``toy`` registered (its loader records the options it gets) and its file
    ``dataset/toy.yaml`` (extending ``schema/dataset/toy`` as every dataset file does) on
    Hydra's search path; the registries as they were afterwards."""
    from hydra.core.config_store import ConfigStore
    datasets()  # every real dataset registered first
    monkeypatch.setattr(dataset_registry._REGISTRY, "_items", dict(dataset_registry._REGISTRY._items))
    monkeypatch.setattr(config_schema, "_DATASETS", dict(config_schema._DATASETS))
    got = []
    register_dataset("toy", lambda root, options: got.append((root, options)) or [], options=ToyOptions)
    store_schemas()
    (tmp_path / "dataset").mkdir()
    (tmp_path / "dataset" / "toy.yaml").write_text(
        "defaults:\n  - /schema/dataset/toy@_here_\n  - _self_\nname: toy\nroot: somewhere\nnewkey: 7\n")
    yield tmp_path, got
    ConfigStore.instance().repo["schema"]["dataset"].pop("toy.yaml", None)


def _compose(search, overrides):
    from hydra import compose, initialize_config_dir
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=[f"hydra.searchpath=[file://{search}]", "dataset=toy",
                                                        "experiment=tosca", *overrides])


def test_a_new_options_field_reaches_the_yaml_schema(toy):
    search, _ = toy
    assert _compose(search, []).dataset.newkey == 7
    assert _compose(search, ["dataset.newkey=3"]).dataset.newkey == 3
    with pytest.raises(config_error_types()) as e:  # typed by the field: Hydra's own refusal
        _compose(search, ["dataset.newkey=abc"])
    assert "dataset.newkey" in hydra_message(e.value) and "\n" not in hydra_message(e.value)


def test_a_new_options_field_reaches_the_loader(toy):
    search, got = toy
    spec = check_config(_compose(search, ["dataset.newkey=3", "dataset.limit=2"]))
    assert type(spec.dataset.options) is ToyOptions and spec.dataset.name == "toy"
    assert load_cases(spec.dataset.name, search, spec.dataset.options) == []
    (root, options), = got
    assert root == search and options.newkey == 3 and options.limit == 2 and options.protocol == "paper"


@pytest.mark.parametrize("cfg", [["dataset.newkey=-1"], {"dataset": {"name": "toy", "newkey": -1}},
                                 {"dataset": {"name": "toy", "newkey": "abc"}}])
def test_a_new_options_field_is_refused_at_the_door_in_one_line_naming_it(toy, cfg):
    search, got = toy
    with pytest.raises(SShaDeError) as e:
        check_config(_compose(search, cfg) if isinstance(cfg, list) else {"methods": ["ARAP"], **cfg})
    assert str(e.value).startswith("dataset.newkey") and "\n" not in str(e.value), str(e.value)
    assert got == []

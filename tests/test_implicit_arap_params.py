"""Implicit-ARAP's parameters as one object (baselines/implicit_arap/params.py), without
PyTorch: each checked field refuses a bad value naming itself, a None takes the preset's
value, overrides over an object or a mapping equal the object built at once, each field is
documented once, and conf/method/Implicit-ARAP.yaml holds exactly the fields, at their
defaults. With PyTorch (the method built from them): tests/test_implicit_arap.py."""
from __future__ import annotations

import dataclasses
import math
import re

import pytest
from omegaconf import OmegaConf

from baselines.implicit_arap.params import PRESETS, SETTINGS, ImplicitARAPParams, implicit_arap_params
from harness.method_registry import META_KEYS, file_spec
from sshade.errors import SShaDeError

from .conftest import ROOT

FIELDS = [f.name for f in dataclasses.fields(ImplicitARAPParams)]

#: field -> bad values, each refused with the field's name in the message
BAD = {
    "preset": ["gpu", None], "device": ["tpu", "CUDA"], "seed": [-1, 1.5, True, "0"],
    "layers": [1, 4.0], "width": [0], "skip": [-1, 3, True], "octaves": [-1], "sdf_steps": [-1, 2.5],
    "sdf_lr": [0, -1e-4, math.nan, math.inf, "1e-4"], "sdf_samples": [0], "deform_steps": [-1],
    "deform_lr": [0, math.nan], "surface_patches": [-1], "handle_patches": [-1], "space_patches": [-1],
    "patch_points": [3, False], "patch_radius": [0, -0.1], "projections": [-1], "level_threshold": [0, math.inf],
    "centres": ["box", 1], "arap_weight": [-1, math.nan, True], "handle_weight": [0],
    "reference_weights": ["yes", 1], "lr_milestones": [[5, 3], [0, 5], 7, [1.5], [True]], "lr_gamma": [0, -0.5],
}


def test_every_field_has_a_bad_value_case():
    assert sorted(BAD) == sorted(FIELDS)


@pytest.mark.parametrize("name, value", [(k, v) for k, vs in BAD.items() for v in vs])
def test_a_bad_value_of_each_field_is_refused_naming_the_field(name, value):
    """``skip=3`` is bad with the cpu preset's 4 layers (at most layers - 2)."""
    with pytest.raises(SShaDeError, match=rf"^Implicit-ARAP: (unknown )?{name}\b"):
        ImplicitARAPParams(**{name: value})


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_a_field_left_none_takes_its_presets_value(preset):
    p = ImplicitARAPParams(preset=preset)
    assert {k: getattr(p, k) for k in SETTINGS} == PRESETS[preset]
    assert None not in p.as_dict().values() and list(p.as_dict()) == FIELDS
    assert p.replace(arap_weight=None, layers=3, skip=0).arap_weight == PRESETS[preset]["arap_weight"]


def test_values_are_normalised_and_the_object_frozen():
    p = ImplicitARAPParams(arap_weight=0, sdf_lr=1, lr_milestones=[3, 9], reference_weights=True)
    assert (p.arap_weight, p.sdf_lr, p.lr_milestones, p.reference_weights) == (0.0, 1.0, (3, 9), True)
    assert type(p.arap_weight) is float and type(p.lr_milestones) is tuple
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.seed = 3
    assert hash(p) == hash(ImplicitARAPParams(arap_weight=0.0, sdf_lr=1.0, lr_milestones=(3, 9),
                                              reference_weights=True))


def test_overrides_over_an_object_or_a_mapping_equal_the_object_built_at_once():
    kw = {"preset": "cpu_soft", "seed": 3, "arap_weight": 50.0, "lr_milestones": (10, 20), "device": "cpu"}
    p = ImplicitARAPParams(**kw)
    assert implicit_arap_params(**kw) == p and implicit_arap_params(kw) == p
    assert implicit_arap_params(ImplicitARAPParams(preset="cpu_soft"), **{k: v for k, v in kw.items()}) == p
    assert implicit_arap_params({"preset": "cpu_soft", "seed": 3}, arap_weight=50, lr_milestones=[10, 20],
                                device="cpu") == p
    assert implicit_arap_params(p) is p and implicit_arap_params() == ImplicitARAPParams()
    assert p.replace(seed=4) == dataclasses.replace(p, seed=4) and p.replace(seed=4).seed == 4


def test_another_preset_over_an_object_an_unknown_name_and_a_wrong_type_are_refused():
    p = ImplicitARAPParams(preset="paper")
    assert implicit_arap_params(p, preset="paper") == p  # the same preset: nothing to mix
    with pytest.raises(SShaDeError, match="preset 'cpu' over parameters of preset 'paper'"):
        implicit_arap_params(p, preset="cpu")
    assert implicit_arap_params({"preset": "paper"}, preset="cpu") == ImplicitARAPParams()  # a mapping: no values yet
    with pytest.raises(SShaDeError, match=r"no parameter 'arap_wieght' \(its parameters: preset, device, seed, "):
        implicit_arap_params(arap_wieght=1.0)
    with pytest.raises(SShaDeError, match="no parameter 'n_low'"):
        p.replace(n_low=6000)
    with pytest.raises(SShaDeError, match="params must be ImplicitARAPParams or a mapping of its fields, got list"):
        implicit_arap_params([("seed", 1)])


def test_each_field_is_documented_once_in_the_class_docstring():
    doc = ImplicitARAPParams.__doc__
    for name in FIELDS:
        assert len(re.findall(rf"^    {name} : ", doc, re.M)) == 1, name
    assert len(re.findall(r"^    \w+ : ", doc, re.M)) == len(FIELDS)


def test_the_method_files_keys_are_the_fields_at_their_defaults():
    """conf/method/Implicit-ARAP.yaml: every key but ``_target_`` and the evaluator's
    (:data:`harness.method_registry.META_KEYS`) is a field, every field a key; its values
    build the default object (the cpu preset)."""
    keys = [k for k in OmegaConf.load(ROOT / "conf" / "method" / "Implicit-ARAP.yaml") if k not in META_KEYS]
    assert sorted(keys) == sorted(["_target_", *FIELDS])
    spec = file_spec("Implicit-ARAP")
    assert implicit_arap_params({k: v for k, v in spec.items() if k != "_target_"}) == ImplicitARAPParams()
    assert {f.name: f.default for f in dataclasses.fields(ImplicitARAPParams)} == \
        {k: v for k, v in spec.items() if k != "_target_"}

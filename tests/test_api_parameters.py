"""SShaDe's API states each parameter once: at most 10 parameters per public function of
sshade/, harness/, baselines/, defaust/ and eval/ (a dataclass's generated ``__init__``, a
record of named fields, aside), SShaDe's own as one :class:`sshade.params.SShaDeParams`
plus keyword overrides, listed in help(), the ARAP solvers' as one
:class:`sshade.arap.ArapOptions` (tests/test_arap_options.py), Implicit-ARAP's as one
:class:`baselines.implicit_arap.ImplicitARAPParams` (tests/test_implicit_arap_params.py),
a mesh image's look as one :class:`eval.present.render_style.RenderStyle`
(tests/test_render_style.py). A public numba kernel counts as a function.
"""
from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import re

import numpy as np
import pytest

from sshade import SShaDe, SShaDeError, check_params, deform, prepare
from sshade.arap.problems import twisted_bar
from sshade.isometric import isometric_transfer, pose_transfer
from sshade.params import SShaDeParams
from sshade.pipeline import deform_once


def _public_callables(package: str):
    for info in pkgutil.walk_packages(importlib.import_module(package).__path__, f"{package}."):
        if info.name.endswith("__main__"):
            continue
        mod = importlib.import_module(info.name)
        for name in getattr(mod, "__all__", None) or [n for n in vars(mod) if not n.startswith("_")]:
            obj = getattr(mod, name, None)
            if getattr(obj, "__module__", None) != mod.__name__:
                continue
            obj = getattr(obj, "py_func", obj)  # a numba kernel: its Python function
            if inspect.isfunction(obj):
                yield f"{mod.__name__}.{name}", obj
            elif inspect.isclass(obj):
                for k, v in vars(obj).items():
                    generated = k == "__init__" and dataclasses.is_dataclass(obj)
                    if inspect.isfunction(v) and (not k.startswith("_") or k == "__init__") and not generated:
                        yield f"{mod.__name__}.{name}.{k}", v


@pytest.mark.parametrize("package", ["sshade", "harness", "baselines", "defaust", "eval"])
def test_no_public_function_takes_more_than_10_parameters(package):
    wide = {}
    for name, fn in _public_callables(package):
        n = len([p for p in inspect.signature(fn).parameters if p not in ("self", "cls")])
        if n > 10:
            wide[name] = n
    assert wide == {}


@pytest.mark.parametrize("fn", [deform, prepare, isometric_transfer, pose_transfer, deform_once, SShaDe])
def test_each_parameter_is_stated_once_in_sshade_params_and_listed_in_help(fn):
    """The entry points take ``params`` and keyword overrides; deform's help lists every
    field of SShaDeParams with its default (the text is SShaDeParams' own)."""
    sig = inspect.signature(vars(fn)["__init__"] if inspect.isclass(fn) else fn)
    assert "params" in sig.parameters and any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values())
    if fn is SShaDe:  # its signature, for introspection (a plug-in builder asks whether `name` is one), spells them out
        shown = inspect.signature(SShaDe).parameters
        assert {f.name: f.default for f in dataclasses.fields(SShaDeParams)} == \
            {k: v.default for k, v in shown.items() if k != "params"}
    if fn is deform:
        for f in dataclasses.fields(SShaDeParams):
            assert re.search(rf"^    (\w+, )*{f.name}(, \w+)* : ", fn.__doc__, re.M), f.name
        assert "{sshade_params}" not in fn.__doc__


@pytest.fixture(scope="module")
def bar():
    return twisted_bar(45.0, h=0.25)


def test_params_object_mapping_and_keywords_give_bit_identical_results(bar):
    """The same parameters as an SShaDeParams, a plain mapping, keywords, or the method
    object: the same bits (one code path after the check)."""
    V, F, h, T = bar
    kw = {"n_low": 120, "n_samplings": 2, "seed": 7, "workers": 1}
    p = check_params(**kw)
    a = deform(V, F, h, T, **kw)
    assert np.array_equal(a, deform(V, F, h, T, p))
    assert np.array_equal(a, deform(V, F, h, T, dict(kw)))
    assert np.array_equal(a, deform(V, F, h, T, check_params(seed=7), n_low=120, n_samplings=2, workers=1))
    assert np.array_equal(a, SShaDe(p).deform(V, F, h, T))
    with prepare(V, F, h, p) as prep:
        assert np.array_equal(prep.solve(T), a)


def test_defaults_live_in_sshade_params_and_the_transfers_own_k(bar):
    assert check_params() == SShaDeParams()  # noqa: SIM300 - the dataclass's defaults are the reference
    assert dict(check_params()) == {f.name: f.default for f in dataclasses.fields(SShaDeParams)}
    V, F, _, _ = bar
    _, info = isometric_transfer(V, F, V, n_low=60, workers=1)
    assert info["n_samplings"] == 10  # the transfers' default (the paper's k for §4.2-4.3)


@pytest.mark.parametrize("call, why", [
    (lambda V, F, h, T: deform(V, F, h, T, n_lo=10), "SShaDe: no parameter 'n_lo'"),
    (lambda V, F, h, T: deform(V, F, h, T, [1, 2]), "params must be SShaDeParams or a mapping"),
    (lambda V, F, h, T: isometric_transfer(V, F, V, tol=1e-3), "isometric_transfer: no parameter 'tol'"),
    (lambda V, F, h, T: pose_transfer(V, F, V, V, warm_start=False), "pose_transfer: no parameter 'warm_start'"),
    (lambda V, F, h, T: deform_once(V, F, h, T, n_samplings=3), "deform_once: no parameter 'n_samplings'"),
])
def test_a_parameter_a_function_does_not_use_is_refused_before_any_work(bar, call, why):
    with pytest.raises(SShaDeError, match=why):
        call(*bar)

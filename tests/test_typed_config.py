"""The evaluator's config typed at the door (eval/config_schema.py, eval/config_check.py):
Hydra's composition refuses a wrong type and an unknown key with its own message (one
``error:`` line, exit 2, no folder made), the schemas hold exactly the keys of the files
they type (so the composed config, and ``run.json``, are those of the files), and below the
commands no function of eval/ takes the raw config."""
from __future__ import annotations

import ast
import dataclasses
import subprocess
import sys
import typing
from pathlib import Path

import pytest
from omegaconf import OmegaConf

from eval.app import CONF_DIR
from eval.config_schema import TopSchema, dataset_schemas, method_schemas, section_schemas
from harness.command import config_error_types, hydra_message
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env

CI = ["experiment=ci", "dataset.root=/nonexistent/faust_reg"]


def _compose(overrides):
    from hydra import compose, initialize_config_dir
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=list(overrides))


def _keys(cls) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)]


def _sections(cls) -> dict:
    """The fields of schema ``cls`` that are schemas themselves: name -> class."""
    return {k: t for k, t in typing.get_type_hints(cls).items() if dataclasses.is_dataclass(t)}


def _yaml(path) -> dict:
    """A config file's own keys (its defaults list left out), unresolved."""
    d = OmegaConf.to_container(OmegaConf.load(path), resolve=False)
    d.pop("defaults", None)
    return d


# ----------------------------------------------------------------------------- refused by Hydra
@pytest.mark.parametrize("overrides, words", [
    (["sshade.n_samplings=abc"], ["sshade.n_samplings=abc", "could not be converted to Integer"]),
    (["dataset.limit=abc"], ["dataset.limit=abc", "Integer"]),
    (["timeout_s=soon"], ["timeout_s=soon", "Float"]),
    (["resume=maybe"], ["resume=maybe", "not a valid bool"]),
    (["method.ARAP.order=abc"], ["method.ARAP.order=abc", "Integer"]),
    (["experiment=tosca", "tosca.min_vertices=abc"], ["tosca.min_vertices", "Integer"]),
    (["experiment=scaling", "scaling.sizes=[1,x]"], ["scaling.sizes", "Integer"]),
    (["dataset.nonsense=1"], ["dataset.nonsense", "not in 'FaustOptions'"]),
    (["method.Elastic.nonsense=1"], ["method.Elastic.nonsense", "not in"]),
    (["experiment=tosca", "tosca.nope=1"], ["tosca.nope", "not in 'ToscaConfig'"]),
    (["report.nope=1"], ["report.nope", "not in 'ReportOptions'"]),
])
def test_composition_refuses_a_wrong_type_or_an_unknown_key(overrides, words):
    with pytest.raises(config_error_types()) as e:
        _compose([*CI, *overrides])
    msg = hydra_message(e.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


def test_the_command_line_refuses_them_in_one_line_before_any_work(tmp_path):
    cases = [("sshade.n_samplings=abc", "could not be converted to Integer"),
             ("dataset.nonsense=1", "Key 'nonsense' not in 'FaustOptions'")]
    procs = [subprocess.Popen([sys.executable, "-m", "eval", *CI, f"out_dir={tmp_path / f'run{i}'}", ov],
                              cwd=tmp_path, env=subprocess_env(), text=True, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE) for i, (ov, _) in enumerate(cases)]
    for (ov, words), p in zip(cases, procs):
        _, err = p.communicate(timeout=180)
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert p.returncode == 2, err[-2000:]
        assert len(lines) == 1 and lines[0].startswith("error: ") and ov.split("=")[0] in lines[0], err[-2000:]
        assert words in lines[0] and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []  # no run folder, no outputs/


def test_every_kind_of_value_still_composes():
    """The values the files and the docs use compose: one name for ``methods``, a plug-in
    mapping, an integer ``jobs``, ``sshade.n_low`` as a number or ``auto``, the optional
    ``sshade`` stopping keys, a ``compare_with`` folder."""
    cfg = _compose([*CI, "methods=[SShaDe,{_target_:tests.plugin_example.MyMethod,name:Mine}]", "jobs=2",
                    "sshade.n_low=500", "+sshade.tol=1e-3", "compare_with=results/defaust", "dataset.subjects=3",
                    "method_cases={SShaDe: per_pose}"])
    assert (cfg.jobs, cfg.sshade.n_low, cfg.sshade.tol, cfg.dataset.subjects) == (2, 500, 1e-3, 3)
    assert _compose([*CI, "methods=ARAP"]).methods == "ARAP"


# ----------------------------------------------------------------------------- the schemas and the files
def test_the_top_schema_holds_the_keys_of_config_yaml_in_their_order():
    top = _yaml(ROOT / "conf" / "config.yaml")
    for k in ("hydra", "method"):  # Hydra's own; the method files, typed each by its own schema
        top.pop(k, None)
    assert _keys(TopSchema) == [*top, "dataset", "experiment"]
    for k, cls in _sections(TopSchema).items():
        if k in top:
            assert _keys(cls) == list(top[k]), k


def test_each_dataset_and_experiment_section_schema_holds_its_files_keys():
    assert sorted(dataset_schemas()) == ["defaust", "faust", "shapes"]
    for name, cls in dataset_schemas().items():
        d = _yaml(ROOT / "conf" / "dataset" / f"{name}.yaml")
        assert _keys(cls) == list(d), name
        assert (ROOT / "conf" / "dataset" / f"{name}.yaml").read_text().count(f"/schema/dataset/{name}@_here_") == 1
    for name, cls in section_schemas().items():
        d = _yaml(ROOT / "conf" / "experiment" / f"{name}.yaml")[name]
        assert _keys(cls) == list(d), name
        for k, sub in _sections(cls).items():
            assert _keys(sub) == list(d[k]), f"{name}.{k}"


def test_every_method_file_is_typed_by_its_schema():
    schemas = method_schemas()
    text = (ROOT / "conf" / "config.yaml").read_text()
    for name, cls in schemas.items():
        assert _keys(cls) == list(_yaml(ROOT / "conf" / "method" / f"{name}.yaml")), name
        key = name.replace("+", "_")
        assert f"- schema/method@method.{key}: {name}\n  - method@method.{key}: {name}\n" in text, name


# ----------------------------------------------------------------------------- below the door
#: The functions of eval/ that take the composed config: the commands and the door. Every
#: other function takes the typed objects it reads (eval/run/spec.py).
ENTRIES = {
    "eval/app.py": {"run_experiment", "_pin_out_dir", "_refuse_fresh_resume", "_main"},
    "eval/config_check.py": {"check_config", "check_values", "_check_sshade", "_output",
                             "method_definition", "plain"},
    # python -m eval.sweeps: a sweep job (Hydra's task function), the sweep folder, Hydra's callbacks
    "eval/sweeps/sweep_command.py": {"sweep_job", "sweep_points", "start_manifest", "claim_sweep_dir",
                                     "on_multirun_start", "on_job_end", "on_multirun_end"},
}
CONFIG_NAMES = {"cfg", "config"}


def _takes_the_config(fn) -> bool:
    """Whether function ``fn`` (an AST node) has a parameter named ``cfg`` / ``config`` or
    annotated with OmegaConf's ``DictConfig``."""
    a = fn.args
    params = [*a.posonlyargs, *a.args, *a.kwonlyargs, *(p for p in (a.vararg, a.kwarg) if p is not None)]
    return any(p.arg in CONFIG_NAMES or (p.annotation is not None and "DictConfig" in ast.unparse(p.annotation))
               for p in params)


def _config_takers() -> dict[str, set[str]]:
    """``{module path: names of its functions that take the config}`` over eval/."""
    out: dict[str, set[str]] = {}
    for path in sorted((ROOT / "eval").rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        names = {n.name for n in ast.walk(tree)
                 if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and _takes_the_config(n)}
        if names:
            out[path.relative_to(ROOT).as_posix()] = names
    return out


def test_no_function_below_the_entries_takes_the_config():
    found = _config_takers()
    below = {m: sorted(names - ENTRIES.get(m, set())) for m, names in found.items() if names - ENTRIES.get(m, set())}
    assert not below, f"functions below the entries that take the config (take its typed objects): {below}"
    assert found == ENTRIES, "the entries changed: update ENTRIES (and keep the rest typed)"


def test_the_walk_finds_a_config_parameter():
    """The check itself: each way of taking the config is seen."""
    for src in ("def f(cfg): pass", "def f(x, *, config=None): pass", "def f(c: DictConfig): pass",
                "def f(c: 'omegaconf.DictConfig | None'): pass", "class A:\n    def m(self, cfg): pass"):
        fn = next(n for n in ast.walk(ast.parse(src)) if isinstance(n, ast.FunctionDef))
        assert _takes_the_config(fn), src
    assert not _takes_the_config(ast.parse("def f(spec, section): pass").body[0])


def test_the_three_defaults_that_disagreed_are_the_schemas():
    """scaling.repeat (3 in the schema and the YAML, 1 in the reader), report.view_cases (2,
    0 in ReportOptions) and convergence.libigl (read, in neither the schema nor the YAML):
    the sections' options are now their schemas' own instances, so a key left out takes the
    schema's default and no other."""
    from eval.config_schema import typed_section
    from eval.experiments.convergence import ConvergenceConfig
    from eval.experiments.scaling.scaling_experiment import ScalingConfig
    from eval.run.spec import ReportOptions
    opts = typed_section("scaling", {"base_mesh": "m.obj", "sizes": [1000]})  # every other key left to its default
    assert type(opts) is ScalingConfig and opts.repeat == 3
    for f in dataclasses.fields(ScalingConfig):
        if f.name not in ("meshes", "sizes", "base_mesh", "first_call_timeout_s", "elastic_budget_s"):
            assert getattr(opts, f.name) == f.default, f.name
    assert ReportOptions().view_cases == 2 and ReportOptions.view_cases == 2
    assert ConvergenceConfig.libigl is True
    yaml = OmegaConf.load(Path(CONF_DIR) / "experiment" / "convergence.yaml")
    assert yaml.convergence.libigl is True


#: the experiment sections' schemas and the modules that own and register them
SECTION_OWNERS = {"animation": "eval/experiments/animation.py", "convergence": "eval/experiments/convergence.py",
                  "pose_transfer": "eval/experiments/pose_transfer.py", "score": "eval/exchange/scored.py",
                  "scaling": "eval/experiments/scaling/scaling_experiment.py", "tosca": "eval/experiments/tosca.py"}


def test_each_section_is_typed_once_by_the_module_that_reads_it():
    """One dataclass per experiment section, in its owner module (registered there), and no
    second dataclass or reader of the section anywhere in eval/ (no ``*Options`` class or
    ``*_options`` function of an experiment kind)."""
    schemas = section_schemas()
    assert sorted(schemas) == sorted(SECTION_OWNERS)
    for name, cls in schemas.items():
        assert Path(sys.modules[cls.__module__].__file__).resolve() == (ROOT / SECTION_OWNERS[name]).resolve(), name
    text = "\n".join(p.read_text() for p in sorted((ROOT / "eval").rglob("*.py")))
    for name in schemas:
        camel = "".join(w.title() for w in name.split("_"))
        assert f"class {camel}Options" not in text and f"def {name}_options(" not in text, name


def test_a_section_made_at_the_door_is_its_schemas_instance_checked_and_normalised():
    from eval.config_check import check_config
    from eval.experiments.convergence import ConvergenceConfig
    from eval.experiments.tosca import ToscaConfig
    spec = check_config(_compose(["experiment=tosca", "tosca.poses=[1,2]", "tosca.classes=cat"]))
    opts = spec.experiment.options
    assert type(opts) is ToscaConfig and opts.poses == (1, 2) and opts.classes == ("cat",) and opts.min_vertices == 5000
    spec = check_config(_compose(["experiment=convergence", "sshade.n_samplings=7"]))
    opts = spec.experiment.options
    assert type(opts) is ConvergenceConfig and opts.sshade.refine_k == 7 and opts.cases == ("plane", "dataset")
    for overrides, words in ((["experiment=tosca", "tosca.min_vertices=-1"], "tosca.min_vertices"),
                             (["experiment=convergence", "convergence.cases=[plane,cube]"], "unknown case 'cube'"),
                             (["experiment=tosca", "tosca.root=null"], "tosca.root is not set: pass tosca.root=DIR"),
                             (["experiment=scaling", "scaling.sizes=[2]"], "scaling.sizes")):
        with pytest.raises(SShaDeError) as e:
            check_config(_compose(overrides))
        assert words in str(e.value) and "\n" not in str(e.value), (overrides, str(e.value))


def test_conf_config_yaml_restates_no_default_differently():
    """conf/config.yaml's sections hold every key (for its comments and ``--cfg job``): each
    value there is its type's default, so the two cannot disagree (the type's is what a
    config without the key, e.g. the Python API's, gets); an interpolation is the YAML's alone."""
    top = _yaml(ROOT / "conf" / "config.yaml")
    for name, cls in _sections(TopSchema).items():
        if name not in top or name == "experiment":
            continue
        for f in dataclasses.fields(cls):
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            value = top[name][f.name]
            if not (isinstance(value, str) and value.startswith("${")):
                assert value == default, f"{name}.{f.name}: {value!r} vs {default!r}"


@pytest.mark.parametrize("cfg, words", [
    ({"report": {"nope": 1}}, "report.nope: unknown key"),
    ({"report": 5}, "report must be a section of keys, got 5"),
    ({"reference": {"max_iter": 0}}, "reference.max_iter"),
    ({"figures": {"max_cases": -1}}, "figures.max_cases"),
    ({"report": {"max_faces": "many"}}, "report.max_faces"),
])
def test_a_plain_mapping_config_is_refused_in_one_line_naming_the_key(cfg, words):
    """The Python API's plain mapping meets the same typed sections as a composed config:
    an unknown key, a section that is not a mapping or a bad value is one SShaDeError."""
    from eval.config_check import check_config
    with pytest.raises(SShaDeError) as e:
        check_config({"methods": ["ARAP"], **cfg})
    assert words in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_tosca_classes_must_be_names():
    from eval.config_check import check_config
    with pytest.raises(SShaDeError, match="tosca.classes must be a class name or a list of names"):
        check_config(_compose(["experiment=tosca", "tosca.classes=[1,2]"]))

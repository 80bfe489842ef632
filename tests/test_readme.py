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

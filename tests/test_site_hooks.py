"""docs/site_hooks.py: the documentation site's API reference is complete (every name of
each package's ``__all__`` has an entry on its page), a name left out is named, and the
leaderboard page's links into results/ become repository paths."""
from __future__ import annotations

import importlib.util
import shutil

import pytest

from .conftest import ROOT
from .optional import optional_import

pytestmark = pytest.mark.docs


def _hooks():
    optional_import("mkdocs")
    spec = importlib.util.spec_from_file_location("site_hooks", ROOT / "docs" / "site_hooks.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_api_reference_names_every_public_name_of_the_four_packages():
    assert _hooks().missing_api_names(ROOT / "docs") == []


def test_a_public_name_left_out_of_the_api_reference_is_named(tmp_path):
    hooks = _hooks()
    shutil.copytree(ROOT / "docs" / "api", tmp_path / "api")
    page = tmp_path / "api" / "sshade.md"
    page.write_text(page.read_text(encoding="utf-8").replace("::: sshade.prepared.prepare\n", ""), encoding="utf-8")
    assert hooks.missing_api_names(tmp_path) == ["sshade.prepare (api/sshade.md)"]


def test_each_public_name_is_listed_as_imported_and_linked_to_its_entry():
    text = (ROOT / "docs" / "api" / "sshade.md").read_text(encoding="utf-8")
    table = _hooks().public_names_table(text, ("sshade",))
    assert "| `sshade.deform` | [`sshade.pipeline.deform`](#sshade.pipeline.deform) |" in table
    import sshade
    assert len(table.splitlines()) == 2 + len(sshade.__all__)


def test_links_into_results_become_repository_paths():
    text = "[faust/](faust/index.html) and [the paper](https://example.org) and [top](#rank)"
    out = _hooks()._repository_links(text, "results")
    assert out == "faust/ (`results/faust/index.html`) and [the paper](https://example.org) and [top](#rank)"

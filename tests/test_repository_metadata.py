"""The files a person reads before using or citing the repository: LICENSE states the
licence pyproject.toml declares, CITATION.cff (Citation File Format 1.2.0) parses as YAML,
names this version and license, and cites the SShaDe paper as its preferred citation."""
from __future__ import annotations

import re
import tomllib

import pytest
import yaml

from .conftest import ROOT, SHARED_DATA


def _pyproject() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _cff() -> dict:
    return yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))


def test_license_file_states_the_declared_licence():
    declared = _pyproject()["license"]["text"]
    text = (ROOT / "LICENSE").read_text()
    assert declared == "MIT" and text.startswith("MIT License")
    assert "Permission is hereby granted, free of charge" in text


def test_citation_cff_matches_pyproject_version_and_licence():
    cff, proj = _cff(), _pyproject()
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert {"message", "title", "authors"} <= set(cff)
    assert str(cff["version"]) == proj["version"]
    assert cff["license"] == proj["license"]["text"]


def test_citation_cff_prefers_the_sshade_paper_with_its_authors():
    ref = _cff()["preferred-citation"]
    assert ref["type"] == "article"
    assert ref["title"] == "SShaDe: scalable shape deformation via local representations"
    assert [a["family-names"] for a in ref["authors"]] == ["Maggioli", "Baieri", "Lähner", "Melzi"]
    for a in ref["authors"]:
        assert re.fullmatch(r"https://orcid\.org/\d{4}-\d{4}-\d{4}-\d{3}[\dX]", a["orcid"])


def test_citation_cff_title_and_orcids_are_the_papers():
    tex = SHARED_DATA.parent / "seeds" / "sshade.tex"
    if not tex.is_file():
        pytest.skip(f"{tex} not present")
    src = tex.read_text(encoding="utf-8")
    ref = _cff()["preferred-citation"]
    m = re.search(r"\\title\[[^\]]*\]%?\s*\{([^}]*)\}", src)
    assert m and m.group(1).strip() == ref["title"]
    orcids = re.findall(r"\\orcid\{([0-9X-]+)\}", src)
    assert [a["orcid"].rsplit("/", 1)[1] for a in ref["authors"]] == orcids

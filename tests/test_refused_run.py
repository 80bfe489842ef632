"""A run refused for a bad config value leaves no output behind: no
dated folder, no parents made for it, no ``.hydra/`` or empty ``eval.log`` in a folder
the user gave; a user's own files stay."""
from __future__ import annotations

import subprocess
import sys

import pytest

from .conftest import subprocess_env


def _eval(cwd, *overrides) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={cwd}", *overrides],
                          cwd=cwd, env=subprocess_env(), capture_output=True, text=True, timeout=300)


def _refused(r, what: str) -> None:
    assert r.returncode == 2, r.stderr[-2000:]
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("error: ") and what in last, r.stderr[-2000:]
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("bad, what", [("methods=[Nope]", "unknown method 'Nope'"),
                                       ("timeout_s=-1", "timeout_s must be a positive number"),
                                       ("method.SShaDe.n_low=abc", "n_low must be an integer")])
def test_default_dated_folder_is_not_left(tmp_path, bad, what):
    """Refused after the claim of outputs/<experiment>/<date_time>: no outputs/ at all."""
    r = _eval(tmp_path, bad)
    _refused(r, what)
    assert not (tmp_path / "outputs").exists(), sorted(p.name for p in (tmp_path / "outputs").rglob("*"))


@pytest.mark.slow
def test_given_folders_are_left_as_they_were(tmp_path):
    """out_dir=a/b (new, with a new parent): neither remains; an existing empty folder
    stays empty; a folder with a user's file (overwrite=true) keeps only that file."""
    _refused(_eval(tmp_path, "methods=[Nope]", "out_dir=a/b"), "unknown method")
    assert not (tmp_path / "a").exists()
    (tmp_path / "empty").mkdir()
    _refused(_eval(tmp_path, "timeout_s=-1", "out_dir=empty"), "timeout_s")
    assert list((tmp_path / "empty").iterdir()) == []
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    _refused(_eval(tmp_path, "timeout_s=-1", "out_dir=mine", "overwrite=true"), "timeout_s")
    names = {p.name for p in mine.iterdir()}
    assert "notes.txt" in names and not names & {".hydra", "eval.log", "run.json"}, names
    assert (mine / "notes.txt").read_text() == "keep me"

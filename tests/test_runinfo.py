"""eval/run/runinfo.py: what a run records of the code that made it."""
from __future__ import annotations

import subprocess

from eval.run.runinfo import git_info


def _git(repo, *args):
    subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)


def test_a_changed_result_file_is_not_dirty_code_but_a_changed_source_is(tmp_path):
    repo = tmp_path / "repo"
    (repo / "results" / "faust").mkdir(parents=True)
    (repo / "code.py").write_text("x = 1\n")
    (repo / "results" / "faust" / "table.md").write_text("| a |\n")
    _git(repo, "init", "-q")
    _git(repo, "add", ".")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "c")
    assert git_info(repo)["dirty"] is False
    (repo / "results" / "faust" / "table.md").write_text("| b |\n")  # a run rewrote its results
    (repo / "new_output.txt").write_text("untracked\n")
    assert git_info(repo)["dirty"] is False and git_info(repo)["modified"] == []
    (repo / "code.py").write_text("x = 2\n")
    info = git_info(repo)
    assert info["dirty"] is True and info["modified"] == ["code.py"]

"""eval/run/stale_runs.py: a folder run whole is held to the code its run executes, at
the commit it names.

On a copy of HEAD's sources: a run.json of experiment ``convergence`` and a benchmark's
table.md made at HEAD are current; an edit of a module the run executes (its experiment,
SShaDe's pipeline, a probe's baseline named only in ``CODE_ROOTS``, the script itself)
makes it stale naming that module; an edit of presentation code leaves it current; a
dirty, unknown-commit, unknown-kind or unreadable origin is stale with why.
"""
from __future__ import annotations

import json
import shutil
import subprocess

import pytest

from eval.experiments import find_experiment
from eval.run.stale_rows import CommitTrees
from eval.run.stale_runs import run_origin, whole_run_folders, whole_run_state

from .conftest import ROOT, edit_syntax_tree


def _head() -> str:
    r = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True, check=False)
    if r.returncode != 0:
        pytest.skip("no git history here")
    return r.stdout.strip()


@pytest.fixture
def head_tree(tmp_path):
    """``(trees, commit, root)``: HEAD's sources copied to a folder of their own (the
    checkout the runs are held to, editable) and the commit trees of this repository."""
    commit = _head()
    with CommitTrees() as trees:
        src = trees.tree(commit)
        if src is None:
            pytest.skip("git cannot archive HEAD here")
        root = tmp_path / "checkout"
        shutil.copytree(src, root)
        yield trees, commit, root


def _run_json(folder, commit, kind="convergence", dirty=False):
    folder.mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps({"git": {"commit": commit, "dirty": dirty, "modified": []},
                                                 "config": {"experiment": {"kind": kind}}}))
    return folder


def _made_by(folder, commit, script="benchmarks/frames.py", dirty="False"):
    folder.mkdir(parents=True)
    (folder / "table.md").write_text(f"| a |\n|---|\n\nMade by `python {script} --frames 60` at git commit "
                                     f"{commit} (dirty: {dirty}), seed 0, on 2 cores.\n")
    return folder


def test_an_experiment_run_is_current_until_a_module_it_executes_changes(tmp_path, head_tree):
    trees, commit, root = head_tree
    run = _run_json(tmp_path / "results" / "convergence", commit)
    assert not whole_run_state(run, trees, find_experiment, str(root)).stale
    edit_syntax_tree(root / "eval" / "present" / "table_markup.py")  # presentation: no part of the run's numbers
    assert not whole_run_state(run, trees, find_experiment, str(root)).stale
    edit_syntax_tree(root / "sshade" / "pipeline.py")
    st = whole_run_state(run, trees, find_experiment, str(root))
    assert st.stale and st.why == f"sshade.pipeline changed since {commit[:7]}"


def test_a_benchmark_run_is_held_to_its_script_and_its_imports(tmp_path, head_tree):
    trees, commit, root = head_tree
    frames = _made_by(tmp_path / "frames", commit)
    assert run_origin(frames).script == "benchmarks/frames.py"
    assert not whole_run_state(frames, trees, find_experiment, str(root)).stale
    edit_syntax_tree(root / "benchmarks" / "frames.py")
    st = whole_run_state(frames, trees, find_experiment, str(root))
    assert st.stale and st.why == f"benchmarks/frames.py changed since {commit[:7]}"


def test_a_probe_run_in_another_process_is_held_through_code_roots(tmp_path, head_tree):
    """cold_start's probes run the baselines in processes of their own (no import of the
    script names them): its ``CODE_ROOTS`` make an edit of their module a stale run."""
    trees, commit, root = head_tree
    cold = _made_by(tmp_path / "cold_start", commit, script="benchmarks/cold_start.py")
    assert not whole_run_state(cold, trees, find_experiment, str(root)).stale
    edit_syntax_tree(root / "baselines" / "arap_sr.py")
    st = whole_run_state(cold, trees, find_experiment, str(root))
    assert st.stale and "baselines.arap_sr changed" in st.why


@pytest.mark.parametrize("make, why", [
    (lambda d, c: _run_json(d, c, dirty=True), "uncommitted changes"),
    (lambda d, c: _run_json(d, "0" * 40), "is not in this clone"),
    (lambda d, c: _run_json(d, c, kind="no_such_kind"), "experiment kind 'no_such_kind' is not one"),
    (lambda d, c: _made_by(d, c, dirty="None"), "uncommitted changes (or of unknown state)"),
    (lambda d, c: _made_by(d, c, script="benchmarks/gone.py"), "its script cannot be read"),
    (lambda d, c: (d.mkdir(parents=True), (d / "run.json").write_text("{not json")), "no run.json with its commit"),
])
def test_an_origin_that_cannot_be_verified_is_stale_with_why(tmp_path, head_tree, make, why):
    trees, commit, root = head_tree
    make(tmp_path / "run", commit)
    st = whole_run_state(tmp_path / "run", trees, find_experiment, str(root))
    assert st.stale and why in st.why


def test_whole_run_folders_are_those_without_stored_rows_and_no_link(tmp_path):
    _run_json(tmp_path / "a", "0" * 40)
    _made_by(tmp_path / "b", "0" * 40)
    (_run_json(tmp_path / "rows", "0" * 40) / "runs").mkdir()  # held row by row (eval.run.stale_rows)
    (tmp_path / "empty").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "a", target_is_directory=True)
    assert whole_run_folders(tmp_path) == [tmp_path / "a", tmp_path / "b"]


def test_committed_whole_runs_are_current_or_marked_pending_at_this_checkout():
    """Every folder of results/ run whole was made by this checkout's code for what it
    runs, or is marked pending in its table.md with the commit that made it
    (``python -m eval.reproduce --check``: the rule for results/ covers them too)."""
    from eval.run.pending_rows import marked_run, short_commit
    shallow = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--is-shallow-repository"], capture_output=True,
                             text=True, check=False).stdout.strip()
    if shallow != "false":
        pytest.skip("a shallow clone (or no git): the commits that made results/ are not here to compare")
    folders = whole_run_folders(ROOT / "results")
    with CommitTrees() as trees:
        stale = {f.name: st.why for f in folders if (st := whole_run_state(f, trees, find_experiment)).stale
                 and marked_run(f) != short_commit(st.origin.commit if st.origin else None)}
    assert not stale
    assert {"convergence", "scaling", "frames", "cold_start"} <= {f.name for f in folders}

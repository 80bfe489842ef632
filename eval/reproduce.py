"""Regenerate every table and figure under ``results/`` with one command (paper §4).

    python -m eval.reproduce                                   # embedded synthetic DeFAUST only
    python -m eval.reproduce --faust DIR --tosca DIR --shapes DIR --scaling MESH
    python -m eval.reproduce --check [--json]     # which committed rows are stale; no computation
    python -m eval.reproduce --rekey | --retabulate   # re-key old records | rebuild tables from rows
    python -m eval.reproduce --budget 2h [--only STEPS]   # the stale rows that fit; the rest marked pending

Each step runs as its own process (a failure is reported, the others still run) after a plan
of the stored rows reused and stale; table and sweep steps compute only stale and missing rows.
Exit 1 if a step failed (``--check``: a row stale and not marked pending, or a folder run whole stale).
Floor 5 of eval/ (the commands, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from eval.experiments import find_experiment
from eval.report import find_chromium
from eval.run.outdir import REPRODUCE_ENV
from eval.run.pending_rows import STOP_AFTER_ENV, mark_run_pending, marked_pending, marked_run, short_commit
from eval.run.runinfo import REPO_ROOT, machine_info, machine_words
from eval.run.stale_rows import (
    CommitTrees,
    check_folders,
    folder_states,
    record_paths,
    rekey_record,
    row_machines,
    run_folders,
    table_problems,
)
from eval.run.stale_runs import is_whole_run, whole_run_folders, whole_run_state
from harness.command import run_command
from sshade.command_errors import ArgumentParser

#: ARAP-SR's alpha values of the sweep step (Open3D's definition; 0.06 is about the
#: stiffness of 0.01 without the valence, this package's earlier definition)
SR_ALPHAS = "0.001,0.003,0.01,0.03,0.06,0.1"
#: Implicit-ARAP's cpu-preset grid of the sweep steps: the ARAP weight with correct
#: cotangent weights (10: the cpu_soft preset's; 120: the cpu preset's, the reference's
#: mesh default since June 2024; 1000: the reference's number at the paper's time, there
#: with its own weights) and the deformation steps (a stiffer field needs more to reach
#: its handles); docs/methods.md, "Selection rule", reads both sweeps
IA_GRID = ("method.Implicit-ARAP.arap_weight=10,120,1000", "method.Implicit-ARAP.deform_steps=500,1000,1500")
#: where ``--faust`` builds its DeFAUST (git-ignored, beside the default ``data/defaust``)
FAUST_BUILD = "data/defaust_faust"
#: the folder every step writes under (the one command that writes it)
RESULTS = "results"
#: how ``--check`` names a folder run whole (no stored rows: held as one unit)
WHOLE_RUN = "whole run"


def _installed(name: str) -> bool:
    """``name`` is installed (found without importing it); a finder that raises while
    looking for it (a module made unimportable) counts as not installed."""
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, OSError, ValueError):
        return False


def _steps(a) -> list[tuple[str, list[str]]]:
    py = [sys.executable, "-m"]
    # the one command that writes results/: every other run goes to outputs/ by default
    # every method on all 40 DeFAUST cases (`python -m eval`'s default runs the baselines on a
    # per_pose subset, eval/run/subset.py); resume=true: a rerun after a crash continues (eval/run/result_store.py)
    # Implicit-ARAP (the [neural] extra, its cpu preset) where PyTorch is installed, on every case too
    neural = _installed("torch")
    ia = ["methods=[ARAP,Elastic,ARAP-SR,SShaDe,Implicit-ARAP]"] if neural else []
    # the deep references (a minute or more each at 169k vertices, three energies) on the
    # per_pose subset, `python -m eval`'s baseline cases: the check that each converged
    # method lands on its minimiser, not a column over all 40 cases (eval/metrics/reference.py)
    # jobs=1: one run at a time on the whole machine, so that the time columns of results/
    # are each method's own (`python -m eval`'s jobs=auto runs cases side by side)
    s = [("defaust", py + ["eval", "figures.enabled=true", "dataset.baseline_cases=all", "reference.cases=per_pose",
                           "resume=true", "jobs=1", *ia, "out_dir=results/defaust", *a.extra]),
         ("defaust_paper", py + ["eval", "arap.protocol=paper", "dataset.baseline_cases=all",
                                 "reference.cases=per_pose", "resume=true", "jobs=1", "out_dir=results/defaust_paper"]),
         ("convergence", py + ["eval", "experiment=convergence", "out_dir=results/convergence"]),
         # SShaDe prepared once and solved per frame on animated DeFAUST cases (ANNY's frames), beside Elastic
         ("animation", py + ["eval", "experiment=animation", "out_dir=results/animation"]),
         # the sweep steps resume as the table steps do: resume=true keeps each job's folder of
         # the grid and its current rows, each job computes only its stale and missing pairs
         # (eval.sweeps.sweep_command.claim_sweep_dir)
         ("sweep", py + ["eval.sweeps", "-m", "experiment=sweep", "dataset.limit=2", "sshade.n_low=1000,3000,6000",
                         "resume=true", "hydra.sweep.dir=results/sweeps/defaust"]),
         # ARAP-SR's alpha (Open3D's definition) on the per_pose cases (the dataset's baseline_cases)
         ("sweep_arap_sr_alpha", py + ["eval.sweeps", "-m", "methods=[ARAP-SR]", "reference.cases=none", "jobs=1",
                                       f"arap_sr.alpha={SR_ALPHAS}", "resume=true",
                                       "hydra.sweep.dir=results/sweeps/arap_sr_alpha"])]
    if neural:  # Implicit-ARAP's cpu preset, its ARAP weight and step count, on DeFAUST's per_pose cases
        s.append(("sweep_implicit_arap", py + ["eval.sweeps", "-m", "methods=[Implicit-ARAP]", "reference.cases=none",
                                               "jobs=1", *IA_GRID, "resume=true",
                                               "hydra.sweep.dir=results/sweeps/implicit_arap_defaust"]))
    if a.faust and neural:  # the same grid on the 8 FAUST cases
        s.append(("sweep_implicit_arap_faust", py + ["eval.sweeps", "-m", "dataset=faust", f"dataset.root={a.faust}",
                                                     "methods=[Implicit-ARAP]", "reference.cases=none", "jobs=1",
                                                     *IA_GRID, "resume=true",
                                                     "hydra.sweep.dir=results/sweeps/implicit_arap_faust"]))
    if a.faust:
        s.append(("faust", py + ["eval", "dataset=faust", f"dataset.root={a.faust}", "figures.enabled=true",
                                  "resume=true", "jobs=1", *ia[:1], "out_dir=results/faust"]))
        s.append(("pose_transfer", py + ["eval", "experiment=pose_transfer", f"pose_transfer.root={a.faust}",
                                           "figures.enabled=true", "out_dir=results/pose_transfer"]))
        # Table 1 on a DeFAUST built from these FAUST subjects (the paper's source data; built
        # into FAUST_BUILD on first use, only verified after), both protocols, every method on every case
        build = [f"dataset.root={FAUST_BUILD}", "dataset.build.enabled=true",
                 f'dataset.build.overrides=["source=faust","faust.root={a.faust}"]', "dataset.baseline_cases=all",
                 "reference.cases=per_pose", "resume=true", "jobs=1"]
        s.append(("defaust_faust", py + ["eval", *build, "figures.enabled=true", *ia,
                                         "out_dir=results/defaust_faust"]))
        s.append(("defaust_faust_paper", py + ["eval", *build, "arap.protocol=paper",
                                               "out_dir=results/defaust_faust_paper"]))
    if a.tosca:
        s.append(("tosca", py + ["eval", "experiment=tosca", f"tosca.root={a.tosca}", "figures.enabled=true",
                                  "out_dir=results/tosca"]))
        # where the transfer loses accuracy, one factor at a time (anchor, frames, n_low, k, ...)
        s.append(("tosca_factors", [sys.executable, str(Path(__file__).resolve().parents[1] / "benchmarks" /
                                                        "tosca_transfer_factors.py"), a.tosca,
                                    "--out", "results/tosca_factors"]))
    if a.shapes:
        s.append(("shapes", py + ["eval", "experiment=shapes", f"dataset.root={a.shapes}", "resume=true", "jobs=1",
                                   *ia[:1], "out_dir=results/shapes"]))
    if a.scaling:
        # "set": the experiment's default set of meshes (scaling.meshes: a clean one and two
        # hard TOSCA ones, at 200k and 1M vertices); a path: that one mesh instead
        one = [] if a.scaling == "set" else ["scaling.meshes=null", f"scaling.base_mesh={a.scaling}"]
        s.append(("scaling", py + ["eval", "experiment=scaling", *one, "out_dir=results/scaling"]))
        # SShaDe prepared once and solved per frame on the set's clean and hard mesh (or that one mesh)
        mesh = [] if a.scaling == "set" else ["--mesh", f"{Path(a.scaling).stem}={a.scaling}"]
        s.append(("frames", [sys.executable, str(Path(__file__).resolve().parents[1] / "benchmarks" / "frames.py"),
                             *mesh, "--out", "results/frames"]))
        # the first call of a fresh process on a cold and a filled numba cache (the bunny, the
        # hard centaur at 200k), with --before COMMIT that commit's code beside this one's
        before = ["--before", a.before] if a.before else []
        s.append(("cold_start", [sys.executable, str(Path(__file__).resolve().parents[1] / "benchmarks" /
                                                     "cold_start.py"), *before, "--out", "results/cold_start"]))
    # last: results/index.html, a link to every folder's page, and its screenshot where a
    # Chromium is installed (eval/report.py); `--only report` rebuilds just these
    shot = ["--screenshot", "results/index.png"] if find_chromium() else []
    s.append(("report", py + ["eval.report", "--index", "results", *shot]))
    return s


def main(argv=None) -> int:
    """``python -m eval.reproduce [--faust DIR] [--tosca DIR] [--shapes DIR] [--scaling MESH] [--only STEPS]``.

    Returns
    -------
    0 when every step succeeded; 1 after ``error: step(s) failed: ...`` when one did
    (all are attempted); 2 after one ``error: ...`` line on a usage error or an OSError;
    130 after ``interrupted`` on Ctrl-C (the running step gets the same Ctrl-C).
    """
    p = ArgumentParser(prog="python -m eval.reproduce", description=__doc__.split("\n\n")[0])
    p.add_argument("--faust", help="folder of FAUST registrations tr_reg_XYZ.ply")
    p.add_argument("--tosca", help="folder of TOSCA .off meshes")
    p.add_argument("--shapes", help="folder with the Stanford models (armadillo.obj, bunny.off, dragon.obj)")
    p.add_argument("--scaling", help="'set': the scaling benchmark on its set of meshes (conf/experiment/"
                                     "scaling.yaml); or one real mesh for it")
    p.add_argument("--before", help="with --scaling: the cold-start step also probes this commit's code")
    p.add_argument("--dry-run", action="store_true", help="print the commands only")
    p.add_argument("--only", help="comma-separated step names to run (e.g. faust,tosca); default every step")
    p.add_argument("--check", action="store_true", help="no computation: list every committed row of results/ whose "
                                                         "code identity differs from this checkout's; exit 1 if any")
    p.add_argument("--json", action="store_true", help="with --check: print {folder: {method: {rows, stale, "
                                                        "pending}}}")
    p.add_argument("--strict", action="store_true", help="with --check: exit 1 on a row marked pending too")
    p.add_argument("--budget", help="regenerate the stale rows of the table and sweep steps that fit in DURATION "
                                    "(600s, 90m, 2h), oldest code first, then the most-cited tables; the rows left "
                                    "stay in their tables marked pending")
    p.add_argument("--any-machine", action="store_true", help="compute a table's or sweep's rows here even where its "
                                                               "rows were timed on another machine only")
    p.add_argument("--rekey", action="store_true", help="no computation: re-key the records of results/ written "
                                                         "under the earlier key layout, from the commit that made "
                                                         "each (git must have it)")
    p.add_argument("--retabulate", action="store_true", help="no computation: rebuild table.{csv,md,tex} of every "
                                                              "committed run folder from its cases.csv (after a "
                                                              "change of the tables' layout: python -m eval.tables)")
    p.add_argument("extra", nargs="*", help="extra overrides for the DeFAUST run")
    a = p.parse_args(argv)
    if (a.json or a.strict) and not a.check:
        p.error("--json and --strict go with --check")
    if a.any_machine and (a.check or a.rekey or a.retabulate):
        p.error("--any-machine goes with a run or --budget, not with --check, --rekey or --retabulate")
    if sum(map(bool, (a.check, a.rekey, a.retabulate, a.budget is not None))) > 1:
        p.error("--check, --rekey, --retabulate and --budget are separate commands: give one")
    if a.check or a.rekey:
        return run_command(lambda: _rekey(a) if a.rekey else _check(a), where="results/")
    if a.retabulate:
        return run_command(_retabulate, where="results/")
    if a.budget is not None:
        budget = parse_duration(a.budget)
        if budget is None:
            p.error(f"--budget takes a duration such as 600s, 90m or 2h, got {a.budget!r}")
        return run_command(lambda: _run_budget(a, budget), where="results/")
    return run_command(lambda: _run_steps(a), where="results/")


def _check(a) -> int:
    """``--check``: every committed row of :data:`RESULTS`, and every folder run whole,
    held to this checkout's code. A stale row its tables mark pending (with the commit
    that made it, :mod:`eval.run.pending_rows`) is counted apart: exit 0 when every row is
    current or so marked, 1 on an unmarked stale row or a stale folder run whole (and,
    with ``--strict``, on a row marked pending too)."""
    with CommitTrees() as trees:
        folders = run_folders(RESULTS)
        states = check_folders(folders, trees, marked=marked_pending)
        runs = [whole_run_state(f, trees, find_experiment) for f in whole_run_folders(RESULTS)]
    unread = _unread(folders)
    marked = {str(r.folder) for r in runs if _older_code(r) and marked_run(r.folder) == short_commit(r.origin.commit)}
    if a.json:
        out = {f: {m: {"rows": v["rows"], "stale": v["stale"] - v["marked"], "pending": v["marked"]}
                   for m, v in ms.items()} for f, ms in states.items()}
        out.update({str(r.folder): {WHOLE_RUN: {"rows": 1, "stale": int(r.stale and str(r.folder) not in marked),
                                                "pending": int(str(r.folder) in marked)}} for r in runs})
        print(json.dumps(out, indent=1, sort_keys=True))
    else:
        for f, ms in states.items():
            for m, v in ms.items():
                if v["stale"]:
                    whys = "; ".join(f"{w} ({n})" for w, n in sorted(v["why"].items(), key=lambda kv: -kv[1]))
                    kind = "pending (marked in its tables)" if v["marked"] == v["stale"] else \
                        f"stale ({v['marked']} of them marked pending)"
                    print(f"{f}: {m}: {v['stale']} of {v['rows']} rows {kind}: {whys}")
        for r in runs:
            if r.stale:
                word = "pending (marked in its table.md)" if str(r.folder) in marked else "stale"
                print(f"{r.folder}: {WHOLE_RUN} {word}: {r.why}")
    rows = sum(v["rows"] for ms in states.values() for v in ms.values())
    pending = sum(v["marked"] for ms in states.values() for v in ms.values())
    n = sum(v["stale"] for ms in states.values() for v in ms.values()) - pending
    k = sum(r.stale for r in runs) - len(marked)
    pending_runs = len(marked)
    for line in unread:
        print(line, file=sys.stderr if a.json else sys.stdout)
    bad = n or k or unread or (a.strict and (pending or pending_runs))
    word = "stale" if n or k else "unread" if unread else "pending" if pending or pending_runs else "current"
    print(f"{word}: {rows - n - pending} of {rows} committed rows in {len(states)} folders are current, "
          f"{pending} pending (marked in their tables), {n} stale; {k} of {len(runs)} folders run whole stale, "
          f"{pending_runs} pending (marked in their table.md)"
          + (f"; {len(unread)} thing(s) a reader would see that the records do not say" if unread else "")
          + ("; --strict: a pending row fails" if a.strict and pending else ""),
          file=sys.stderr if a.json else sys.stdout)
    return 1 if bad else 0


def _older_code(r) -> bool:
    """Whether the folder run whole of state ``r`` (:func:`eval.run.stale_runs.whole_run_state`)
    is stale and was made by a commit's code (clean checkout): what a pending mark may stand
    for; a folder of unknown or dirty origin is stale, never pending."""
    return bool(r.stale and r.origin is not None and r.origin.commit and r.origin.dirty is False)


def _unread(folders) -> list[str]:
    """What ``--check`` reads beyond the records: each folder's ``cases.csv`` against its
    records (:func:`eval.run.stale_rows.table_problems`), and every link under
    :data:`RESULTS` (a folder, case folder or record replaced by a link is not committed
    content: the check would not see what it points to)."""
    out = [x for f in folders for x in table_problems(f)]
    out += [f"{p}: a link (to {os.readlink(p)}), not committed content" for p in sorted(Path(RESULTS).rglob("*"))
            if p.is_symlink()]
    return out


def _rekey(a) -> int:
    """``--rekey``: re-key every record of :data:`RESULTS` of the earlier layout (:func:`rekey_record`)."""
    counts: dict[str, int] = {}
    with CommitTrees() as trees:
        for f in run_folders(RESULTS):
            for _, path in record_paths(f):
                r = rekey_record(f, path, trees)
                counts[r] = counts.get(r, 0) + 1
                if r.startswith("refused"):
                    print(f"{path}: {r}", file=sys.stderr)
    print("rekey: " + ", ".join(f"{n} {w}" for w, n in sorted(counts.items())) if counts else "rekey: no record")
    return 1 if any(w.startswith("refused") for w in counts) else 0


def _retabulate() -> int:
    """``--retabulate``: ``python -m eval.tables`` on every run folder of :data:`RESULTS`
    with a ``cases.csv`` (the folders whose tables :func:`eval.tables.write_tables` made:
    those with a result store), as a step of this command (:func:`step_env`); then each
    folder run whole marked pending in its ``table.md`` while stale, unmarked once current
    (:func:`eval.run.pending_rows.mark_run_pending`). Its exit code: that of the tables."""
    dirs = [str(f) for f in run_folders(RESULTS) if (f / "cases.csv").is_file()]
    rc = subprocess.call([sys.executable, "-m", "eval.tables", *dirs], env=step_env()) if dirs else 0
    if not dirs:
        print("retabulate: no run folder with cases.csv under results/")
    with CommitTrees() as trees:
        for r in (whole_run_state(f, trees, find_experiment) for f in whole_run_folders(RESULTS)):
            commit = r.origin.commit if r.origin else None
            if mark_run_pending(r.folder, commit, r.why if _older_code(r) else None):
                print(f"{r.folder}: {'marked pending (made at ' + short_commit(commit) + ')' if r.stale else 'current'}"
                      " in its table.md")
    return rc


def parse_duration(text) -> float | None:
    """Seconds of a duration ``"600"``, ``"600s"``, ``"90m"``, ``"2h"`` (> 0), None when it is none.

    >>> parse_duration("90m"), parse_duration("2h"), parse_duration("0s"), parse_duration("soon")
    (5400.0, 7200.0, None, None)
    """
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([smh]?)\s*", str(text))
    if not m:
        return None
    secs = float(m[1]) * {"": 1, "s": 1, "m": 60, "h": 3600}[m[2]]
    return secs if 0 < secs < float("inf") else None


def _selected(a) -> list[tuple[str, list[str]]] | None:
    """The steps ``--only`` selects (every step without it); None after one ``error:`` line
    when it names no step."""
    steps = _steps(a)
    only = [x.strip() for x in (a.only or "").split(",") if x.strip()]
    unknown = sorted(set(only) - {name for name, _ in steps})
    if unknown:
        print(f"error: --only names no step of this command: {', '.join(unknown)} "
              f"(steps: {', '.join(name for name, _ in steps)})", file=sys.stderr)
        return None
    return [(name, cmd) for name, cmd in steps if not only or name in only]


def _commit_time(commit: str, cache: dict) -> int:
    """The commit time (Unix seconds) of ``commit`` (a short or full hash), 0 when git does
    not know it (an unknown commit counts as the oldest code)."""
    if commit not in cache:
        try:
            r = subprocess.run(["git", "-C", str(REPO_ROOT), "show", "-s", "--format=%ct", commit],
                               capture_output=True, text=True, timeout=30, check=False)
            cache[commit] = int(r.stdout.strip()) if r.returncode == 0 and r.stdout.strip().isdigit() else 0
        except (OSError, subprocess.TimeoutExpired):
            cache[commit] = 0
    return cache[commit]


def _citations(folder: Path) -> int:
    """How often the README and docs/ name ``folder`` (``results/<name>``, not a longer name)."""
    pat = re.compile(re.escape(folder.as_posix()) + r"(?![\w-])")
    texts = [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").glob("*.md"))]
    return sum(len(pat.findall(t.read_text(errors="replace"))) for t in texts if t.is_file())


def _stored_folders(cmd: list[str]) -> tuple[list[Path], bool]:
    """``(run folders, has rows)`` of a step: the table steps' folder (a result store,
    ``out_dir=``) or the sweep steps' job folders (``hydra.sweep.dir=``) when the step
    resumes them with ``jobs=1`` (what a stop needs), else none; ``has rows``: the step
    keeps a result store at all."""
    folder = step_folder(cmd)
    sweep = any(x.startswith("hydra.sweep.dir=") for x in cmd)
    rows = folder is not None and (sweep or (folder / "runs").is_dir())
    stored = rows and "resume=true" in cmd and "jobs=1" in cmd
    return ([] if not stored else run_folders(folder) if sweep else [folder]), rows


def other_machine(folders, here: str | None, trees: CommitTrees | None = None) -> str | None:
    """Why rows of ``folders`` should not be computed on machine ``here``
    (:func:`eval.run.runinfo.machine_words`): the records a resumed run keeps were all timed
    on other machines, and a table cannot tell two machines' times apart. With ``trees``
    only a folder with both stale rows (computed again) and current ones counts, and only
    its current records (where none of them names its machine, every record of the folder);
    without, every record. None when one of them is ``here``, none says its machine, no
    folder mixes, or ``here`` is unknown."""
    if here is None:
        return None
    machines: dict[str, int] = {}
    for f in folders:
        kept = None
        if trees is not None:
            states = folder_states(f, trees)
            kept = {(s.case, s.method) for s in states if not s.stale}
            if not kept or len(kept) == len(states):
                continue  # every row computed again, or none: no two machines' rows in one table
        counts = row_machines([f], pairs=kept) or row_machines([f])  # kept rows of unknown machine: the folder's
        for w, n in counts.items():
            machines[w] = machines.get(w, 0) + n
    if not machines or here in machines:
        return None
    made = "; ".join(f"{n} on {w}" for w, n in sorted(machines.items(), key=lambda kv: (-kv[1], kv[0])))
    return (f"its rows were timed on another machine ({made}) and this one is {here}: one table cannot tell "
            "their times apart (--any-machine computes them here anyway)")


def _budget_order(selected, any_machine: bool = False) -> tuple[list, list]:
    """``(steps with stale rows, in the order --budget runs them, other steps not run)``:
    the table and sweep steps (:func:`_stored_folders`), each resumed with ``jobs=1``,
    ordered by the oldest commit among their stale rows, then by how often the docs cite
    their folder (most first). Each comes as ``(name, command, its run folders, why not
    here)``: why not here is :func:`other_machine`'s reason (None with ``any_machine``)."""
    runs, skipped, times = [], [], {}
    here = None if any_machine else machine_words(machine_info())
    with CommitTrees() as trees:
        for name, cmd in selected:
            folders, rows = _stored_folders(cmd)
            states = check_folders(folders, trees)
            commits = {c for ms in states.values() for v in ms.values() for c in v["commits"]}
            if commits:
                runs.append((min(_commit_time(c, times) for c in commits), -_citations(step_folder(cmd)), name, cmd,
                             folders, other_machine(folders, here, trees)))
            else:
                skipped.append((name, "no stale row" if folders else "not run with resume=true jobs=1, which a stop "
                                "needs" if rows else "not a table or sweep step (a whole run)"))
    return [r[2:] for r in sorted(runs, key=lambda r: r[:2])], skipped


def _run_budget(a, budget: float) -> int:
    """``--budget``: the plan, then the table and sweep steps with stale rows
    (:func:`_budget_order`), each given what is left of ``budget`` in
    :data:`eval.run.pending_rows.STOP_AFTER_ENV` (the evaluator starts no pair after it, and
    no job of a sweep after that moment, :func:`eval.run.pending_rows.share_stop`; the pairs
    left keep their stored rows, marked pending in the tables); a step with no time left is
    not started and its tables are rebuilt to mark its stale rows (``python -m
    eval.tables``), and so is a step whose rows were all timed on other machines
    (:func:`other_machine`; ``--any-machine`` runs it). A pair already running finishes: a
    step may overrun its share by one pair. Exit 1 if a step failed."""
    selected = _selected(a)
    if selected is None:
        return 2
    _print_plan(selected)
    order, skipped = _budget_order(selected, a.any_machine)
    for name, why in skipped:
        print(f"== {name}: not run under --budget ({why})", flush=True)
    t0, failed = time.monotonic(), []
    for name, cmd, folders, elsewhere in order:
        left = budget - (time.monotonic() - t0)
        if a.dry_run:
            print(f"== {name}: " + (f"not run ({elsewhere})" if elsewhere else
                                    f"{' '.join(cmd[1:])} ({STOP_AFTER_ENV}=what is left of {budget:.0f} s)"),
                  flush=True)
            continue
        if left < 1 or elsewhere:
            print(f"== {name}: {f'not run ({elsewhere})' if elsewhere else 'no time left in the budget'}; its stale "
                  "rows are marked pending", flush=True)
            rc = subprocess.call([sys.executable, "-m", "eval.tables", *map(str, folders)], env=step_env())
        else:
            print(f"== {name}: {' '.join(cmd[1:])} ({STOP_AFTER_ENV}={left:.0f})", flush=True)
            rc = subprocess.call(cmd, env={**step_env(), STOP_AFTER_ENV: f"{left:.0f}"})
        print(f"== {name}: exit {rc}", flush=True)
        if rc != 0:
            failed.append(name)
    print(f"budget: {time.monotonic() - t0:.0f} of {budget:.0f} s used; python -m eval.reproduce --check "
          "counts the rows still pending", flush=True)
    if failed:
        print(f"error: step(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def _run_steps(a) -> int:
    """Run every step as its own process, but a table or sweep step whose rows were all timed
    on other machines (:func:`other_machine`; its tables rebuilt to mark its stale rows
    instead, unless ``--any-machine``); 1 (after one ``error:`` line) if any failed."""
    failed = []
    selected = _selected(a)
    if selected is None:
        return 2
    _print_plan(selected)
    here = None if a.any_machine else machine_words(machine_info())
    with CommitTrees() as trees:  # before any step: each step writes its own folders only
        why = {name: other_machine(_stored_folders(cmd)[0], here, trees) for name, cmd in selected}
    for name, cmd in selected:
        folders, elsewhere = _stored_folders(cmd)[0], why[name]
        print(f"== {name}: " + (f"not run ({elsewhere}); its stale rows are marked pending" if elsewhere
                                else " ".join(cmd[1:])), flush=True)
        if a.dry_run:
            continue
        t = time.perf_counter()
        rc = subprocess.call([sys.executable, "-m", "eval.tables", *map(str, folders)] if elsewhere else cmd,
                             env=step_env())
        print(f"== {name}: exit {rc} after {time.perf_counter() - t:.0f} s", flush=True)
        if rc != 0:
            failed.append(name)
    if failed:
        print(f"error: step(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def step_env() -> dict:
    """The environment of every step: this one, marked as the reproduce run's
    (:data:`eval.run.outdir.REPRODUCE_ENV`), with this checkout first on ``PYTHONPATH``, so
    that each step and each process it starts (a benchmark's fresh-process probes) runs this
    checkout's code, not another installed copy's."""
    path = os.pathsep.join(p for p in (str(REPO_ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return dict(os.environ, **{REPRODUCE_ENV: "1", "PYTHONPATH": path})


def step_folder(cmd: list[str]) -> Path | None:
    """The folder a step writes: its ``out_dir=``, ``hydra.sweep.dir=`` or ``--out``."""
    for i, x in enumerate(cmd):
        for pre in ("out_dir=", "hydra.sweep.dir="):
            if x.startswith(pre):
                return Path(x[len(pre):])
        if x == "--out" and i + 1 < len(cmd):
            return Path(cmd[i + 1])
    return None


def _whole_now(folder: Path | None, trees: CommitTrees) -> str:
    """How the committed output of a step run whole stands: ``" (its output: current at
    abc1234)"``, ``" (its output: stale: why)"``, or ``""`` without one."""
    if folder is None or not is_whole_run(folder):
        return ""
    st = whole_run_state(folder, trees, find_experiment)
    made = f"current at {str(st.origin.commit)[:7]}" if not st.stale and st.origin else f"stale: {st.why}"
    return f" (its output: {made})"


def _print_plan(selected) -> None:
    """Before any work: per step and method, the stored rows reused and those stale (why,
    and their stored seconds as the estimate); a step without stored rows runs whole."""
    print("plan: stored rows reused and stale, per step and method (before any work)", flush=True)
    with CommitTrees() as trees:
        for name, cmd in selected:
            folder = step_folder(cmd)
            states = check_folders(run_folders(folder), trees) if folder and folder.is_dir() else {}
            if not states:
                print(f"   {name}: no stored rows; the step runs whole{_whole_now(folder, trees)}", flush=True)
                continue
            per: dict[str, list] = {}
            for ms in states.values():
                for m, v in ms.items():
                    agg = per.setdefault(m, [0, 0, 0.0, {}])
                    agg[0] += v["rows"] - v["stale"]
                    agg[1] += v["stale"]
                    agg[2] += v["stale_s"]
                    for w, n in v["why"].items():
                        agg[3][w] = agg[3].get(w, 0) + n
            # a sweep step without resume=true runs all its jobs again; with it, its jobs
            # reuse their current rows as a table step does (eval.sweeps.sweep_command.claim_sweep_dir)
            whole = "hydra.sweep.dir" in " ".join(cmd) and "resume=true" not in cmd
            for m, (ok, stale, secs, why) in per.items():
                words = "; ".join(f"{w} ({n})" for w, n in why.items())
                head = f"{ok + stale} stored, {stale} stale" if whole else f"{ok} reused, {stale} stale"
                print(f"   {name}: {m}: {head}" + (f" ({words}), about {secs:.0f} s" if stale else "")
                      + ("; a sweep step computes every row again" if whole else ""), flush=True)


if __name__ == "__main__":
    raise SystemExit(main())

"""eval/run/stale_rows.py: which committed rows are stale, and re-keying records of the
earlier key layout from the commit that made them, never recomputing them.

A record of store version 3 (from git's history of results/faust) re-keyed here keeps its
row bit for bit and becomes current; an edited, dirty, unknown-commit or wrong-identity
record is refused; an edit of SShaDe's transfer makes ``--check --json`` report SShaDe's
rows stale and no baseline's.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from eval.run.code_identity import PACKAGES
from eval.run.pending_rows import marked_pending
from eval.run.result_store import STORE_VERSION, ResultStore, fields_digest, pair_key, record_digest
from eval.run.stale_rows import (
    REKEY_FROM,
    CommitTrees,
    changed_since,
    check_folders,
    current_code,
    record_paths,
    references_on,
    rekey_record,
    row_state,
    run_folders,
)
from sshade.errors import SShaDeError

from .conftest import ROOT, edit_syntax_tree, subprocess_env
from .current_rows import current_copy, resign_current

#: a commit whose results/faust records are of store version 4 (the identity with every
#: loader and the reference code in every row), made by 3e79476's code (ARAP) and c449109's (SShaDe)
OLD = "79d1940"
OLD_RECORD = "results/faust/runs/s0_p1/{}.json"


def _git_show(rev: str, path: str) -> str:
    r = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"], capture_output=True, text=True,
                       timeout=60, check=False)
    if r.returncode != 0:
        pytest.skip(f"git history without {rev}:{path} (a shallow clone?)")
    return r.stdout


def _made_at(record: Path) -> str:
    """The short commit a stored row names as the code that made it."""
    return json.loads(record.read_text())["git"]["commit"][:7]


def _old_store(tmp_path, *methods):
    """A run folder holding results/faust's s0_p1 records of ``methods`` as committed at :data:`OLD`."""
    out = tmp_path / "run"
    (out / "runs" / "s0_p1").mkdir(parents=True)
    for m in methods:
        (out / "runs" / "s0_p1" / f"{m}.json").write_text(_git_show(OLD, OLD_RECORD.format(m)))
    return out


def test_rekey_keeps_the_row_and_makes_an_earlier_record_current(tmp_path):
    """ARAP's and SShaDe's s0_p1 records of store version 4 re-keyed: rows kept bit for
    bit, keys their new key fields' digests, the loaders (eval.datasets' package) out of
    the identity; both current held to the sources of the commit that made them (at this
    checkout too, unless their code changed since); an edit of SShaDe's transfer in a copy
    of those sources then stales SShaDe's and not ARAP's, naming the module and commit."""
    out = _old_store(tmp_path, "ARAP", "SShaDe")
    before = {m: json.loads((out / "runs" / "s0_p1" / f"{m}.json").read_text()) for m in ("ARAP", "SShaDe")}
    assert {r["version"] for r in before.values()} == {REKEY_FROM[0]}
    assert all("eval.datasets.faust" in r["key_fields"]["code"]["modules"] for r in before.values())
    was: dict = {}  # method -> the modules of its code changed since its commit, at this checkout
    with CommitTrees() as trees:
        assert {m: rekey_record(out, out / "runs" / "s0_p1" / f"{m}.json", trees) for m in before} == \
            {"ARAP": "rekeyed", "SShaDe": "rekeyed"}
        for m, old in before.items():
            found = ResultStore(out).read("s0_p1", m)
            rec = found.record
            assert found.why is None and rec["version"] == STORE_VERSION
            assert rec["row"] == old["row"] and rec["info"] == old["info"] and rec["git"] == old["git"]
            loaders = {"eval.datasets", "eval.datasets.faust", "sshade.mesh.io"}
            assert not loaders & set(rec["key_fields"]["code"]["modules"])
            assert pair_key(rec["key_fields"]["method"], rec["key_fields"]["case"], rec["key_fields"]["extra"],
                            rec["key_fields"]["code"])[0] == rec["key"]
            assert {k: rec["rekeyed"][k] for k in ("from_version", "from_key", "commit")} == \
                {"from_version": REKEY_FROM[0], "from_key": old["key"], "commit": old["git"]["commit"]}
            code, made = rec["key_fields"]["code"], trees.tree(rec["git"]["commit"])
            since = changed_since(code["modules"], code["constants"], made)  # this checkout's changes since
            st = row_state(out, rec, trees)
            assert st.stale == bool(since) and sorted(st.extra.get("changed", [])) == sorted(since), (m, since)
            was[m] = set(since)
        assert rekey_record(out, out / "runs" / "s0_p1" / "ARAP.json", trees) == "current"  # idempotent
        tree = tmp_path / "tree"
        for d in PACKAGES:
            shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
        edit_syntax_tree(tree / "sshade" / "smooth_transfer.py")
        arap, sshade = (row_state(out, ResultStore(out).read("s0_p1", m).record, trees, str(tree))
                        for m in ("ARAP", "SShaDe"))
        assert arap.stale == bool(was["ARAP"]) and set(arap.extra.get("changed", [])) == was["ARAP"]
        assert sshade.stale and set(sshade.extra["changed"]) == was["SShaDe"] | {"sshade.smooth_transfer"}
        assert sshade.why.endswith("changed since c449109") and "sshade.smooth_transfer" in sshade.why
        got = check_folders([out], trees, str(tree))[str(out)]
        assert got["SShaDe"]["changed"] == was["SShaDe"] | {"sshade.smooth_transfer"}
        assert got["ARAP"]["changed"] == was["ARAP"]


def _resign(rec: dict) -> dict:
    text = json.dumps(rec["key_fields"], sort_keys=True, separators=(",", ":"))
    rec["key"] = hashlib.sha256(text.encode()).hexdigest()
    rec["digest"] = record_digest(rec)
    return rec


@pytest.mark.parametrize("edit, why", [
    (lambda r: r["row"].update(volume_err_pct=0.0), "edited"),
    (lambda r: r["git"].update(dirty=True), "uncommitted changes"),
    (lambda r: r["git"].update(commit="0" * 40), "is not in this repository"),
    (lambda r: _resign(dict(r, key_fields=dict(r["key_fields"], code=dict(r["key_fields"]["code"], sources="0" * 64)))),
     "is not that of"),
])
def test_rekey_refuses_what_it_cannot_verify_and_leaves_the_file(tmp_path, edit, why):
    out = _old_store(tmp_path, "Elastic")
    path = out / "runs" / "s0_p1" / "Elastic.json"
    rec = json.loads(path.read_text())
    rec = edit(rec) or rec
    path.write_text(json.dumps(rec, indent=1))
    text = path.read_text()
    with CommitTrees() as trees:
        got = rekey_record(out, path, trees)
    assert got.startswith("refused") and why in got
    assert path.read_text() == text


def _reproduce(tree, *args):
    env = dict(subprocess_env(), PYTHONPATH=str(tree))
    return subprocess.run([sys.executable, "-m", "eval.reproduce", *args], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=300)


def _check_json(tree):
    env = dict(subprocess_env(), PYTHONPATH=str(tree))
    r = subprocess.run([sys.executable, "-m", "eval.reproduce", "--check", "--json"], cwd=tree, env=env,
                       capture_output=True, text=True, timeout=300)
    return r.returncode, json.loads(r.stdout), r.stderr


@pytest.mark.slow  # about 25 s: six --check / --retabulate processes on a copy of the checkout
def test_an_edit_of_sshade_transfer_makes_only_sshade_rows_stale(tmp_path):
    """``--check --json`` in a copy of the checkout with results/faust: current (exit 0);
    after an edit of sshade/smooth_transfer.py's syntax tree, SShaDe's 8 rows are stale
    and no ARAP, Elastic, ARAP-SR or Implicit-ARAP row is (exit 1); ``--retabulate`` marks
    them pending in the table (title count, one line each with its commit): ``--check``
    exits 0, ``--check --strict`` 1; with the code back, the marks go."""
    tree = tmp_path / "tree"
    for d in (*PACKAGES, "conf"):
        shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tree)  # a checkout: its conf/ is the configs' (harness.confdir)
    current_copy(ROOT / "results" / "faust", tree / "results" / "faust", str(tree))
    rc, got, err = _check_json(tree)
    assert rc == 0, err
    assert {m: v["stale"] for m, v in got["results/faust"].items()} == \
        {"ARAP": 0, "Elastic": 0, "ARAP-SR": 0, "Implicit-ARAP": 0, "SShaDe": 0}
    edit_syntax_tree(tree / "sshade" / "smooth_transfer.py")
    rc, got, err = _check_json(tree)
    assert rc == 1 and "0 pending (marked in their tables), 8 stale" in err
    assert {m: v["stale"] for m, v in got["results/faust"].items()} == \
        {"ARAP": 0, "Elastic": 0, "ARAP-SR": 0, "Implicit-ARAP": 0, "SShaDe": 8}
    # the tables rebuilt mark the 8 rows pending: --check passes, --check --strict does not
    table = tree / "results" / "faust" / "table.md"
    before = table.read_text().splitlines()
    r = _reproduce(tree, "--retabulate")
    assert r.returncode == 0, r.stderr
    text = table.read_text()
    made = [_made_at(r) for r in sorted((ROOT / "results" / "faust" / "runs").glob("*/SShaDe.json"))]
    assert len(made) == 8  # the committed rows' commits, one or several
    assert text.splitlines()[0] == before[0] + \
        f" (32 of 40 rows made by this commit's code; 8 pending from {', '.join(sorted(set(made)))})"
    assert sum(text.count(f"`SShaDe`: made at {c}; ") for c in set(made)) == 8  # no git clone: why says so
    rc, got, err = _check_json(tree)
    assert rc == 0 and "32 of 40 committed rows in 1 folders are current, 8 pending" in err, err
    assert got["results/faust"]["SShaDe"] == {"rows": 8, "stale": 0, "pending": 8}
    assert _reproduce(tree, "--check", "--strict").returncode == 1
    (tree / "sshade" / "smooth_transfer.py").write_text((ROOT / "sshade" / "smooth_transfer.py").read_text())
    assert _reproduce(tree, "--retabulate").returncode == 0  # current again: the marks are gone
    assert table.read_text().splitlines()[0] == before[0] and "made at" not in table.read_text()
    assert _reproduce(tree, "--check", "--strict").returncode == 0


def test_committed_results_are_current_or_marked_pending_at_this_checkout():
    """Every committed row's identity equals this checkout's, or its table marks it pending
    with the commit that made it (``--check`` passes): the rule for results/ (a change to
    a row's code regenerates that row, only it, or marks it)."""
    with CommitTrees() as trees:
        states = check_folders(run_folders(ROOT / "results"), trees, None, marked=marked_pending)
    stale = {f: {m: v["why"] for m, v in ms.items() if v["stale"] > v["marked"]} for f, ms in states.items()}
    assert not {f: s for f, s in stale.items() if s}
    assert sum(v["rows"] for ms in states.values() for v in ms.values()) > 0


def test_run_folders_finds_stores_and_enters_no_link(tmp_path):
    (tmp_path / "a" / "runs" / "c").mkdir(parents=True)
    (tmp_path / "sweeps" / "0" / "runs" / "runs").mkdir(parents=True)  # a case named "runs"
    (tmp_path / "outside" / "runs").mkdir(parents=True)
    os.symlink(tmp_path / "outside", tmp_path / "a" / "link")
    assert run_folders(tmp_path) == [tmp_path / "a", tmp_path / "outside", tmp_path / "sweeps" / "0"]
    assert run_folders(tmp_path / "a") == [tmp_path / "a"]


@pytest.fixture(scope="module")
def committed_records(tmp_path_factory):
    """The committed records of results/ (their ``runs/`` folders only), copied once and
    made current at this checkout (:func:`tests.current_rows.resign_current`)."""
    dst = tmp_path_factory.mktemp("records") / "results"
    for folder in run_folders(ROOT / "results"):
        rel = folder.relative_to(ROOT / "results")
        shutil.copytree(folder / "runs", dst / rel / "runs")
    resign_current(dst)  # current before the edit, whatever the committed rows' state
    return dst


def _stale_after_edit(tmp_path, records, path: str) -> dict[str, int]:
    """``{method: stale rows}`` of the committed records held to a copy of the checkout
    whose file ``path`` has one module-level statement more (as benchmarks/identity_cost.py)."""
    tree = tmp_path / "tree"
    for d in PACKAGES:
        shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
    with open(tree / path, "a") as fh:
        fh.write("\n_PROBE_EDIT = object()\n")
    out: dict[str, int] = {}
    with CommitTrees() as trees:
        for ms in check_folders(run_folders(records), trees, str(tree)).values():
            for m, v in ms.items():
                out[m] = out.get(m, 0) + v["stale"]
    return out


def _with_references(records, method: str) -> int:
    return sum(1 for f in run_folders(records) for _, p in record_paths(f)
               if p.stem == method and references_on(json.loads(p.read_text())["key_fields"]))


@pytest.mark.slow  # about 30 s: four copies of the checkout held against the 637 committed records
@pytest.mark.parametrize("path, allowed", [
    ("eval/datasets/__init__.py", {}),  # a loader's package: no row runs it
    ("sshade/mesh/io.py", {"SShaDe": None}),  # the mesh reader: no baseline row runs it
    ("sshade/arap/solver.py", {"ARAP": None, "Elastic": None, "ARAP-SR": None, "SShaDe": None,
                               "Implicit-ARAP": "references"}),
    ("baselines/implicit_arap/method.py", {"Implicit-ARAP": None}),
])
def test_an_edit_stales_only_the_rows_whose_code_it_is(tmp_path, committed_records, path, allowed):
    """A module-level edit stales only the committed rows that run the module: none for the
    dataset package, no baseline's for the mesh reader, of Implicit-ARAP only the rows with
    reference columns for the shared solver, no other method's for Implicit-ARAP's own module."""
    got = _stale_after_edit(tmp_path, committed_records, path)
    for m, n in got.items():
        bound = allowed.get(m, 0)
        if bound == "references":
            bound = _with_references(committed_records, m)
        assert bound is None or n <= bound, (m, n, bound)
    if path.startswith("baselines/implicit_arap"):
        assert got["Implicit-ARAP"] > 0  # the edit is seen where it belongs


@pytest.mark.slow  # about 20 s: --check and a --budget plan on a copy of the checkout
def test_budget_takes_a_sweep_step_with_stale_rows(tmp_path):
    """A probe edit of sshade/guard.py stales the rows of a copy of results/sweeps/arap_sr_alpha
    (ARAP-SR's alpha sweep, one store per job folder): ``--budget 1h --only
    sweep_arap_sr_alpha --dry-run`` plans that sweep step with the budget's stop, where it
    once skipped sweeps."""
    tree = tmp_path / "tree"
    for d in (*PACKAGES, "conf"):
        shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tree)
    src = ROOT / "results" / "sweeps" / "arap_sr_alpha"
    for job in sorted(p for p in src.iterdir() if (p / "runs").is_dir()):
        current_copy(job, tree / "results" / "sweeps" / "arap_sr_alpha" / job.name, str(tree))
    with open(tree / "sshade" / "guard.py", "a") as fh:
        fh.write("\n_PROBE_EDIT = object()\n")
    rc, got, err = _check_json(tree)
    stale = sum(v["stale"] for f, ms in got.items() if f.startswith("results/sweeps/arap_sr_alpha/")
                for v in ms.values())
    assert rc == 1 and stale == 24, err
    r = _reproduce(tree, "--only", "sweep_arap_sr_alpha", "--budget", "1h", "--dry-run")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "== sweep_arap_sr_alpha: -m eval.sweeps " in r.stdout
    assert "(SSHADE_STOP_AFTER_S=what is left of 3600 s)" in r.stdout
    assert "not run under --budget" not in r.stdout
    # every row stale and timed on another machine: all computed here again, no table mixes
    other = {"cpu": "Elsewhere CPU", "simd": "avx2", "cores": 2}
    sweep = tree / "results" / "sweeps" / "arap_sr_alpha"
    resign_current(sweep, str(ROOT), other)  # current at the unedited checkout: stale in the edited tree
    r = _reproduce(tree, "--only", "sweep_arap_sr_alpha", "--budget", "1h", "--dry-run")
    assert "== sweep_arap_sr_alpha: -m eval.sweeps " in r.stdout, r.stderr[-3000:]
    # one job's row current, its others stale, all of another machine: not computed here, unless asked
    job = sorted(p for p in sweep.iterdir() if (p / "runs").is_dir())[0]
    rec_path = sorted((job / "runs").glob("*/*.json"))[0]
    rec = json.loads(rec_path.read_text())
    rec["key_fields"]["code"] = current_code(rec["key_fields"], str(tree))
    rec["key"] = fields_digest(rec["key_fields"])
    rec["digest"] = record_digest(rec)
    rec_path.write_text(json.dumps(rec, indent=1) + "\n")
    r = _reproduce(tree, "--only", "sweep_arap_sr_alpha", "--budget", "1h", "--dry-run")
    assert r.returncode == 0, r.stderr[-3000:]
    assert ("== sweep_arap_sr_alpha: not run (its rows were timed on another machine (1 on Elsewhere CPU, avx2, "
            "2 cores) and this one is ") in r.stdout
    r = _reproduce(tree, "--only", "sweep_arap_sr_alpha", "--budget", "1h", "--dry-run", "--any-machine")
    assert "== sweep_arap_sr_alpha: -m eval.sweeps " in r.stdout


def test_rows_timed_on_other_machines_only_are_not_computed_here_and_say_where_they_were(tmp_path):
    """:func:`eval.reproduce.other_machine` reads the machines of a folder's records: None
    when one of them is this machine, when none says its machine (older records, a link, an
    unreadable file) or when this machine is unknown; else the reason, with the count per
    machine, most first."""
    from eval.reproduce import other_machine
    from eval.run.runinfo import machine_words
    a = {"cpu": "AMD EPYC", "simd": "avx2", "cores": 2}
    b = {"cpu": "Intel Xeon", "simd": "avx512f", "cores": 2}
    folder = tmp_path / "run"
    for i, m in enumerate([a, a, b, None]):
        d = folder / "runs" / f"s00_p0{i}"
        d.mkdir(parents=True)
        (d / "ARAP.json").write_text(json.dumps({"machine": m}))
    (folder / "runs" / "s00_p00" / "Elastic.json").write_text("{not json")
    (folder / "runs" / "s00_p01" / "Elastic.json").symlink_to(folder / "runs" / "s00_p02" / "ARAP.json")
    here = machine_words({"cpu": "Arm Neoverse", "simd": "asimd", "cores": 8})
    why = other_machine([folder], here)
    assert why.startswith("its rows were timed on another machine (2 on AMD EPYC, avx2, 2 cores; 1 on Intel Xeon, "
                          "avx512f, 2 cores) and this one is Arm Neoverse, asimd, 8 cores")
    assert "--any-machine" in why
    assert other_machine([folder], machine_words(b)) is None  # one of them is this machine
    assert other_machine([folder], None) is None
    assert other_machine([tmp_path / "empty"], here) is None


@pytest.mark.slow  # about a minute: the evaluator on the 8 FAUST cases for 20 s, then the tables
def test_budget_after_a_guard_edit_leaves_its_rows_marked_pending(tmp_path):
    """A probe edit of sshade/guard.py stales every row of a copy of results/faust (its
    Implicit-ARAP rows left out: that method may not be installed); ``--budget 20s --only
    faust`` regenerates what fits and stops: the table's title counts the rows made by this
    code and the pending ones, lists each pending row with its commit; ``--check`` exits 0,
    ``--check --strict`` 1, and no row of the table is lost."""
    faust = ROOT.parent / "shared" / "data" / "faust_reg"
    if not (faust / "tr_reg_000.ply").is_file():
        pytest.skip("no FAUST registrations in ../shared/data/faust_reg")
    tree = tmp_path / "tree"
    for d in (*PACKAGES, "conf"):
        shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tree)
    current_copy(ROOT / "results" / "faust", tree / "results" / "faust", str(tree))  # current before the edit
    for p in (tree / "results" / "faust" / "runs").glob("*/Implicit-ARAP.json"):
        p.unlink()
    with open(tree / "sshade" / "guard.py", "a") as fh:
        fh.write("\n_PROBE_EDIT = object()\n")
    rc, got, err = _check_json(tree)
    assert rc == 1 and sum(v["stale"] for v in got["results/faust"].values()) == 32
    r = _reproduce(tree, "--faust", str(faust), "--only", "faust", "--budget", "20s")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "SSHADE_STOP_AFTER_S=20" in r.stdout
    rc, got, err = _check_json(tree)
    pending = sum(v["pending"] for v in got["results/faust"].values())
    assert rc == 0 and pending > 0 and sum(v["stale"] for v in got["results/faust"].values()) == 0, err
    title = (tree / "results" / "faust" / "table.md").read_text().splitlines()[0]
    assert f"({32 - pending} of 32 rows made by this commit's code; {pending} pending from " in title
    assert (tree / "results" / "faust" / "table.md").read_text().count(": made at ") == pending
    assert _reproduce(tree, "--check", "--strict").returncode == 1


@pytest.mark.parametrize("harm", ["edited cell", "deleted record", "record a link", "case folder a file",
                                  "row deleted", "key fields edited", "plug-in claimed"])
def test_check_holds_a_table_to_its_records_and_refuses_a_record_it_cannot_trust(tmp_path, harm):
    """``--check`` reads what a reader sees: a number edited in cases.csv, a row whose
    record is gone, a link or a file where records belong, a record whose row the table
    hides, key fields edited under an unchanged key (a plug-in claimed, say) are each
    reported, and ``python -m eval.tables`` makes no table from rows that disagree."""
    from eval.run.stale_rows import table_problems
    from eval.tables import retabulate
    run = tmp_path / "faust"
    shutil.copytree(ROOT / "results" / "faust", run)
    assert table_problems(run) == []
    rec_path = run / "runs" / "s0_p2" / "ARAP.json"
    csv = run / "cases.csv"
    if harm == "edited cell":
        lines = csv.read_text().splitlines()
        head = lines[0].split(",")
        i = next(k for k, line in enumerate(lines) if line.startswith("s0_p2,") and ",ARAP," in line)
        cells = lines[i].split(",")
        j = head.index("volume_err_pct")
        cells[j] = str(float(cells[j]) + 1.0)
        lines[i] = ",".join(cells)
        csv.write_text("\n".join(lines) + "\n")
        with pytest.raises(SShaDeError, match="volume_err_pct"):
            retabulate(run)
    elif harm == "deleted record":
        rec_path.unlink()
    elif harm == "record a link":
        (tmp_path / "elsewhere.json").write_text(rec_path.read_text())
        rec_path.unlink()
        rec_path.symlink_to(tmp_path / "elsewhere.json")
    elif harm == "case folder a file":
        shutil.rmtree(run / "runs" / "s0_p2")
        (run / "runs" / "s0_p2").write_text("not a folder")
    elif harm == "row deleted":
        csv.write_text("\n".join(x for x in csv.read_text().splitlines()
                                 if not (x.startswith("s0_p2,") and ",ARAP," in x)) + "\n")
    else:
        rec = json.loads(rec_path.read_text())
        rec["key_fields"]["code"]["plugin" if harm == "plug-in claimed" else "sources"] = "0" * 64
        rec["digest"] = record_digest(rec)  # re-signed: the digest does not cover the key fields, the key does
        rec_path.write_text(json.dumps(rec))
        found = ResultStore(run).read("s0_p2", "ARAP")
        assert found.record is None and "key fields' digest" in found.why
    problems = table_problems(run)
    assert problems and any("s0_p2" in p for p in problems), problems
    with CommitTrees() as trees:
        states = check_folders([run], trees)[str(run)]
    if harm not in ("edited cell", "row deleted", "deleted record"):
        assert sum(v["stale"] for v in states.values()) >= 1  # and the record is no current row


def test_check_fails_on_a_committed_folder_replaced_by_a_link(tmp_path):
    """results/faust replaced by a link to a copy of itself: ``--check`` names the link and
    exits 1 (it once counted 597 of 637 rows and said current)."""
    tree = tmp_path / "tree"
    for d in (*PACKAGES, "conf"):
        shutil.copytree(ROOT / d, tree / d, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tree)
    shutil.copytree(ROOT / "results" / "faust", tmp_path / "faust")
    (tree / "results").mkdir()
    (tree / "results" / "faust").symlink_to(tmp_path / "faust")
    rc, got, err = _check_json(tree)
    assert rc == 1 and "results/faust: a link" in err, err


@pytest.mark.parametrize("kind", ["sparse", "fifo"])
def test_a_giant_or_pipe_cases_csv_is_reported_not_read(tmp_path, kind):
    """``--check`` (table_problems) and ``python -m eval.tables`` given a cases.csv that is a
    sparse 2 GB file or a FIFO: one problem or one error, without reading it or blocking."""
    from eval.run.stale_rows import table_problems
    from eval.tables import retabulate
    run = tmp_path / "faust"
    shutil.copytree(ROOT / "results" / "faust", run)
    csv = run / "cases.csv"
    csv.unlink()
    if kind == "fifo":
        os.mkfifo(csv)
    else:
        with open(csv, "wb") as fh:
            fh.truncate(2 ** 31)
    problems = table_problems(run)
    assert len(problems) == 1 and "cases.csv: unreadable" in problems[0], problems
    with pytest.raises(SShaDeError, match="cases.csv: cannot be read"):
        retabulate(run)

"""``python -m eval jobs=2`` when its processes die, stall or are told to stop: a dead
worker fails only the pair it ran (its row names the signal) and the advised command
keeps every stored pair; a plug-in that ends its process is a failed pair; the workers
and multiprocessing's resource tracker never outlive the main process; SIGTERM ends the
run as interrupted; a stopped worker cannot hang a Ctrl-C; a Ctrl-C at a terminal
prints no worker traceback (eval/experiments/cases/case_jobs.py, harness/jobs.py).

Every signal is sent while the plug-in :class:`tests.worker_methods.Waits` is known to
be mid-run (it wrote its ready file), never after a guessed delay.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from contextlib import contextmanager

import pandas as pd
import pytest

from eval.run.outdir import MARKER

from .conftest import ROOT, subprocess_env

A = "{_target_:tests.plugin_example.MyMethod,name:A}"
WAITS = "{_target_:tests.worker_methods.Waits,name:W}"
WAITS_ONCE = "{_target_:tests.worker_methods.Waits,name:W,once:true}"
ADVICE = re.compile(r"(?:to continue|to run them again): (python -m eval .*)$", re.M)


def _cmd(faust_root, out, methods, *extra, limit=2, jobs=2) -> list[str]:
    return [sys.executable, "-m", "eval", "dataset=faust", f"dataset.root={faust_root}", f"dataset.limit={limit}",
            "reference.cases=none", f"methods=[{','.join(methods)}]", f"jobs={jobs}", f"out_dir={out}", *extra]


def _env(ready) -> dict:
    ready.mkdir(exist_ok=True)
    return dict(subprocess_env(), SSHADE_TEST_READY=str(ready))


def _start(cmd, ready, **kw) -> subprocess.Popen:
    return subprocess.Popen(cmd, cwd=ROOT, env=_env(ready), text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, **kw)


def _wait_ready(p, ready, n: int) -> list[int]:
    """The pids of the first ``n`` processes mid-run in :class:`tests.worker_methods.Waits`."""
    t_end = time.monotonic() + 240
    while len(list(ready.glob("*.ready"))) < n and p.poll() is None and time.monotonic() < t_end:
        time.sleep(0.1)
    assert p.poll() is None and len(list(ready.glob("*.ready"))) >= n, p.communicate(timeout=60)
    return sorted(int(f.stem) for f in ready.glob("*.ready"))


def _children(pid: int) -> list[int]:
    r = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True)
    return [int(x) for x in r.stdout.split()]


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has ended
    except OSError:
        return False


def _all_gone(pids, within: float) -> list[int]:
    """The processes of ``pids`` still alive after ``within`` seconds (polled)."""
    t_end = time.monotonic() + within
    while any(_alive(q) for q in pids) and time.monotonic() < t_end:
        time.sleep(0.05)
    return [q for q in pids if _alive(q)]


def _kill_all(pids) -> None:
    for q in pids:
        if _alive(q):
            os.kill(q, signal.SIGKILL)


@contextmanager
def _two_workers_mid_run(faust_root, out, ready):
    """A ``jobs=2`` run with both workers mid-run in :class:`tests.worker_methods.Waits`:
    yields ``(p, workers, kids)`` (the main process, the workers' pids, every child of the
    main process with the workers: the resource tracker too); whatever is left of them is
    killed afterwards."""
    p = _start(_cmd(faust_root, out, [WAITS]), ready)
    kids: list[int] = []
    try:
        workers = _wait_ready(p, ready, 2)
        kids = sorted(set(_children(p.pid)) | set(workers))
        yield p, workers, kids
    finally:
        if p.poll() is None:
            p.kill()
        _kill_all(kids)


def _stored(out) -> dict:
    return {str(f.relative_to(out)): (hashlib.sha256(f.read_bytes()).hexdigest(), f.stat().st_mtime_ns)
            for f in sorted((out / "runs").rglob("*")) if f.is_file()}


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.mark.slow
def test_a_killed_worker_fails_its_pair_only_and_the_advised_command_keeps_the_store(tmp_path, faust_root):
    out, ready = tmp_path / "out", tmp_path / "ready"
    p = _start(_cmd(faust_root, out, [A, WAITS_ONCE], limit=3), ready)
    try:
        (victim,) = _wait_ready(p, ready, 1)
        os.kill(victim, signal.SIGKILL)
        o, e = p.communicate(timeout=300)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 0 and "Traceback" not in e, e[-3000:]
    rows = pd.read_csv(out / "cases.csv", keep_default_na=False)
    failed = rows[rows["error"] != ""]
    assert len(rows) == 6 and len(failed) == 1, rows[["case", "method", "error"]]
    assert failed["method"].item() == "W"
    assert failed["error"].item() == "worker process died (SIGKILL) while running this pair"
    assert json.loads((out / "run.json").read_text())["status"] == "done"
    stored = _stored(out)  # every finished pair, and not the lost one
    assert len(stored) == 5 and f"runs/{failed['case'].item()}/W.json" not in stored
    advised = ADVICE.findall(o)
    assert advised and f"{failed['case'].item()} W" in o, o[-3000:]
    again = shlex.split(advised[-1])
    assert "resume=true" in again and f"out_dir={out}" in again
    r = subprocess.run([sys.executable, *again[1:]], cwd=ROOT, env=_env(ready), capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "removed" not in r.stdout + r.stderr and "1 to run" in r.stdout
    after = _stored(out)
    assert {k: after[k] for k in stored} == stored and len(after) == 6  # kept untouched; the lost pair added
    rows = pd.read_csv(out / "cases.csv", keep_default_na=False)
    assert len(rows) == 6 and (rows["error"] == "").all()


@pytest.mark.slow
def test_os_exit_in_a_plugin_is_a_failed_pair_in_one_process(tmp_path, faust_root):
    out = tmp_path / "out"
    r = subprocess.run(_cmd(faust_root, out, [A, "{_target_:tests.worker_methods.ExitsProcess,name:X}"], jobs=1),
                       cwd=ROOT, env=subprocess_env(), capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = pd.read_csv(out / "cases.csv", keep_default_na=False)
    assert (rows.loc[rows["method"] == "X", "error"].str.startswith("os._exit(0) called")).all()
    assert (rows.loc[rows["method"] == "A", "error"] == "").all() and len(rows) == 4
    assert json.loads((out / "run.json").read_text())["status"] == "done" and (out / "table.md").is_file()


@pytest.mark.slow
def test_os_exit_and_segfault_in_workers_are_failed_pairs(tmp_path, faust_root):
    out = tmp_path / "out"
    methods = [A, "{_target_:tests.worker_methods.ExitsProcess,name:X}",
               "{_target_:tests.worker_methods.Segfaults,name:S}"]
    r = subprocess.run(_cmd(faust_root, out, methods, jobs=2), cwd=ROOT, env=subprocess_env(), capture_output=True,
                       text=True, timeout=400)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = pd.read_csv(out / "cases.csv", keep_default_na=False).set_index("method")
    assert (rows.loc["A", "error"] == "").all() and len(rows) == 6
    assert rows.loc["X", "error"].str.startswith("os._exit(0) called").all()
    assert (rows.loc["S", "error"] == "worker process died (SIGSEGV) while running this pair").all()
    assert json.loads((out / "run.json").read_text())["status"] == "done" and (out / "table.md").is_file()
    assert len(list((out / "runs").rglob("S.json"))) == 0 and len(list((out / "runs").rglob("X.json"))) == 2


@pytest.mark.slow
def test_killing_the_main_process_leaves_no_process(tmp_path, faust_root):
    with _two_workers_mid_run(faust_root, tmp_path / "out", tmp_path / "ready") as (p, _, kids):
        assert len(kids) >= 3, kids  # the workers and the resource tracker
        p.kill()
        p.communicate(timeout=60)
        left = _all_gone(kids, 5.0)
    assert not left, left


@pytest.mark.slow
def test_sigterm_ends_the_run_as_interrupted(tmp_path, faust_root):
    out = tmp_path / "out"
    with _two_workers_mid_run(faust_root, out, tmp_path / "ready") as (p, _, kids):
        p.terminate()
        o, e = p.communicate(timeout=60)
        left = _all_gone(kids, 5.0)
    assert p.returncode == 143 and _lines(e)[-1] == "interrupted" and "Traceback" not in e, e[-3000:]
    assert not left, left
    info = json.loads((out / "run.json").read_text())
    assert info["status"] == "interrupted" and "SIGTERM" in info["error"]
    assert json.loads((out / MARKER).read_text())["status"] == "interrupted"
    advised = ADVICE.findall(o)
    assert advised and "resume=true" in shlex.split(advised[-1]), o[-3000:]


@pytest.mark.slow
def test_ctrl_c_with_a_stopped_worker_ends_within_seconds(tmp_path, faust_root):
    with _two_workers_mid_run(faust_root, tmp_path / "out", tmp_path / "ready") as (p, workers, kids):
        os.kill(workers[0], signal.SIGSTOP)
        t0 = time.monotonic()
        p.send_signal(signal.SIGINT)
        try:
            _, e = p.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            e = "not ended within 10 s"
        took = time.monotonic() - t0
        left = _all_gone(kids, 5.0)
    assert took < 10 and p.returncode == 130 and _lines(e)[-1] == "interrupted", (took, e[-3000:])
    assert not left, left


@pytest.mark.slow
def test_ctrl_c_to_the_process_group_prints_no_worker_traceback(tmp_path, faust_root):
    """One worker mid-run, the other idle (its case finished: cases.csv written), when
    the whole group gets SIGINT, as a Ctrl-C at a terminal sends it. The main process is
    held (SIGSTOP) meanwhile so that it cannot end the workers before they see the
    signal: a worker that reacts to it has up to 3 s to do so (it ends, or prints)."""
    out, ready = tmp_path / "out", tmp_path / "ready"
    p = _start(_cmd(faust_root, out, [WAITS_ONCE]), ready, start_new_session=True)  # its own group
    kids: list[int] = []
    try:
        _wait_ready(p, ready, 1)
        t_end = time.monotonic() + 240
        while not (out / "cases.csv").is_file() and p.poll() is None and time.monotonic() < t_end:
            time.sleep(0.1)
        assert p.poll() is None and (out / "cases.csv").is_file(), p.communicate(timeout=60)
        kids = _children(p.pid)
        workers = [q for q in kids if b"resource_tracker" not in open(f"/proc/{q}/cmdline", "rb").read()]
        assert len(workers) == 2, kids
        os.kill(p.pid, signal.SIGSTOP)
        os.killpg(p.pid, signal.SIGINT)
        t_end = time.monotonic() + 3.0
        while all(_alive(q) for q in workers) and time.monotonic() < t_end:
            time.sleep(0.05)
        os.kill(p.pid, signal.SIGCONT)
        _, e = p.communicate(timeout=60)
        left = _all_gone(kids, 5.0)
    finally:
        if p.poll() is None:
            p.kill()
        _kill_all(kids)
    assert p.returncode == 130 and _lines(e)[-1] == "interrupted", e[-3000:]
    assert "Traceback" not in e and "KeyboardInterrupt" not in e, e[-3000:]
    assert not left, left

"""sshade/kernel_cache.py: a cold numba cache is filled on two processes (the child's half
loaded, not compiled, by the caller), announced by one line, and a failing or interrupted
child costs only time; every kernel a SShaDe call compiles is in a group."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sshade import kernel_cache
from sshade.mesh import halfedge as hmod

from .conftest import ROOT

_PROBE = r"""
import json, sys
from sshade import kernel_cache as kc
from sshade import deform
from sshade.warmup import tiny_problem
cold = kc.cold_kernels()
kc.compile_kernels(split=True)
kc.compile_kernels(split=True)                    # once per process: no second notice
ds = kc.kernel_dispatchers()
stats = {n: [sum(d.stats.cache_hits.values()), sum(d.stats.cache_misses.values())] for n, d in ds.items()}
deform(*tiny_problem(), n_low=40, n_samplings=2, workers=1)
later = [n for n, d in ds.items() if sum(d.stats.cache_misses.values()) > stats[n][1]]
print(json.dumps({"cold": cold, "stats": stats, "compiled_later": later}))
"""


def _probe(cache):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    r = subprocess.run([sys.executable, "-c", _PROBE], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout.strip().splitlines()[-1]), [ln for ln in r.stderr.splitlines() if ln.strip()]


@pytest.mark.slow
def test_a_cold_cache_is_announced_once_filled_on_two_processes_and_then_warm(tmp_path):
    first, err = _probe(tmp_path / "numba")
    groups = {g: names + kernel_cache.LARGE_GROUPS[g][1] for g, (_, names) in kernel_cache.GROUPS.items()}
    assert sorted(first["cold"]) == sorted(n for names in groups.values() for n in names)
    assert len(err) == 1 and err[0].startswith("compiling SShaDe's kernels once (about ")
    assert err[0].endswith("python -m sshade warmup does it ahead")
    child, parent = list(groups)  # the first group runs in the forked child
    # the child's kernels loaded from the cache it wrote, none compiled here (a kernel called
    # only from other kernels is neither: it is compiled into its callers)
    assert all(first["stats"][n][1] == 0 for n in groups[child])
    assert sum(first["stats"][n][0] for n in groups[child]) >= 1
    assert sum(first["stats"][n][1] for n in groups[parent]) >= 1
    assert first["compiled_later"] == []  # a SShaDe call needs no kernel the groups left out
    for name in ("_push_serial", "_mix_serial"):  # Anderson's, which SShaDe's L-BFGS never runs
        assert first["stats"][f"sshade.arap.solver_kernels.{name}"] == [0, 0]
    second, err = _probe(tmp_path / "numba")
    assert second["cold"] == [] and err == []
    assert all(s[1] == 0 for s in second["stats"].values())  # every kernel loaded


_SMALL = r"""
import json
from sshade import kernel_cache as kc
from sshade import deform
from sshade.warmup import tiny_problem
deform(*tiny_problem(), n_low=40, n_samplings=2, workers=1)
ds = kc.kernel_dispatchers()
used = {n: sum(d.stats.cache_misses.values()) + sum(d.stats.cache_hits.values()) for n, d in ds.items()}
from sshade.mesh import halfedge
print(json.dumps({"used": used, "cold_small": kc.cold_kernels(False), "cold": kc.cold_kernels(),
                  "deferred": halfedge._DEFERRED[0]}))
"""


@pytest.mark.slow
def test_a_cold_first_call_on_a_small_mesh_compiles_none_of_the_large_meshes_kernels(tmp_path):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))

    def small_call():
        r = subprocess.run([sys.executable, "-c", _SMALL], cwd=ROOT, env=env, capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 0, r.stderr[-2000:]
        return json.loads(r.stdout.strip().splitlines()[-1])
    out = small_call()
    large = sorted(n for _, names in kernel_cache.LARGE_GROUPS.values() for n in names)
    assert [n for n in large if out["used"][n]] == [] and out["deferred"]  # neither compiled nor loaded
    assert all(out["used"][n] >= 1 for _, names in kernel_cache.GROUPS.values() for n in names)
    assert out["cold_small"] == [] and out["cold"] == large  # the next small call finds the cache warm
    fill = "from sshade import kernel_cache as kc; kc.compile_kernels()"  # python -m sshade warmup's fill
    assert subprocess.run([sys.executable, "-c", fill], cwd=ROOT, env=env, timeout=600).returncode == 0
    out = small_call()  # now the cache holds them: loaded, and small meshes take the kernels again
    assert all(out["used"][n] >= 1 for n in large) and not out["deferred"] and out["cold"] == []


def _fake_groups(monkeypatch, log, child_body):
    """Two cheap groups whose runs are logged as (group, pid) lines in ``log``."""
    def run(name, body=None):
        def f():
            with open(log, "a") as fh:
                fh.write(json.dumps([name, os.getpid()]) + "\n")
            if body is not None:
                body()
        return f
    monkeypatch.setattr(kernel_cache, "GROUPS", {"a": (run("a", child_body), ()), "b": (run("b"), ())})
    monkeypatch.setattr(kernel_cache, "LARGE_GROUPS", {"a": (run("A"), ()), "b": (run("B"), ())})
    monkeypatch.setattr(kernel_cache, "_FILLED", set())
    monkeypatch.setattr(hmod, "_DEFERRED", [False])


def _runs(log):
    return [tuple(json.loads(ln)) for ln in log.read_text().splitlines()] if log.exists() else []


def test_a_failing_child_leaves_its_group_to_the_caller(tmp_path, monkeypatch):
    log = tmp_path / "runs.jsonl"
    me = os.getpid()

    def fail_in_child():
        if os.getpid() != me:
            raise RuntimeError("child fails")
    _fake_groups(monkeypatch, log, fail_in_child)
    assert kernel_cache.compile_kernels(split=True, show_notice=False) >= 0
    runs = _runs(log)
    assert ("b", me) in runs and ("a", me) in runs  # the caller ran both groups itself
    assert any(g == "a" and pid != me for g, pid in runs)  # the child tried its group
    assert kernel_cache.compile_kernels(split=True) == 0.0  # once per process


def test_the_childs_group_is_reported_with_the_childs_own_seconds_not_the_load_here(tmp_path, monkeypatch):
    log = tmp_path / "runs.jsonl"
    me = os.getpid()
    _fake_groups(monkeypatch, log, lambda: time.sleep(0.6) if os.getpid() != me else None)
    lines: list[str] = []
    kernel_cache.compile_kernels(split=True, show_notice=False, progress=lines.append)
    assert [ln.split(":")[0] for ln in lines] == ["b", "a"]  # this process's group first, then the child's
    assert {g for g, _ in _runs(log)} == {"a", "b", "A", "B"}  # each group with its large part
    assert re.fullmatch(r"b: \d+\.\d s", lines[0])
    m = re.fullmatch(r"a: (\d+\.\d) s in a second process, beside the first \((\d+\.\d) s to load here\)", lines[1])
    assert m and float(m[1]) >= 0.6 > float(m[2])  # the child's sleep, not the caller's quick run
    monkeypatch.setattr(kernel_cache, "_FILLED", set())
    lines.clear()
    kernel_cache.compile_kernels(split=False, show_notice=False, progress=lines.append)
    assert [re.fullmatch(r"[ab]: \d+\.\d s", ln) is not None for ln in lines] == [True, True]


def test_a_small_calls_fill_at_a_cold_cache_defers_the_large_part_to_the_first_large_call(tmp_path, monkeypatch):
    log = tmp_path / "runs.jsonl"
    me = os.getpid()
    _fake_groups(monkeypatch, log, None)
    monkeypatch.setattr(kernel_cache, "_cold", lambda *parts: ["cold"])
    kernel_cache.compile_kernels(large=False, split=True, show_notice=False)
    assert {g for g, _ in _runs(log)} == {"a", "b"}  # the small call's kernels only
    assert hmod._DEFERRED == [True]  # small meshes take the NumPy paths meanwhile
    assert kernel_cache.compile_kernels(large=False, split=True) == 0.0
    log.unlink()
    kernel_cache.compile_kernels(large=True, split=False, show_notice=False)
    assert sorted(_runs(log)) == [("A", me), ("B", me)]  # then only what was left
    assert hmod._DEFERRED == [False]
    assert kernel_cache.compile_kernels(large=True) == 0.0


def test_a_small_calls_fill_loads_the_large_part_where_the_cache_holds_it(tmp_path, monkeypatch):
    log = tmp_path / "runs.jsonl"
    _fake_groups(monkeypatch, log, None)
    monkeypatch.setattr(kernel_cache, "_cold", lambda *parts: [])
    kernel_cache.compile_kernels(large=False, show_notice=False)
    assert {g for g, _ in _runs(log)} == {"a", "b", "A", "B"} and hmod._DEFERRED == [False]


def test_a_small_calls_cold_kernels_leave_out_the_large_part():
    small, every = set(kernel_cache.cold_kernels(large=False)), set(kernel_cache.cold_kernels())
    large = {n for _, names in kernel_cache.LARGE_GROUPS.values() for n in names}
    assert small == every - large


def test_an_interrupted_caller_leaves_no_child_behind(tmp_path, monkeypatch):
    log = tmp_path / "runs.jsonl"
    me = os.getpid()
    _fake_groups(monkeypatch, log, lambda: time.sleep(60) if os.getpid() != me else None)

    def interrupted():
        time.sleep(0.5)  # the child has started its group
        raise KeyboardInterrupt
    groups = dict(kernel_cache.GROUPS)
    groups["b"] = (interrupted, ())
    monkeypatch.setattr(kernel_cache, "GROUPS", groups)
    t = time.perf_counter()
    with pytest.raises(KeyboardInterrupt):
        kernel_cache.compile_kernels(split=True, show_notice=False)
    assert time.perf_counter() - t < 30
    child = [pid for g, pid in _runs(log) if pid != me]
    assert len(child) == 1
    with pytest.raises(ProcessLookupError):
        os.kill(child[0], 0)  # ended and reaped


def test_a_hanging_child_is_given_up_and_its_group_run_by_the_caller(tmp_path, monkeypatch):
    log = tmp_path / "runs.jsonl"
    me = os.getpid()
    _fake_groups(monkeypatch, log, lambda: time.sleep(60) if os.getpid() != me else None)
    monkeypatch.setattr(kernel_cache, "CHILD_MIN_WAIT_S", 0.5)
    t = time.perf_counter()
    kernel_cache.compile_kernels(split=True, show_notice=False)
    assert time.perf_counter() - t < 30
    runs = _runs(log)
    assert ("a", me) in runs and ("b", me) in runs
    child = [pid for g, pid in runs if pid != me]
    with pytest.raises(ProcessLookupError):
        os.kill(child[0], 0)


def test_every_group_kernel_is_a_cached_kernel_of_the_package():
    ds = kernel_cache.kernel_dispatchers()
    named = [n for part in (kernel_cache.GROUPS, kernel_cache.LARGE_GROUPS) for _, names in part.values()
             for n in names]
    assert set(kernel_cache.LARGE_GROUPS) == set(kernel_cache.GROUPS)
    assert len(named) == len(set(named)) and set(named) <= set(ds)
    assert kernel_cache.cache_folder() is not None


def test_the_lock_file_lives_in_numbas_cache_folder_never_beside_the_sources(tmp_path, monkeypatch):
    """Without NUMBA_CACHE_DIR the lock is in a ``__pycache__`` folder; with it, inside
    NUMBA_CACHE_DIR (a fresh process each: numba reads the variable at import)."""
    probe = "import sshade.kernel_cache as k; print(k.lock_folder())"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    beside = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True, text=True,
                            timeout=120)
    assert beside.returncode == 0, beside.stderr[-2000:]
    assert Path(beside.stdout.strip()).name == "__pycache__"
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "nb")
    inside = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, env=env, capture_output=True, text=True,
                            timeout=120)
    assert inside.returncode == 0, inside.stderr[-2000:]
    folder = Path(inside.stdout.strip())
    assert folder.is_dir() and folder.resolve().is_relative_to((tmp_path / "nb").resolve())


def _hold(path):
    """Hold ``path``'s flock from another open file (as another process would)."""
    import fcntl
    fh = open(path, "a")  # noqa: SIM115
    fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
    return fh


def test_a_process_at_a_cold_cache_waits_its_turn_and_finds_it_filled(tmp_path, monkeypatch):
    """While another process fills the cache (its lock file held) this one waits; once the
    lock is free it checks again and finds the cache warm; past TURN_WAIT_S it stops
    waiting and fills it alongside."""
    pytest.importorskip("fcntl")
    monkeypatch.setattr(kernel_cache, "lock_folder", lambda: tmp_path)
    monkeypatch.setattr(kernel_cache, "cold_kernels", lambda *a: [])  # filled by the other process
    monkeypatch.setattr(kernel_cache, "TURN_WAIT_S", 0.4)
    other = _hold(tmp_path / kernel_cache.LOCK_NAME)
    t = time.perf_counter()
    with kernel_cache._turn(["m.k"]) as cold:
        waited = time.perf_counter() - t
    assert cold and waited >= 0.4  # given up: compiles alongside, as without the lock
    other.close()  # the other process done (or dead: flock goes with it)
    with kernel_cache._turn(["m.k"]) as cold:
        assert not cold
        assert _hold_fails(tmp_path / kernel_cache.LOCK_NAME)  # this process holds it while filling
    with kernel_cache._turn([]) as cold:  # a warm cache: no turn taken
        assert not cold


def _hold_fails(path) -> bool:
    import fcntl
    with open(path, "a") as fh:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return True
        fcntl.flock(fh.fileno(), fcntl.LOCK_UN)
        return False


@pytest.mark.parametrize("kind", ["link", "fifo", "folder"])
def test_a_link_fifo_or_folder_in_place_of_the_lock_file_takes_no_turn(tmp_path, monkeypatch, kind):
    """A symbolic link, a FIFO or a folder named like the lock file: the link not followed
    (nothing created where it points), the FIFO not waited on, no turn taken; the cache
    filled as without the lock."""
    pytest.importorskip("fcntl")
    cache, outside = tmp_path / "cache", tmp_path / "elsewhere" / "target"
    cache.mkdir()
    lock = cache / kernel_cache.LOCK_NAME
    {"link": lambda: lock.symlink_to(outside), "fifo": lambda: os.mkfifo(lock), "folder": lock.mkdir}[kind]()
    monkeypatch.setattr(kernel_cache, "lock_folder", lambda: cache)
    monkeypatch.setattr(kernel_cache, "cold_kernels", lambda *a: pytest.fail("no turn was to be taken"))
    t = time.perf_counter()
    with kernel_cache._turn(["m.k"]) as cold:
        assert cold
    assert time.perf_counter() - t < 5 and not outside.exists() and not outside.parent.exists()


_TURN = r"""
import json, time
from sshade import kernel_cache as kc
t = time.perf_counter()
kc.compile_kernels(split=False, show_notice=False)
ds = kc.kernel_dispatchers()
print(json.dumps({"compiled": sum(sum(d.stats.cache_misses.values()) for d in ds.values()),
                  "s": time.perf_counter() - t}))
"""


@pytest.mark.slow
def test_two_processes_at_a_cold_cache_compile_it_once(tmp_path):
    """Two processes started together on one empty cache: one compiles the kernels, the
    other waits for it and loads them all (no cache miss)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    procs = [subprocess.Popen([sys.executable, "-c", _TURN], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = []
    for p in procs:
        out, err = p.communicate(timeout=600)
        assert p.returncode == 0, err[-2000:]
        outs.append(json.loads(out.strip().splitlines()[-1]))
    assert sorted(o["compiled"] == 0 for o in outs) == [False, True], outs

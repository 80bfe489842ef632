"""harness/jobs.py's worker processes, in this process: a worker that dies loses only its
job (``on_lost``, or one error naming the signal), workers ignore Ctrl-C, a stopped
worker cannot hang the end of a run, a process a worker forks dies with it, the options
word a worker's death; and sshade/guard.py turns a plug-in's ``os._exit`` into a failed run.

Every signal is sent once the job said (through :func:`harness.jobs.send`) that it is
running, never after a guessed delay.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from harness.jobs import THREAD_VARIABLES, JobOptions, run_jobs, send
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _gone(pids, within: float) -> bool:
    t_end = time.monotonic() + within
    while any(_alive(p) for p in pids) and time.monotonic() < t_end:
        time.sleep(0.05)
    return not any(_alive(p) for p in pids)


# module-level jobs: the spawned workers import them from this module
def _job(kind: str, x: int = 0, flag: str = ""):
    """``wait``: say the worker's pid, then sleep; ``fork``: fork a child that sleeps, say
    both pids, then sleep; ``flag``: say the pid, return once ``flag`` exists; ``exit``:
    end the worker with status x; else x * x."""
    if kind == "exit":
        os._exit(x)
    if kind == "wait":
        send(("pid", os.getpid()))
        time.sleep(120)
    if kind == "fork":
        child = os.fork()
        if child == 0:
            time.sleep(120)
            os._exit(0)
        send(("pid", os.getpid(), child))
        time.sleep(120)
    if kind == "flag":
        send(("pid", os.getpid(), "flag"))
        t_end = time.monotonic() + 60
        while not os.path.exists(flag) and time.monotonic() < t_end:
            time.sleep(0.05)
        return "finished"
    return x * x


def test_a_dead_worker_loses_only_its_job_and_a_fresh_worker_continues_it():
    results, lost, killed = {}, [], []

    def message(msg):
        if msg[0] == "pid" and not killed:
            killed.append(msg[1])
            os.kill(msg[1], signal.SIGKILL)

    def on_lost(i, reason):
        lost.append((i, reason))
        return ("square", 7)  # job 0 continues with other arguments

    run_jobs(_job, [("wait",), ("square", 2), ("square", 3), ("square", 4)], workers=2, on_message=message,
             on_result=lambda i, r: results.__setitem__(i, r), on_lost=on_lost)
    assert lost == [(0, "worker process died (SIGKILL)")]
    assert results == {0: 49, 1: 4, 2: 9, 3: 16}


def test_a_dead_worker_without_on_lost_is_one_error_naming_the_signal(tmp_path):
    """Worker 0 dies while job 1 runs beside it (both have reported, so neither order nor
    load decides): one error naming the signal, after job 1 finished."""
    flag, pids = tmp_path / "flag", {}

    def message(msg):
        pids[msg[2] if len(msg) > 2 else "wait"] = msg[1]
        if len(pids) == 2:  # both jobs running: kill the waiting one, let the other finish
            os.kill(pids["wait"], signal.SIGKILL)
            flag.touch()

    results = {}
    with pytest.raises(SShaDeError, match=r"^a build worker process died \(SIGKILL\); run the same command again"):
        run_jobs(_job, [("wait",), ("flag", 0, str(flag))], workers=2, on_message=message,
                 on_result=lambda i, r: results.__setitem__(i, r))
    assert results == {1: "finished"}  # the job running beside it finished


def test_job_options_word_the_death_of_a_worker_and_are_checked():
    with pytest.raises(SShaDeError, match=r"^an evaluation worker process exited with status 3; try again$"):
        run_jobs(_job, [("exit", 3)], workers=1, options=JobOptions(what="evaluation", advice="try again"))
    assert JobOptions(thread_variables=list(THREAD_VARIABLES[:2])).thread_variables == THREAD_VARIABLES[:2]
    for bad in ({"thread_variables": "OMP_NUM_THREADS"}, {"thread_variables": ("PATH",)}, {"what": ""},
                {"advice": None}):
        with pytest.raises(SShaDeError, match=f"^JobOptions: {next(iter(bad))}"):
            JobOptions(**bad)


def test_workers_ignore_ctrl_c(tmp_path):
    flag = tmp_path / "flag"

    def message(msg):  # Ctrl-C at a terminal reaches every process of the group: the worker too
        os.kill(msg[1], signal.SIGINT)
        flag.touch()

    results = {}
    try:
        run_jobs(_job, [("flag", 0, str(flag))], workers=1, on_message=message,
                 on_result=lambda i, r: results.__setitem__(i, r))
    except KeyboardInterrupt:
        pytest.fail("the worker's Ctrl-C reached this process")
    assert results == {0: "finished"}


def test_a_stopped_worker_does_not_hang_an_interrupted_run():
    stopped, outcome = [], []

    def message(msg):
        stopped.append(msg[1])
        os.kill(msg[1], signal.SIGSTOP)
        raise KeyboardInterrupt

    def body():
        try:
            run_jobs(_job, [("wait",)], workers=1, on_message=message)
        except KeyboardInterrupt:
            outcome.append("interrupted")

    t = threading.Thread(target=body, daemon=True)
    t0 = time.monotonic()
    t.start()
    try:
        t.join(timeout=60)
        took = time.monotonic() - t0
    finally:
        for pid in stopped:  # never leave a stopped process behind, whatever happened
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
    assert outcome == ["interrupted"] and not t.is_alive()
    assert took < 60 and _gone(stopped, 5.0)


def test_a_process_forked_by_a_worker_dies_with_it():
    pids = []

    def message(msg):
        pids.extend(msg[1:])
        os.kill(msg[1], signal.SIGKILL)

    try:
        run_jobs(_job, [("fork",)], workers=1, on_message=message, on_lost=lambda i, reason: None)
        assert len(pids) == 2 and _gone(pids, 5.0)
    finally:
        for pid in pids:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)


def test_os_exit_in_a_plugin_is_a_failed_run_and_forked_children_still_exit(tmp_path):
    """In a child process (an uncaught os._exit would end pytest itself)."""
    script = textwrap.dedent("""
        import os
        from sshade.guard import MethodFailure, run_method
        from tests.conftest import icosphere

        class Exits:
            name, info = "Exits", {}
            def deform(self, V, F, handles, targets):
                child = os.fork()
                if child == 0:
                    os._exit(7)  # a child the plug-in forks exits as usual
                print("child status", os.waitstatus_to_exitcode(os.waitpid(child, 0)[1]), flush=True)
                os._exit(0)

        real = os._exit
        V, F = icosphere()
        try:
            run_method(Exits(), V, F, [0], V[:1])
        except MethodFailure as e:
            print("failed:", e)
        print("restored", os._exit is real)
    """)
    r = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=subprocess_env(), capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.splitlines() == ["child status 7",
                                     "failed: os._exit(0) called (a method must return, not end the program)",
                                     "restored True"], r.stdout

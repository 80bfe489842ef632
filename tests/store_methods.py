"""Test plug-ins for the result store (tests/test_store.py): the README's toy method,
each ``deform`` call appended to the file named by ``$SSHADE_TEST_COUNTER`` (one line
``<n_vertices> <name>``); with ``$SSHADE_TEST_HANG_AFTER=k`` the call after the k-th
one recorded sleeps (so a test can kill the run there); ``$SSHADE_TEST_SLEEP_S=s``: each
call recorded takes ``s`` seconds more."""
from __future__ import annotations

import os
import time

from .plugin_example import MyMethod


class Counted(MyMethod):
    """:class:`tests.plugin_example.MyMethod` that records its calls (module docstring)."""

    def deform(self, V, F, handles, targets):
        path = os.environ.get("SSHADE_TEST_COUNTER")
        if path:
            with open(path, "a") as fh:
                fh.write(f"{len(V)} {self.name}\n")
            with open(path) as fh:
                n = sum(1 for _ in fh)
            time.sleep(float(os.environ.get("SSHADE_TEST_SLEEP_S") or 0))
            hang = os.environ.get("SSHADE_TEST_HANG_AFTER")
            if hang and n > int(hang):
                time.sleep(600)
        return super().deform(V, F, handles, targets)


def kill_at_call(proc, counter, n: int, timeout_s: float = 300.0, sig: int | None = None) -> None:
    """Wait until the run ``proc`` (a Popen of ``python -m eval`` with
    ``$SSHADE_TEST_COUNTER`` = ``counter`` and ``$SSHADE_TEST_HANG_AFTER`` = ``n - 1``) has
    made its ``n``-th call, which sleeps, then send it ``sig`` (default SIGKILL) and wait
    for its end (SIGKILL after ``timeout_s`` more). AssertionError if it ends first or
    takes longer than ``timeout_s``."""
    import signal
    import subprocess

    try:
        t0 = time.time()
        while not (counter.exists() and len(counter.read_text().splitlines()) >= n):
            assert proc.poll() is None, proc.communicate()[1][-3000:]
            assert time.time() - t0 < timeout_s
            time.sleep(0.2)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL if sig is None else sig)
        try:
            proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            raise


class DiesOnCase(Counted):
    """:class:`Counted`, case-aware: on the case named by ``$SSHADE_TEST_DIE_CASE`` it
    kills its own process (SIGKILL), as OOM or ``kill -9`` would (tests/test_case_array.py)."""

    case = None  # set by the evaluator before each deform (eval.datasets.deformation_case.case_label)

    def deform(self, V, F, handles, targets):
        import signal
        if self.case is not None and os.environ.get("SSHADE_TEST_DIE_CASE") == self.case.name:
            os.kill(os.getpid(), signal.SIGKILL)
        return super().deform(V, F, handles, targets)


class CountedSpokes(Counted):
    """:class:`Counted` scored against the spokes energy (its ``energy`` attribute,
    :func:`eval.metrics.reference_scores.method_energy`), not spokes-and-rims."""

    energy = "spokes"

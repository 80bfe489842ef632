"""Plug-in methods that end or stall their process, for the tests of worker processes
(tests/test_jobs_no_harm.py), usable as ``_target_: tests.worker_methods.<Class>``.

:class:`Waits` lets a test act while a pair is running: its ``deform`` writes
``<pid>.ready`` into the folder named by ``$SSHADE_TEST_READY`` (atomically: the file
appears complete) and then sleeps, so the test knows which process runs it and that it
is mid-run, however loaded the machine.
"""
from __future__ import annotations

import ctypes
import os
import time
from pathlib import Path

from .plugin_example import MyMethod


class Waits(MyMethod):
    """Writes ``<pid>.ready`` into ``$SSHADE_TEST_READY``, then sleeps ``seconds``
    (default 600) before deforming. With ``once=true`` only the first call of all
    processes does so (it creates ``once.claim`` there first); the others, and every call
    of a later run in the same folder, deform at once."""

    def __init__(self, name="Waits", seconds=600.0, once=False):
        super().__init__(name)
        self.seconds, self.once = float(seconds), bool(once)

    def deform(self, V, F, handles, targets):
        folder = os.environ.get("SSHADE_TEST_READY")
        if folder and self._claim(Path(folder)):
            tmp = Path(folder) / f".{os.getpid()}.tmp"
            tmp.write_text(f"{os.getpid()}\n")
            os.replace(tmp, Path(folder) / f"{os.getpid()}.ready")
            time.sleep(self.seconds)
        return super().deform(V, F, handles, targets)

    def _claim(self, folder: Path) -> bool:
        if not self.once:
            return True
        try:
            os.close(os.open(folder / "once.claim", os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return True
        except FileExistsError:
            return False


class ExitsProcess(MyMethod):
    """Ends its process at once with ``os._exit(0)`` (no cleanup, no exception)."""

    def __init__(self, name="ExitsProcess"):
        super().__init__(name)

    def deform(self, V, F, handles, targets):
        os._exit(0)


class Segfaults(MyMethod):
    """Crashes its process with a segmentation fault (reads address 0)."""

    def __init__(self, name="Segfaults"):
        super().__init__(name)

    def deform(self, V, F, handles, targets):
        ctypes.string_at(0)
        return super().deform(V, F, handles, targets)

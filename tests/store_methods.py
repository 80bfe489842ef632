"""Test plug-ins for the result store (tests/test_store.py): the README's toy method,
each ``deform`` call appended to the file named by ``$SSHADE_TEST_COUNTER`` (one line
``<n_vertices> <name>``); with ``$SSHADE_TEST_HANG_AFTER=k`` the call after the k-th
one recorded sleeps (so a test can kill the run there)."""
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
            hang = os.environ.get("SSHADE_TEST_HANG_AFTER")
            if hang and n > int(hang):
                time.sleep(600)
        return super().deform(V, F, handles, targets)

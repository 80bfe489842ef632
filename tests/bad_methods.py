"""Tiny misbehaving plug-in methods for tests/test_guard.py, usable
as ``_target_: tests.bad_methods.<Class>`` in the evaluator's ``methods`` or as
``--method tests.bad_methods.<Class>`` in ``python -m sshade deform``.

Each one breaks one promise of :class:`sshade.method_interface.Deformer`; none of them may
corrupt a written result, stop a run, or put a bold "best" into a table.
"""
from __future__ import annotations

import sys
import time

import numpy as np


class _Base:
    """``name`` defaults to the class name; ``info`` starts empty."""

    def __init__(self, name=None):
        self.name = name or type(self).__name__
        self.info = {}

    @staticmethod
    def _moved(V, handles, targets):
        U = np.array(V, np.float64)
        U[handles] = targets
        return U


class ShortOutput(_Base):
    """Returns 5 vertices fewer than the mesh has."""

    def deform(self, V, F, handles, targets):
        return self._moved(V, handles, targets)[:-5]


class NaNOutput(_Base):
    """Returns NaN everywhere."""

    def deform(self, V, F, handles, targets):
        return np.full((len(V), 3), np.nan)


class InfOutput(_Base):
    """Returns the moved mesh with one infinite coordinate."""

    def deform(self, V, F, handles, targets):
        U = self._moved(V, handles, targets)
        U[-1, 0] = np.inf
        return U


class ComplexOutput(_Base):
    """Returns the moved mesh as a complex array (imaginary part zero)."""

    def deform(self, V, F, handles, targets):
        return self._moved(V, handles, targets) + 0j


class TextOutput(_Base):
    """Returns strings."""

    def deform(self, V, F, handles, targets):
        return self._moved(V, handles, targets).astype(str)


class FlatOutput(_Base):
    """Returns the right values as a flat (3n,) array."""

    def deform(self, V, F, handles, targets):
        return self._moved(V, handles, targets).ravel()


class HugeOutput(_Base):
    """Moves one free vertex 1e9 bounding-box diagonals away."""

    def deform(self, V, F, handles, targets):
        U = self._moved(V, handles, targets)
        free = np.setdiff1d(np.arange(len(V)), handles)
        U[free[0]] += 1e9 * np.linalg.norm(np.ptp(V, axis=0))
        return U


class NoneOutput(_Base):
    """Returns None."""

    def deform(self, V, F, handles, targets):
        return None


class ScalesInput(_Base):
    """Scales the rest pose it is given in place (then returns the moved copy)."""

    def deform(self, V, F, handles, targets):
        V *= 2.0
        targets += 1.0
        return self._moved(V, handles, targets)


class Exits(_Base):
    """Calls sys.exit(0)."""

    def deform(self, V, F, handles, targets):
        sys.exit(0)


class Interrupted(_Base):
    """Raises KeyboardInterrupt, as Ctrl-C would."""

    def deform(self, V, F, handles, targets):
        raise KeyboardInterrupt


class Sleeper(_Base):
    """Never returns in useful time (sleeps ``seconds``, default 60)."""

    def __init__(self, name=None, seconds=60.0):
        super().__init__(name)
        self.seconds = float(seconds)

    def deform(self, V, F, handles, targets):
        time.sleep(self.seconds)
        return self._moved(V, handles, targets)


class SwallowsAll(_Base):
    """Sleeps but swallows every exception raised meanwhile (a timeout included), then
    returns a plausible result."""

    def deform(self, V, F, handles, targets):
        try:
            time.sleep(60)
        except BaseException:  # noqa: BLE001 -- the misbehaviour under test
            pass
        return self._moved(V, handles, targets)


class RestPose(_Base):
    """Returns the rest pose unchanged (handles never reach their targets)."""

    def deform(self, V, F, handles, targets):
        return np.array(V)


class SoftRestPose(RestPose):
    """The rest pose, from a method that says its handles are soft (a penalty)."""

    def deform(self, V, F, handles, targets):
        self.info = {"handles": "soft"}
        return np.array(V)


class NewlineName(_Base):
    """Its name holds a newline."""

    def __init__(self, name="Bad\nName"):
        super().__init__(name)

    def deform(self, V, F, handles, targets):
        return self._moved(V, handles, targets)


class WeirdInfo(_Base):
    """Puts every awkward kind of value into ``info``; the result itself is fine."""

    def deform(self, V, F, handles, targets):
        self.info = {"nan_value": float("nan"), "inf_value": float("inf"), "huge_int": 10 ** 400,
                     "big_int": 2 ** 70, "nested": {"a": {"b": [1, 2]}}, 3: "int key", ("t", 1): "tuple key",
                     "bad\nkey": 1.5, "n_cases": 99, "n_failed": 7, "method": "Other", "error": "not an error",
                     "iterations": "many", "text": "line one\nline two | cell", "ok_value": 2.5,
                     "list_nan": [1.0, float("nan")], "obj": object(), "status": 3, "handles": 7,
                     "handle_pre_pct": "small"}
        return self._moved(V, handles, targets)

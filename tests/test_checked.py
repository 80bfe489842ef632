"""sshade/mesh/checked.py: a mesh checked once. Inside the block, validate_mesh of the very
read-only arrays returns copies without checking; of anything else it checks; the guard
checks a method's mesh once."""
from __future__ import annotations

import threading

import numpy as np
import pytest

import sshade.mesh.validate as val
from sshade.errors import SShaDeError
from sshade.guard import run_method
from sshade.mesh.checked import checked_mesh
from sshade.mesh.validate import validate_mesh


def _tet():
    V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    return V, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


@pytest.fixture()
def counted(monkeypatch):
    """The number of times validate_mesh's checks ran (the compiled checks or, on a small mesh,
    the reference checks alone)."""
    calls = []
    real_fast, real_ref = val._fast_checks, val._reference_checks

    def fast(*a, **k):
        calls.append(1)
        return real_fast(*a, **k)

    def ref(*a, **k):
        calls.append(1)
        return real_ref(*a, **k)
    monkeypatch.setattr(val, "_fast_checks", fast)
    monkeypatch.setattr(val, "_reference_checks", ref)
    return calls


def _checked():
    V, F, he = validate_mesh(*_tet(), return_halfedges=True)
    V.flags.writeable = False
    F.flags.writeable = False
    return V, F, he


def test_the_checked_arrays_come_back_as_writeable_copies_unchecked_and_nothing_else_does(counted):
    V, F, he = _checked()
    n0 = len(counted)
    with checked_mesh(V, F, he, single_component=True):
        V2, F2, he2 = validate_mesh(V, F, return_halfedges=True)
        assert len(counted) == n0 and he2 is he and np.array_equal(V2, V) and np.array_equal(F2, F)
        assert V2.flags.writeable and F2.flags.writeable and V2 is not V
        validate_mesh(V.copy(), F)  # equal, but not the checked object
        validate_mesh(V, F, allow_boundary=False)  # a check it did not pass
        assert len(counted) == n0 + 2
    validate_mesh(V, F)  # the block has ended
    assert len(counted) == n0 + 3


def test_several_components_are_trusted_only_where_the_check_allows_them(counted):
    V, F, he = _checked()
    n0 = len(counted)
    with checked_mesh(V, F, he, single_component=False):
        validate_mesh(V, F, allow_components=True)
        assert len(counted) == n0
        validate_mesh(V, F)  # the check refuses several components: run it
        assert len(counted) == n0 + 1


def test_no_trust_for_writeable_arrays_or_in_another_thread(counted):
    V, F, he = validate_mesh(*_tet(), return_halfedges=True)
    with pytest.raises(ValueError, match="read-only"):
        with checked_mesh(V, F, he, single_component=True):
            pass
    V, F, he = _checked()
    n0 = len(counted)
    with checked_mesh(V, F, he, single_component=True):
        t = threading.Thread(target=validate_mesh, args=(V, F))
        t.start()
        t.join()
    assert len(counted) == n0 + 1


class _Checks:
    """A method that checks its input, as every public entry point does."""
    name = "checks"

    def deform(self, V, F, handles, targets):
        V, F = validate_mesh(V, F)
        return V + 0.0


def test_the_guard_checks_a_methods_mesh_once_and_still_refuses_a_bad_one(counted):
    V, F = _tet()
    n0 = len(counted)
    run = run_method(_Checks(), V, F, np.array([0]), V[:1])
    assert len(counted) == n0 + 1 and np.array_equal(run.U, V)
    with pytest.raises(SShaDeError):
        run_method(_Checks(), V, F[:, ::-1][[0, 0, 1, 2]], np.array([0]), V[:1])

"""defaust/highres.py: LS3 Loop + isotropic remeshing to a vertex range; a remesh the mesh
checks refuse (e.g. a degenerate face) is followed by another attempt, never returned."""
from __future__ import annotations

import pytest

import defaust.highres as hr
from sshade.errors import SShaDeError
from sshade.mesh.validate import validate_mesh

from .conftest import icosphere


def test_a_refused_remesh_is_tried_again_with_a_shorter_edge(monkeypatch):
    V, F = icosphere()
    first = hr.subdivide_remesh(V, F, vertex_range=(150, 400), remesh_iterations=3, check_distance=True)
    assert first.attempts == 1 and 150 <= len(first.V) <= 400
    calls = []

    def refuse_once(V, F, **kw):
        calls.append(1)
        if len(calls) == 1:
            raise SShaDeError("high-res remesh: 1 degenerate (zero-area) faces")
        return validate_mesh(V, F, **kw)

    monkeypatch.setattr(hr, "validate_mesh", refuse_once)
    again = hr.subdivide_remesh(V, F, vertex_range=(150, 400), remesh_iterations=3, check_distance=True)
    assert again.attempts == 2 and again.target_edge == pytest.approx(first.target_edge * 0.995)
    assert 150 <= len(again.V) <= 400
    monkeypatch.setattr(hr, "validate_mesh", lambda V, F, **kw: (_ for _ in ()).throw(SShaDeError("bad face")))
    with pytest.raises(SShaDeError, match="meshes refused: bad face"):
        hr.subdivide_remesh(V, F, vertex_range=(150, 400), remesh_iterations=3, check_distance=True)

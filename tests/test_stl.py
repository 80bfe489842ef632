"""sshade/mesh/stl.py: STL's own cases. Binary and ASCII STL give the same mesh, corners
merged into vertices numbered in order of first appearance; a binary file is told by its
size (even when its header starts with ``solid``), its NUL bytes pass the prefix check;
what is neither binary nor ASCII STL is refused by name."""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh
from sshade.mesh.stl import check_stl_prefix, read_stl
from tests.conftest import icosphere

P = Path("m.stl")


def _first_appearance():
    """The icosphere with its vertices renumbered in order of first appearance in F."""
    V, F = icosphere()
    _, first = np.unique(F.ravel(), return_index=True)
    order = F.ravel()[np.sort(first)]  # old vertex ids in order of first appearance
    new = np.empty(len(V), np.int64)
    new[order] = np.arange(len(V))
    return V[order].astype(np.float32).astype(np.float64), new[F]


def _binary(V, F, header: bytes = b"\0" * 80) -> bytes:
    rec = np.zeros(len(F), np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")]))
    rec["v"] = V[F]
    return header.ljust(80, b" ") + struct.pack("<I", len(F)) + rec.tobytes()


def test_binary_and_ascii_stl_give_the_mesh_with_corners_merged_in_order_of_first_appearance():
    V, F = _first_appearance()
    ascii_stl = "solid s\n" + "".join(
        "facet normal 0 0 0\n outer loop\n" + "".join(f"  vertex {x!r} {y!r} {z!r}\n" for x, y, z in V[f].tolist())
        + " endloop\nendfacet\n" for f in F) + "endsolid s\n"
    for data in (_binary(V, F), _binary(V, F, b"solid but binary"), ascii_stl.encode(), ascii_stl.upper().encode()):
        U, G = read_stl(data, P)
        assert np.array_equal(U, V) and np.array_equal(G, F)


def test_nul_bytes_pass_the_prefix_check_of_a_binary_stl_only():
    V, F = _first_appearance()
    data = _binary(V, F)
    check_stl_prefix(data[:1 << 16], len(data), P)
    with pytest.raises(SShaDeError, match="byte 0: a NUL byte, so no STL text"):
        check_stl_prefix(data[:1 << 16], len(data) + 1, P)


def test_what_stl_refuses_is_named():
    cases = {
        "neither binary: its size, 12 bytes": b"no stl here\n",
        "ASCII STL with a non-ASCII byte at 21": "solid x\nvertex 0 0 0\n\xe9\n".encode("latin-1"),
        r"2 vertex lines, not a multiple of 3": b"solid x\nvertex 0 0 0\nvertex 0 0 1\n",
        "line 2: vertex '0 0 q' is not three numbers": b"solid x\nvertex 0 0 q\nvertex 0 0 1\nvertex 1 0 1\n",
        "NaN/inf vertex coordinates": b"solid x\nvertex 0 0 nan\nvertex 0 0 1\nvertex 1 0 1\n",
    }
    for word, data in cases.items():
        with pytest.raises(SShaDeError, match=word):
            read_stl(data, P)


def test_garbage_stl_is_unreadable_stl(tmp_path):
    p = tmp_path / "g.stl"
    p.write_bytes(bytes(range(256)) * 7)
    with pytest.raises(SShaDeError, match="unreadable STL"):
        read_mesh(p)

"""sshade/mesh/ply.py: PLY's own cases. Binary PLY in either byte order with any vertex and
index type, properties and elements beyond the mesh skipped (binary and ASCII), what is
refused by name, and a binary file's size bounded by its header before the rest is read
(:data:`~sshade.mesh.ply.PLY_LIST_MAX` entries per list at most)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.mesh.ply import PLY_LIST_MAX, check_ply_prefix, read_ply
from tests.conftest import icosphere

P = Path("m.ply")


def _header(fmt: str, nv: int, nf: int, vtype: str = "float", itype: str = "int", vertex_extra: str = "",
            face_extra: str = "", more: str = "") -> bytes:
    return (f"ply\nformat {fmt} 1.0\ncomment c\nelement vertex {nv}\nproperty {vtype} x\n{vertex_extra}"
            f"property {vtype} y\nproperty {vtype} z\nelement face {nf}\n"
            f"property list uchar {itype} vertex_indices\n{face_extra}{more}end_header\n").encode()


def _faces(F, order: str, itype: str, count: int = 3) -> bytes:
    fa = np.empty(len(F), np.dtype([("n", "u1"), ("idx", order + itype, (3,))]))
    fa["n"] = count
    fa["idx"] = F
    return fa.tobytes()


@pytest.mark.parametrize("fmt, order", [("binary_little_endian", "<"), ("binary_big_endian", ">")])
@pytest.mark.parametrize("vtype, vt", [("float", "f4"), ("double", "f8")])
@pytest.mark.parametrize("itype, it", [("uchar", "u1"), ("ushort", "u2"), ("int", "i4"), ("uint", "u4")])
def test_binary_ply_in_either_byte_order_with_any_type(fmt, order, vtype, vt, itype, it):
    V, F = icosphere()
    data = _header(fmt, len(V), len(F), vtype, itype) + V.astype(order + vt).tobytes() + _faces(F, order, it)
    U, G = read_ply(data, P)
    assert U.dtype == np.float64 and np.array_equal(U, V.astype(vt).astype(np.float64))
    assert np.array_equal(G, F)


def test_binary_properties_and_elements_beyond_the_mesh_are_skipped():
    V, F = icosphere()
    head = _header("binary_little_endian", len(V), len(F), vertex_extra="property uchar red\n",
                   face_extra="property int tag\n", more="element extra 1\nproperty list uchar int stuff\n")
    va = np.zeros(len(V), np.dtype([("x", "<f4"), ("red", "u1"), ("y", "<f4"), ("z", "<f4")]))
    va["x"], va["y"], va["z"] = V.T
    fa = np.zeros(len(F), np.dtype([("n", "u1"), ("idx", "<i4", (3,)), ("tag", "<i4")]))
    fa["n"], fa["idx"], fa["tag"] = 3, F, 7
    U, G = read_ply(head + va.tobytes() + fa.tobytes() + b"\x02" + np.array([1, 2], "<i4").tobytes(), P)
    assert np.array_equal(U, V.astype("f4").astype(np.float64)) and np.array_equal(G, F)


def test_ascii_properties_and_elements_beyond_the_mesh_are_skipped():
    V, F = icosphere()
    head = _header("ascii", len(V), len(F), "double", vertex_extra="property float nx\n",
                   face_extra="property uchar flag\n", more="element edge 2\nproperty int a\nproperty int b\n")
    body = "".join(f"{x!r} 0.5 {y!r} {z!r}\n" for x, y, z in V.tolist()) + "".join(
        f"3 {a} {b} {c} 1\n" for a, b, c in F.tolist()) + "0 1\n1 2\n"
    U, G = read_ply(head + body.encode(), P)
    assert np.array_equal(U, V) and np.array_equal(G, F)


def test_what_ply_refuses_is_named():
    V, F = icosphere()
    le = "binary_little_endian"
    vb = V.astype("<f4").tobytes()
    cases = {
        "face 0 has 4 vertices": _header(le, len(V), len(F)) + vb + _faces(F, "<", "i4", count=4),
        "face indices are not integers": _header(le, len(V), len(F), itype="float") + vb
        + _faces(F + 0.5, "<", "f4"),
        "list property in the vertex element": _header(le, len(V), len(F), vertex_extra="property list uchar int q\n")
        + vb,
        "with a list property before the mesh": _header(le, len(V), len(F)).replace(
            b"element vertex", b"element pre 1\nproperty list uchar int q\nelement vertex") + vb,
        "the face element needs exactly one list property": _header(le, len(V), len(F),
                                                                    face_extra="property list uchar int q\n") + vb,
        "truncated: element face announces 80 items": _header(le, len(V), len(F)) + vb + b"\x03\x00",
        "header line 9 not understood": _header(le, len(V), len(F), itype="uint64"),
        "no vertex or no face element": _header(le, len(V), len(F)).replace(b"element face", b"element facet"),
    }
    for word, data in cases.items():
        with pytest.raises(SShaDeError, match=word):
            read_ply(data, P)


def test_a_binary_files_size_is_bounded_by_its_header_before_the_rest_is_read():
    """The bound: the header, then per vertex its properties and per face a count and
    PLY_LIST_MAX indices. A file of that size passes the prefix check, one byte more is
    refused by name; NUL bytes after a binary header pass, in an ASCII body they do not."""
    head = _header("binary_little_endian", 10, 4)
    most = len(head) + 10 * 3 * 4 + 4 * (1 + PLY_LIST_MAX * 4)
    check_ply_prefix(head + b"\0" * 64, most, P)
    with pytest.raises(SShaDeError, match=rf"{most + 1} bytes, more than its header's elements can hold \({most}\)"):
        check_ply_prefix(head, most + 1, P)
    ascii_head = _header("ascii", 1, 1) + b"0 0 0\n\0"
    with pytest.raises(SShaDeError, match=f"byte {len(ascii_head) - 1}: a NUL byte, so no PLY text"):
        check_ply_prefix(ascii_head, len(ascii_head), P)

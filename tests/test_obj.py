"""sshade/mesh/obj.py: OBJ's own cases. Statements other than ``v`` and ``f`` ignored,
``f a/b/c`` and relative (negative) indices resolved, index 0 and a line that is no
statement refused by line number, and the parse in chunks: the same mesh and the same
line numbers as in one piece, in memory bounded by the file's content."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.mesh import text_rows
from sshade.mesh.io import read_mesh
from sshade.mesh.obj import read_obj
from tests.conftest import icosphere

P = Path("m.obj")


def test_other_statements_slashes_and_relative_indices_give_the_plain_mesh():
    V, F = icosphere()
    plain = "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist()) + "".join(
        f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F.tolist())
    fancy = ("# a comment\nmtllib m.mtl\no body\ng part\n"
             + "".join(f"v\t{x!r}  {y!r} {z!r} # trailing\nvn 0 0 1\nvt 0.5 0.5\n" for x, y, z in V.tolist())
             + "usemtl skin\ns off\n"
             + "".join(f"f {a + 1}/1/{a + 1} {b - len(V)}//2 {c + 1}/3\n" for a, b, c in F.tolist()))
    for text in (plain, fancy):
        U, G = read_obj(text.encode(), P)
        assert np.array_equal(U, V) and np.array_equal(G, F)


def test_index_zero_and_a_line_that_is_no_statement_are_refused_by_line():
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
    with pytest.raises(SShaDeError, match=r"line 4: vertex index 0 \(OBJ indices start at 1\)"):
        read_obj((text + "f 0 1 2\n").encode(), P)
    with pytest.raises(SShaDeError, match="line 4 is not an OBJ statement: '7x 1 2'"):
        read_obj((text + "7x 1 2\n").encode(), P)


def test_an_obj_is_parsed_in_chunks_with_the_whole_files_line_numbers_and_indices(tmp_path, monkeypatch):
    """Chunks of 64 bytes: the same mesh as one chunk (relative indices across chunks
    included), and a bad line named by its line in the file."""
    V, F = icosphere()
    text = "".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in V)
    text += "".join(f"f {a + 1} {b - len(V)} {c + 1}/{c + 1}\n" for a, b, c in F)  # b relative (negative)
    (tmp_path / "m.obj").write_text(text)
    whole = read_mesh(tmp_path / "m.obj")
    monkeypatch.setattr(text_rows.text_chunks, "__defaults__", (64,))
    small = read_mesh(tmp_path / "m.obj")
    assert np.array_equal(whole[0], V) and np.array_equal(small[0], V)
    assert np.array_equal(whole[1], F) and np.array_equal(small[1], F)
    (tmp_path / "bad.obj").write_text(text + "f 1 2\n")
    with pytest.raises(SShaDeError, match=f"line {len(V) + len(F) + 1} is a face with 2 vertices"):
        read_mesh(tmp_path / "bad.obj")


def test_a_large_obj_with_a_bad_last_line_is_refused_in_memory_bounded_by_its_content(tmp_path):
    """200,000 face lines (1.6 MB) then a bad line: refused naming that line, the parse's
    peak allocation the file, its faces and a few chunks (48 MB at most; the whole-file
    token lists took 190 MB for 500,000 lines and 776 MB for 2,000,000: 76 MB here)."""
    import tracemalloc
    (tmp_path / "g.obj").write_bytes(b"v 1 2 3\nv 1 2 4\nv 1 3 3\n" + b"f 1 2 3\n" * 200_000 + b"f 1 2\n")
    tracemalloc.start()
    with pytest.raises(SShaDeError, match="line 200004 is a face with 2 vertices"):
        read_mesh(tmp_path / "g.obj", validate=False)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 1_600_030 + 4_800_000 + 40 * 2 ** 20  # the file's bytes, its faces as int64, chunks

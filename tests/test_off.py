"""sshade/mesh/off.py: OFF's own cases. The COFF/NOFF/CNOFF variants' extra values ignored,
the counts on the ``OFF`` line or without an ``OFF`` line at all, the variants it cannot
read refused by name, and the header's counts held to the lines present."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.mesh.off import read_off
from tests.conftest import icosphere

P = Path("m.off")


def _rows(V, F, vextra: str = "", fextra: str = "") -> str:
    return "".join(f"{x!r} {y!r} {z!r}{vextra}\n" for x, y, z in V.tolist()) + "".join(
        f"3 {a} {b} {c}{fextra}\n" for a, b, c in F.tolist())


def test_variants_and_counts_lines_give_the_same_mesh():
    V, F = icosphere()
    n = f"{len(V)} {len(F)} 0"
    texts = [f"OFF\n{n}\n" + _rows(V, F), f"OFF {n}\n" + _rows(V, F), f"{n}\n" + _rows(V, F),
             f"COFF\n# colours\n\n{n}\n" + _rows(V, F, " 255 0 0 255", " 1 2 3"),
             f"NOFF\n{n}\n" + _rows(V, F, " 0 0 1"), f"CNOFF\n{n}\n" + _rows(V, F, " 0 0 1 255 0 0 255")]
    for text in texts:
        U, G = read_off(text.encode(), P)
        assert np.array_equal(U, V) and np.array_equal(G, F), text[:20]


def test_what_off_refuses_is_named():
    V, F = icosphere()
    n = f"{len(V)} {len(F)} 0"
    cases = {
        "unsupported OFF variant b'STOFF'": f"STOFF\n{n}\n" + _rows(V, F),
        "unsupported OFF variant b'4OFF'": f"4OFF\n{n}\n" + _rows(V, F),
        "truncated: no counts line after OFF": "OFF\n",
        "line 2: expected the counts 'nvertices nfaces nedges', got 'x y z'": "OFF\nx y z\n",
        f"the header announces {len(V)} vertices and {len(F) + 1} faces but only {len(V) + len(F)} data lines":
            f"OFF\n{len(V)} {len(F) + 1} 0\n" + _rows(V, F),
        "empty file": "# nothing\n\n",
    }
    for word, text in cases.items():
        with pytest.raises(SShaDeError, match=word):
            read_off(text.encode(), P)

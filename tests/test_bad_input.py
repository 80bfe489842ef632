"""Every bad input raises SShaDeError, naming the problem, before any work is done.

Checked through :func:`sshade.mesh.validate.validate_mesh` / :func:`validate_handles`,
:func:`sshade.mesh.io.read_mesh`, and the full-resolution baseline
``baselines.Elastic().deform`` (whose solver is replaced by a tripwire, so a test
fails if the method gets as far as deforming).

The ``KNOWN_BAD_MESH_BUGS`` cases and the file-format tests below were written against
bugs found in review (pinch vertices between closed fans, ragged faces, comment lines in
OFF, STL triangle soups, tab-separated OBJ quads, 0600 output files); they now guard the
fixes.
"""
from __future__ import annotations

import os

import numpy as np
import pytest

import baselines.fullres_converged
from baselines import Elastic
from sshade.errors import SShaDeError
from sshade.files import atomic_write
from sshade.mesh.io import read_mesh, write_mesh
from sshade.mesh.validate import validate_handles, validate_mesh
from tests.conftest import data_file

# ----------------------------------------------------------------------------- meshes
TET_V = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
TET_F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
OFF_TET = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"


def _cone(apex: int, ring_start: int, center: int, k: int, up: bool) -> np.ndarray:
    """Faces of a closed cone: apex fan + base fan, outward when ``up`` says where
    the apex is relative to the base."""
    i = np.arange(k)
    j = (i + 1) % k
    side = np.c_[np.full(k, apex), ring_start + j, ring_start + i]
    base = np.c_[np.full(k, center), ring_start + i, ring_start + j]
    F = np.vstack([side, base])
    return F if up else F[:, ::-1]


def _double_cone(k: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Two closed cones touching at their shared tip (vertex 0): every edge has two
    faces, orientation is consistent, one component, but vertex 0 is non-manifold."""
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t), np.zeros(k)]
    V = np.vstack([[0, 0, 0], ring + [0, 0, -1], [0, 0, -1], ring + [0, 0, 1], [0, 0, 1]])
    F = np.vstack([_cone(0, 1, k + 1, k, up=True), _cone(0, k + 2, 2 * k + 2, k, up=False)])
    return V, F


def _bowtie() -> tuple[np.ndarray, np.ndarray]:
    """Two triangles touching at one vertex (two open fans at vertex 0)."""
    V = np.array([[0., 0, 0], [1, 0, 0], [1, 1, 0], [-1, 0, 0], [-1, -1, 0]])
    return V, np.array([[0, 1, 2], [0, 3, 4]])


def _bad_meshes() -> dict[str, tuple[np.ndarray, np.ndarray, str]]:
    """name -> (V, F, word expected in the error message)."""
    nanV = TET_V.copy()
    nanV[2, 1] = np.nan
    infV = TET_V.copy()
    infV[3, 0] = -np.inf
    degV = np.vstack([TET_V, [0.5, 0.5, 0.0]])  # vertex 4 on edge (1, 2)
    degF = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 4, 3], [4, 2, 3], [1, 2, 4]])
    # three triangles on edge (0, 1): a "book" with three pages
    bookV = np.array([[0., 0, 0], [0, 0, 1], [1, 0, 0], [-1, 0.1, 0], [0, 1, 0]])
    bookF = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    twoV = np.vstack([TET_V, TET_V + [5.0, 0, 0]])
    twoF = np.vstack([TET_F, TET_F + 4])
    flipF = TET_F.copy()
    flipF[0] = flipF[0, ::-1]
    return {
        "nan coordinates": (nanV, TET_F, "NaN"),
        "inf coordinates": (infV, TET_F, "NaN/inf"),
        "quad faces": (TET_V, np.array([[0, 1, 2, 3]]), "triangles only"),
        "2-D vertices": (TET_V[:, :2], TET_F, "shape"),
        "float face indices": (TET_V, TET_F + 0.5, "not integers"),
        "index out of range": (TET_V, np.vstack([TET_F[:3], [1, 2, 4]]), "out of range"),
        "negative index": (TET_V, np.vstack([TET_F[:3], [1, 2, -1]]), "out of range"),
        "face repeats a vertex": (TET_V, np.vstack([TET_F, [1, 2, 2]]), "repeats a vertex"),
        "zero-area face": (degV, degF, "degenerate"),
        "duplicate faces": (TET_V, np.vstack([TET_F, TET_F[1]]), "duplicate faces"),
        "duplicate faces, other order": (TET_V, np.vstack([TET_F, TET_F[1, ::-1]]), "duplicate faces"),
        "non-manifold edge": (bookV, bookF, "non-manifold edge"),
        "inconsistent orientation": (TET_V, flipF, "orient"),
        "two components": (twoV, twoF, "components"),
        "non-manifold vertex (bowtie)": (*_bowtie(), "non-manifold vertices"),
        "unreferenced vertex": (np.vstack([TET_V, [2.0, 2, 2]]), TET_F, "unreferenced"),
        "too few vertices": (TET_V[:2], TET_F[:1] % 2, "at least 3"),
    }


BAD_MESHES = _bad_meshes()

# known bugs (see the module docstring); kept separate so the main list stays green
KNOWN_BAD_MESH_BUGS = {
    "non-manifold vertex (two cones touching at a tip)": (*_double_cone(), "non-manifold"),
    "ragged faces (a triangle and a quad)": (TET_V, [[0, 1, 2], [0, 1, 2, 3]], "triangle"),
}


@pytest.fixture
def no_work(monkeypatch):
    """Replace the ARAP solver behind the baselines with a tripwire."""
    def tripwire(*a, **k):
        raise AssertionError("the deformation started: bad input was not rejected first")
    monkeypatch.setattr(baselines.fullres_converged, "arap_deform", tripwire)


def test_good_tet_passes_validation_and_reaches_the_solver(no_work):
    """Sanity check of the fixtures: the tetrahedron and its handles are valid, so a
    deform call gets as far as the (tripwired) solver."""
    V, F = validate_mesh(TET_V, TET_F)
    h, T = validate_handles(V, [0, 1], V[[0, 1]])
    assert V.dtype == np.float64 and F.dtype == np.int64 and h.dtype == np.int64
    with pytest.raises(AssertionError, match="deformation started"):
        Elastic().deform(TET_V, TET_F, [0, 1], TET_V[[0, 1]])


@pytest.mark.parametrize("name", list(BAD_MESHES))
def test_validate_mesh_rejects(name):
    V, F, word = BAD_MESHES[name]
    with pytest.raises(SShaDeError, match=word):
        validate_mesh(V, F)


@pytest.mark.parametrize("name", list(BAD_MESHES))
def test_elastic_rejects_bad_mesh_before_work(name, no_work):
    V, F, word = BAD_MESHES[name]
    with pytest.raises(SShaDeError, match=word):
        Elastic().deform(V, F, [0], np.zeros((1, 3)))


@pytest.mark.parametrize("name", list(KNOWN_BAD_MESH_BUGS))
def test_validate_mesh_rejects_known_bugs(name):
    V, F, word = KNOWN_BAD_MESH_BUGS[name]
    with pytest.raises(SShaDeError, match=word):
        validate_mesh(V, F)


def test_double_cone_fixture_is_otherwise_valid():
    """The two cones are each closed, outward and manifold, so only the shared tip is
    wrong (this pins the test above on the vertex check, not on the fixture)."""
    V, F = _double_cone()
    k = 6
    validate_mesh(V[: k + 2], F[: 2 * k], allow_boundary=False)
    up = F[2 * k:] - (k + 1)
    up[F[2 * k:] == 0] = 0
    W = np.vstack([V[:1], V[k + 2:]])
    validate_mesh(W, up, allow_boundary=False)


def test_closed_mesh_required_when_asked():
    V = TET_V
    with pytest.raises(SShaDeError, match="boundary"):
        validate_mesh(V, TET_F[:3], allow_boundary=False)
    validate_mesh(V, TET_F[:3])  # an open mesh is fine by default


def test_unreferenced_vertices_in_a_real_file():
    with pytest.raises(SShaDeError, match="unreferenced"):
        read_mesh(data_file("classic/stanford-bunny.obj"))
    # the same file read without validation has the vertices but they are unused
    V, F = read_mesh(data_file("classic/stanford-bunny.obj"), validate=False)
    assert len(np.setdiff1d(np.arange(len(V)), F.ravel())) == 1113


# ----------------------------------------------------------------------------- handles
BAD_HANDLES = {
    "index out of range": ([0, 4], np.zeros((2, 3)), "out of range"),
    "negative index": ([-1], np.zeros((1, 3)), "out of range"),
    "uint64 index of 2**63": (np.array([2**63], np.uint64), np.zeros((1, 3)),
                              r"handle index 9223372036854775808 is out of range"),  # not wrapped negative
    "duplicate handles": ([1, 1], np.zeros((2, 3)), "duplicate"),
    "length mismatch": ([0, 1, 2], np.zeros((2, 3)), "differ in length"),
    "NaN targets": ([0, 1], [[0, 0, 0], [np.nan, 0, 0]], "NaN"),
    "inf targets": ([0], [[np.inf, 0, 0]], "NaN/inf"),
    "empty handles": ([], np.zeros((0, 3)), "non-empty"),
    "float handles": ([0.0, 1.0], np.zeros((2, 3)), "integer"),
    "2-D targets": ([0, 1], np.zeros((2, 2)), "shape"),
    "complex targets": ([0, 1], np.zeros((2, 3)) + 1j, "complex numbers"),
    "complex targets, no imaginary part": ([0, 1], np.zeros((2, 3), complex), "complex numbers"),
    "string targets": ([0, 1], np.array([["0", "0", "0"], ["1", "0", "0"]]), "not real numbers"),
    "object targets": ([0, 1], np.array([[0, 0, 0], [1, 0, None]], dtype=object), "not real numbers"),
}


@pytest.mark.parametrize("name", list(BAD_HANDLES))
def test_validate_handles_rejects(name):
    h, T, word = BAD_HANDLES[name]
    with pytest.raises(SShaDeError, match=word):
        validate_handles(TET_V, h, T)


@pytest.mark.parametrize("name", list(BAD_HANDLES))
def test_elastic_rejects_bad_handles_before_work(name, no_work):
    h, T, word = BAD_HANDLES[name]
    with pytest.raises(SShaDeError, match=word):
        Elastic().deform(TET_V, TET_F, h, T)


def test_scalar_handle():
    with pytest.raises(SShaDeError):
        validate_handles(TET_V, 2, np.zeros((1, 3)))


# ----------------------------------------------------------------------------- files
def _write(path, content) -> str:
    mode = "wb" if isinstance(content, bytes) else "w"
    with open(path, mode) as fh:
        fh.write(content)
    return str(path)


GARBAGE = bytes(range(256)) * 4

BAD_FILES = {
    "garbage .off": ("g.off", GARBAGE, "unreadable"),
    "garbage .obj": ("g.obj", GARBAGE, "unreadable"),
    "garbage .ply": ("g.ply", GARBAGE, "unreadable"),
    "garbage .stl": ("g.stl", GARBAGE, "unreadable"),
    "empty .off": ("e.off", "", "unreadable"),
    "unknown extension": ("m.xyz", "0 0 0\n1 0 0\n0 1 0\n", "unsupported"),
    "obj with a quad": ("q.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 2 3 4\n", "triangle"),
    "off with a quad": ("q.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n4 0 1 2 3\n", "triangle"),
    "ply with a quad": ("q.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n", "triangle"),
    "off with NaN coordinate": ("n.off", OFF_TET.replace("0 1 0\n", "0 nan 0\n"), "NaN"),
    "off with inf coordinate": ("i.off", OFF_TET.replace("0 0 1\n", "0 0 inf\n"), "NaN/inf"),
    "off with index out of range": ("r.off", OFF_TET.replace("3 1 2 3\n", "3 1 2 7\n"), "out of range"),
    "off with duplicate face": ("d.off", OFF_TET.replace("4 4 0", "4 5 0") + "3 0 2 1\n", "duplicate"),
    "obj with unreferenced vertex": ("u.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nf 1 2 3\n", "unreferenced"),
}


@pytest.mark.parametrize("name", list(BAD_FILES))
def test_read_mesh_rejects(name, tmp_path):
    fname, content, word = BAD_FILES[name]
    with pytest.raises(SShaDeError, match=word):
        read_mesh(_write(tmp_path / fname, content))


def test_read_mesh_missing_path(tmp_path):
    with pytest.raises(SShaDeError, match="not found"):
        read_mesh(tmp_path / "nothere.off")
    with pytest.raises(SShaDeError, match="a folder, not a mesh file"):
        read_mesh(tmp_path)  # a directory is not a mesh file


def test_read_good_off_and_round_trip(tmp_path):
    V, F = read_mesh(_write(tmp_path / "tet.off", OFF_TET))
    np.testing.assert_array_equal(F, TET_F)
    np.testing.assert_allclose(V, TET_V)
    for ext in (".obj", ".off", ".ply"):
        write_mesh(tmp_path / f"out{ext}", V, F)
        V2, F2 = read_mesh(tmp_path / f"out{ext}")
        np.testing.assert_allclose(V2, V)
        np.testing.assert_array_equal(F2, F)
    with pytest.raises(SShaDeError, match="unsupported"):
        write_mesh(tmp_path / "out.xyz", V, F)


@pytest.mark.parametrize("extra", ["\n", "# a comment\n"])
def test_read_off_with_blank_or_comment_line_in_vertices(tmp_path, extra):
    text = OFF_TET.replace("1 0 0\n", "1 0 0\n" + extra)
    V, F = read_mesh(_write(tmp_path / "tet.off", text))
    assert F.shape == (4, 3)


def test_read_valid_stl(tmp_path):
    import trimesh
    trimesh.Trimesh(TET_V, TET_F, process=False).export(tmp_path / "tet.stl")
    V, F = read_mesh(tmp_path / "tet.stl")
    assert V.shape == (4, 3)


def test_obj_quad_with_tab_separator(tmp_path):
    with pytest.raises(SShaDeError, match="triangle"):
        read_mesh(_write(tmp_path / "q.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf\t1 2 3 4\n"))


# ----------------------------------------------------------------------------- atomic_write
def _leftovers(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_atomic_write_success(tmp_path):
    p = tmp_path / "sub" / "out.txt"
    with atomic_write(p) as fh:
        fh.write("hello")
    assert p.read_text() == "hello"
    assert _leftovers(p.parent) == ["out.txt"]


def test_atomic_write_exception_leaves_nothing(tmp_path):
    p = tmp_path / "out.txt"
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_write(p) as fh:
            fh.write("half")
            raise RuntimeError("boom")
    assert not p.exists()
    assert _leftovers(tmp_path) == []


def test_atomic_write_exception_keeps_previous_content(tmp_path):
    p = tmp_path / "out.bin"
    p.write_bytes(b"old content")
    with pytest.raises(KeyboardInterrupt):
        with atomic_write(p, "wb") as fh:
            fh.write(b"new, half written")
            raise KeyboardInterrupt
    assert p.read_bytes() == b"old content"
    assert _leftovers(tmp_path) == ["out.bin"]


def test_write_mesh_failure_keeps_previous_file(tmp_path, monkeypatch):
    p = tmp_path / "m.off"
    write_mesh(p, TET_V, TET_F)
    before = p.read_bytes()

    def fail(*a, **k):
        raise OSError("disk full")
    monkeypatch.setattr(os, "fsync", fail)
    with pytest.raises(OSError, match="disk full"):
        write_mesh(p, 2 * TET_V, TET_F)
    assert p.read_bytes() == before
    assert _leftovers(tmp_path) == ["m.off"]


def test_atomic_write_respects_umask(tmp_path):
    p = tmp_path / "out.txt"
    old = os.umask(0o022)
    try:
        with atomic_write(p) as fh:
            fh.write("x")
    finally:
        os.umask(old)
    assert (p.stat().st_mode & 0o777) == 0o644

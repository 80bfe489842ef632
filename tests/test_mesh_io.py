"""sshade/mesh/io.py and the files around it (handle files, ``-o``): no input kills the
interpreter, no wrong mesh is ever written.

Readers never abort natively nor print a reader's noise, writers are bit exact and
signed, index handles are refused on STL, handle files fail on one line, scale
problems are named, and ``-o`` never overwrites an input or a foreign file silently.
"""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from sshade.deform_command import main
from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh, write_mesh
from sshade.mesh.validate import validate_handles, validate_mesh
from tests.conftest import ROOT, icosphere, subprocess_env, write_lift_selection


def written_by_sshade(path) -> bool:
    """sshade.mesh.io.written_by_sshade, imported per test (each test fails on its own)."""
    from sshade.mesh.io import written_by_sshade as ours
    return ours(path)


def _mesh():
    """A small closed mesh: a once-subdivided icosahedron (42 vertices, 80 faces)."""
    return icosphere()


PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
            "element face {nf}\nproperty list uchar int vertex_indices\nend_header\n")


def _bad_mesh_files(d):
    """{name: path} of truncated, lying, huge-count and garbage mesh files."""
    V, F = _mesh()
    vtxt = "".join(f"{x} {y} {z}\n" for x, y, z in V)
    ftxt = "".join(f"3 {a} {b} {c}\n" for a, b, c in F)
    ply = PLY_HEAD.format(nv=len(V), nf=len(F)) + vtxt + ftxt
    off = f"OFF\n{len(V)} {len(F)} 0\n" + vtxt + ftxt
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in V) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F)
    bhead = PLY_HEAD.replace("ascii", "binary_little_endian")
    rng = np.random.default_rng(0)
    files = {
        "ply truncated": ("t.ply", ply[:len(ply) // 3]),
        "ply header claims more": ("m.ply", PLY_HEAD.format(nv=len(V) * 10, nf=len(F)) + vtxt + ftxt),
        "ply binary 2e9 vertices": ("h.ply", bhead.format(nv=2_000_000_000, nf=2).encode()
                                    + V.astype("<f4").tobytes()),
        "ply binary truncated faces": ("bt.ply", bhead.format(nv=len(V), nf=len(F)).encode()
                                       + V.astype("<f4").tobytes() + b"\x03\x00"),
        "off truncated": ("t.off", off[:len(off) // 2]),
        "off header claims more": ("m.off", off.replace(f"{len(V)} {len(F)} 0", f"{len(V)} {len(F) * 5} 0")),
        "off huge counts": ("h.off", off.replace(f"{len(V)} {len(F)} 0", "2000000000 2000000000 0")),
        "obj truncated mid-line": ("t.obj", obj[:len(obj) // 2 + 3]),
        "obj index past the end": ("e.obj", obj + "f 1 2 99999999999999999999\n"),
        "obj binary garbage": ("g.obj", rng.integers(0, 256, 3000, dtype=np.uint8).tobytes()),
        "stl binary garbage": ("g.stl", rng.integers(0, 256, 3000, dtype=np.uint8).tobytes()),
        "stl ascii garbage": ("a.stl", "solid x\nfacet normal 0 0 1\nvertex 0 0\n\xe9\n".encode("latin-1")),
    }
    out = {}
    for name, (fname, content) in files.items():
        p = d / fname
        p.write_bytes(content if isinstance(content, bytes) else content.encode())
        out[name] = p
    return out


def test_no_mesh_file_aborts_or_prints_reader_noise(tmp_path):
    """Every broken file is one SShaDeError in a child process that survives them all
    (libigl aborted with a double free on truncated PLYs), quickly, with nothing printed
    on the C-level stdout/stderr (libigl's 'readOBJ() ignored ...' and raw bytes)."""
    files = _bad_mesh_files(tmp_path)
    code = ("import json, sys\nfrom sshade.mesh.io import read_mesh\nfrom sshade.errors import SShaDeError\n"
            "for name, p in json.loads(sys.argv[1]).items():\n"
            "    try:\n        read_mesh(p)\n        res = 'read'\n"
            "    except SShaDeError as e:\n        res = 'error: ' + str(e)\n"
            "    sys.stderr.write('\\n' + json.dumps([name, res]) + '\\n'); sys.stderr.flush()\n")
    r = subprocess.run([sys.executable, "-c", code, json.dumps({k: str(v) for k, v in files.items()})],
                       cwd=ROOT, env=subprocess_env(), capture_output=True, timeout=60)
    assert r.returncode == 0, (r.returncode, r.stderr[-500:])
    assert r.stdout == b""
    lines = [ln for ln in r.stderr.decode("utf-8", "replace").splitlines() if ln]
    got = dict(json.loads(ln) for ln in lines)  # any reader noise would not be JSON
    assert set(got) == set(files)
    for name, res in got.items():
        assert res.startswith("error: ") and str(files[name]) in res, (name, res)
        assert res.isascii(), (name, res)


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply"])
def test_write_read_round_trip_is_bit_exact_and_signed(tmp_path, ext):
    V, F = _mesh()
    rng = np.random.default_rng(1)
    scale = 10.0 ** rng.integers(-25, 25, size=V.shape)  # tiny and huge magnitudes, random digits
    Vr = V * scale + rng.standard_normal(V.shape) * scale * 1e-3
    Vr[0] = [np.nextafter(1.0, 2.0), 5e-324 * 3e5, -1.7976931348623157e+30]
    p = tmp_path / f"m{ext}"
    write_mesh(p, Vr, F)
    V2, F2 = read_mesh(p, validate=False)
    assert V2.dtype == np.float64 and np.array_equal(V2.view(np.int64), Vr.view(np.int64))
    np.testing.assert_array_equal(F2, F)
    assert written_by_sshade(p)
    other = tmp_path / f"o{ext}"
    import igl
    igl.write_triangle_mesh(str(other), V, F)
    assert not written_by_sshade(other)
    # another writer's file keeps its vertex order too (index handles refer to it)
    perm = rng.permutation(len(V))
    Vp, Fp = V[perm], np.argsort(perm)[F]
    import trimesh
    trimesh.Trimesh(Vp, Fp, process=False).export(other, **({"encoding": "ascii"} if ext == ".ply" else {}))
    V3, F3 = read_mesh(other)
    np.testing.assert_allclose(V3, Vp, rtol=1e-7, atol=1e-7)
    np.testing.assert_array_equal(F3, Fp)


# ----------------------------------------------------------------------------- the CLI
@pytest.fixture
def case(tmp_path):
    """A small mesh (.off, written by sshade) with a .sel/.def and a .json/.csv."""
    V, F = _mesh()
    d = tmp_path / "in"
    d.mkdir()
    write_mesh(d / "m.off", V, F)
    write_lift_selection(d, V)
    return {"V": V, "F": F, "d": d, "off": d / "m.off", "sel": d / "m.sel", "def": d / "m.def"}


FAST = ["--n-low", "20", "--k", "1", "--param", "workers=1"]


def _run(args, capsys):
    try:
        rc = main(["deform", *map(str, args)])
    except SystemExit as e:
        rc = e.code
    out, err = capsys.readouterr()
    return rc, out, err


def _one_error(rc, err, word):
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("error: "), (rc, err)
    assert word in lines[0], lines[0]


def test_stl_input_with_index_handles_is_refused(case, tmp_path, capsys):
    import trimesh
    stl = tmp_path / "m.stl"
    trimesh.Trimesh(case["V"], case["F"], process=False).export(stl)
    rc, out, err = _run([stl, "--sel", case["sel"], "--def", case["def"], "-o", tmp_path / "o.off", *FAST], capsys)
    _one_error(rc, err, "no vertex indices")
    assert "OBJ, OFF or PLY" in err and not (tmp_path / "o.off").exists()


def test_output_checks_before_any_work(case, tmp_path, capsys, monkeypatch):
    import sshade.mesh.io as mio

    def boom(*a, **k):
        raise AssertionError("read the mesh before checking -o")
    args = ["--sel", case["sel"], "--def", case["def"], *FAST]
    before = case["off"].read_bytes()
    monkeypatch.setattr(mio, "read_mesh", boom)
    rc, out, err = _run([case["off"], *args, "-o", case["off"]], capsys)  # the input itself
    _one_error(rc, err, "--force")
    assert case["off"].read_bytes() == before
    foreign = tmp_path / "foreign.ply"
    foreign.write_bytes(b"not ours")
    rc, out, err = _run([case["off"], *args, "-o", foreign], capsys)
    _one_error(rc, err, "--force")
    assert foreign.read_bytes() == b"not ours"
    rc, out, err = _run([case["off"], *args, "-o", tmp_path / "nodir" / "o.ply"], capsys)
    _one_error(rc, err, "does not exist")
    monkeypatch.undo()
    out_p = tmp_path / "o.ply"
    rc, out, err = _run([case["off"], *args, "-o", out_p], capsys)
    assert rc == 0 and "replacing" not in out, err
    first = out_p.read_bytes()
    rc, out, err = _run([case["off"], *args, "-o", out_p, "--seed", "3"], capsys)  # ours: replaced, said so
    assert rc == 0 and f"replacing {out_p}" in out, err
    rc, out, err = _run([case["off"], *args, "-o", foreign, "--force"], capsys)
    assert rc == 0 and written_by_sshade(foreign) and len(read_mesh(foreign)[0]) == len(case["V"])
    assert first[:3] == b"ply"


def _handle_file(d, name, text):
    p = d / name
    p.write_text(text)
    return p


BAD_HANDLES = {  # file name: (content, word in the error)
    "big.json": ('{"handles": [100000000000000000000000, 2], "targets": [[0,0,0],[1,1,1]]}', "out of range"),
    "e30.json": ('{"handles": [1e30], "targets": [[0,0,0]]}', "integer vertex indices"),
    "deep.json": ('{"handles": ' + "[" * 100000 + "]" * 100000 + "}", "nested too deeply"),
    "bool.json": ('{"handles": [1, 2], "targets": [[0,0,true],[1,1,1]]}', "[x, y, z] numbers"),
    "nan.json": ('{"handles": [1], "targets": [[0,0,NaN]]}', "NaN/inf"),
    "inf.json": ('{"handles": [1], "targets": [[0,0,1e999]]}', "NaN/inf"),
    "str.json": ('{"handles": [1], "targets": [[0,0,"x"]]}', "[x, y, z] numbers"),
    "big.csv": ("100000000000000000000000,0,0,0\n", "out of range"),
    "e30.csv": ("1e30,0,0,0\n", "not an integer"),
    "nan.csv": ("1,0,0,nan\n", "NaN/inf"),
    "far.csv": ("1,0,0,1e200\n", "out of scale"),
}


def test_bad_handle_files_are_one_line(case, capsys):
    """Overflowing indices, deep JSON, bools, NaN/inf, text, far targets: each one
    ``error:`` line (no traceback), and no output file."""
    for name, (text, word) in BAD_HANDLES.items():
        p = _handle_file(case["d"], name, text)
        rc, out, err = _run([case["off"], "--handles", p, "-o", case["d"] / "o.ply", *FAST], capsys)
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1 and lines[0].startswith("error: ") and word in lines[0], (name, err)
        assert not (case["d"] / "o.ply").exists(), name


def test_huge_handle_file_refused_before_reading(case, capsys):
    p = case["d"] / "huge.sel"
    with open(p, "wb") as fh:
        fh.truncate(200 << 20)  # sparse: 200 MiB of zero bytes
    rc, out, err = _run([case["off"], "--sel", p, "--def", case["def"], "-o", case["d"] / "o.ply", *FAST], capsys)
    _one_error(rc, err, "too large")


def test_dmat_reader_is_quiet_and_checks_counts(case, capfd):
    from sshade.mesh.handle_files import read_dmat_selection
    p = case["d"] / "short.dmat"
    p.write_text("1 1000\n0\n1\n2\n")
    with pytest.raises(SShaDeError, match="1000 values, 3 found"):
        read_dmat_selection(p, 1000)
    assert capfd.readouterr().err == ""


# ----------------------------------------------------------------------------- scale
def test_overflowing_mesh_is_called_overflow_not_degenerate(case):
    V, F = case["V"], case["F"]
    with pytest.raises(SShaDeError, match=r"coordinates overflow in float64 \(largest \|x\| = 1"):
        validate_mesh(V * 1e160, F)
    with pytest.raises(SShaDeError, match="underflow"):
        validate_mesh(V * 1e-160, F)
    validate_mesh(V * 1e25, F)  # large but fine
    validate_mesh(V * 1e-25, F)


def test_targets_out_of_scale_named(case):
    V = case["V"]
    with pytest.raises(SShaDeError, match="targets are out of scale: they lie 1e\\+30 x"):
        validate_handles(V, [0, 1], np.array([V[0], V[1] + [0, 0, 1e30 * np.linalg.norm(np.ptp(V, 0))]]))
    validate_handles(V, [0, 1], np.array([V[0], V[1] + [0, 0, 1e3]]))  # a big edit is still allowed


def test_targets_checked_against_the_bounding_box_corners_as_against_the_mesh(case):
    """validate_targets with the two corners of V's bounding box accepts and refuses what
    validate_handles with V does, with the same message."""
    from sshade.mesh.validate import validate_targets
    V = case["V"]
    corners = np.array([V.min(0), V.max(0)])
    ok = np.array([V[0], V[1] + [0, 0, 1e3]])
    assert np.array_equal(validate_targets(corners, 2, ok), validate_handles(V, [0, 1], ok)[1])
    far = V[1] + [0, 0, 1e30 * np.linalg.norm(np.ptp(V, 0))]
    bad = [ok[:1], np.array([V[0], [np.nan, 0, 0]]), np.array([V[0], far])]
    for T in bad:
        with pytest.raises(SShaDeError) as a:
            validate_handles(V, [0, 1], T)
        with pytest.raises(SShaDeError) as b:
            validate_targets(corners, 2, T)
        assert str(a.value) == str(b.value)


def test_def_scaled_by_1e200_is_out_of_scale_not_singular(case, capsys):
    from sshade.mesh.handle_files import read_def
    p = case["d"] / "big.def"
    M = np.eye(4)
    M[:3, :3] *= 1e200
    np.savetxt(p, M)
    np.testing.assert_array_equal(read_def(p), M)
    rc, out, err = _run([case["off"], "--sel", case["sel"], "--def", p, "-o", case["d"] / "o.ply", *FAST], capsys)
    _one_error(rc, err, "targets are out of scale")


BOM = b"\xef\xbb\xbf"


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply"])
def test_a_utf8_byte_order_mark_is_read_as_the_same_mesh(tmp_path, ext):
    V, F = icosphere()
    write_mesh(tmp_path / f"m{ext}", V, F)
    (tmp_path / f"bom{ext}").write_bytes(BOM + (tmp_path / f"m{ext}").read_bytes())
    U, G = read_mesh(tmp_path / f"bom{ext}")
    assert np.array_equal(U, V) and np.array_equal(G, F)


def test_handle_files_with_a_byte_order_mark_give_the_same_handles(tmp_path):
    from sshade.mesh.handle_files import read_handle_file, read_sel
    V, F = icosphere()
    (tmp_path / "h.csv").write_bytes(BOM + b"index,x,y,z\n3,0,0,1\n7,1,0,0\n")
    (tmp_path / "h.json").write_bytes(BOM + json.dumps({"handles": [3, 7], "targets": [[0, 0, 1], [1, 0, 0]]}).encode())
    h1, T1 = read_handle_file(tmp_path / "h.csv", len(V))
    h2, T2 = read_handle_file(tmp_path / "h.json", len(V))
    assert h1.tolist() == h2.tolist() == [3, 7] and np.array_equal(T1, T2)
    status = np.ones(len(V), int)
    status[:5] = 2
    (tmp_path / "s.sel").write_bytes(BOM + "".join(f"{s}\n" for s in status).encode())
    assert np.array_equal(read_sel(tmp_path / "s.sel", len(V)), status)

"""Every reader of a file given by a user refuses what is no regular file, in one line,
without blocking: a FIFO, a folder, a link to ``/dev/zero``; and a mesh reader reads no
more than its header promises: a sparse file of 2 GB named as a mesh is refused from its
first bytes (sshade/json_file.py ``regular_file``, sshade/mesh/io.py)."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env


def _readers():
    from sshade.animate import read_animation_npz as read_animation
    from sshade.mesh.gltf import read_glb_animation
    from sshade.mesh.handle_files import read_def, read_dmat_selection, read_handle_file, read_sel
    from sshade.mesh.io import read_mesh
    return {".obj": read_mesh, ".off": read_mesh, ".ply": read_mesh, ".stl": read_mesh,
            ".npz": read_animation, ".glb": read_glb_animation, ".sel": lambda p: read_sel(p, 10),
            ".dmat": lambda p: read_dmat_selection(p, 10), ".def": read_def,
            ".json": lambda p: read_handle_file(p, 10), ".csv": lambda p: read_handle_file(p, 10)}


def _hostile(tmp_path, kind: str, ext: str):
    p = tmp_path / f"{kind}{ext}"
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "folder":
        p.mkdir()
    else:
        if not os.path.exists("/dev/zero"):
            pytest.skip("no /dev/zero on this machine")
        p.symlink_to("/dev/zero")
    return p


@pytest.mark.parametrize("kind", ["fifo", "folder", "devzero"])
def test_every_reader_refuses_what_is_no_regular_file_in_one_line_without_blocking(tmp_path, kind):
    if not hasattr(os, "mkfifo"):
        pytest.skip("no FIFOs on this system")
    for ext, read in _readers().items():
        p = _hostile(tmp_path, kind, ext)
        with pytest.raises(SShaDeError) as e:
            read(p)
        msg = str(e.value)
        assert str(p) in msg and "\n" not in msg and "not found" not in msg, (ext, msg)
        assert {"fifo": "FIFO", "folder": "a folder", "devzero": "device"}[kind] in msg, (ext, msg)


def test_the_frames_option_refuses_a_fifo_without_blocking(tmp_path):
    """``python -m sshade animate ... --frames fifo.npy`` ends with one error line."""
    from sshade.mesh.io import write_mesh
    os.mkfifo(tmp_path / "frames.npy")
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    F = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    write_mesh(tmp_path / "m.ply", V, F)
    (tmp_path / "h.json").write_text('{"handles": [0, 1]}')
    r = subprocess.run([sys.executable, "-m", "sshade", "animate", str(tmp_path / "m.ply"), "--handles",
                        str(tmp_path / "h.json"), "--frames", str(tmp_path / "frames.npy"), "-o",
                        str(tmp_path / "out.npz")], cwd=ROOT, env=subprocess_env(), capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "FIFO" in r.stderr and r.stderr.strip().count("\n") == 0, r.stderr


@pytest.mark.parametrize("ext, head", [(".off", b"OFF\n4 4 0\n"), (".obj", b"v 0 0 0\n"), (".ply", b""),
                                       (".ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 4\n"
                                                b"property float x\nproperty float y\nproperty float z\n"
                                                b"element face 4\nproperty list uchar int vertex_indices\n"
                                                b"end_header\n"),
                                       (".stl", b"solid x\n")])
def test_a_sparse_2gb_mesh_is_refused_from_its_first_bytes_in_bounded_memory(tmp_path, ext, head):
    p = tmp_path / f"sparse{ext}"
    with open(p, "wb") as fh:
        fh.write(head)
        fh.truncate(2 ** 31)
    code = ("import resource, sys\nfrom sshade.mesh.io import read_mesh\nfrom sshade.errors import SShaDeError\n"
            "base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
            f"try:\n    read_mesh({str(p)!r})\nexcept SShaDeError as e:\n    print(e)\n"
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base)")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=subprocess_env(), capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr[-2000:]
    msg, rss_kib = r.stdout.strip().splitlines()
    assert str(p) in msg and ("NUL" in msg or "more than its header" in msg), msg
    assert int(rss_kib) < 64 * 1024, f"{int(rss_kib) / 1024:.0f} MiB more than the import's"


@pytest.mark.parametrize("ext", [".npz", ".glb", ".sel", ".dmat", ".def", ".json", ".csv", "manifest"])
def test_every_other_reader_refuses_a_sparse_2gb_file_in_bounded_memory(tmp_path, ext):
    """Animations, handle files and a DeFAUST manifest (sshade.json_file.read_json) given a
    sparse 2 GB file: one line, and less than 64 MiB above the readers' import."""
    p = tmp_path / ("manifest.json" if ext == "manifest" else f"sparse{ext}")
    with open(p, "wb") as fh:
        fh.truncate(2 ** 31)
    call = {"manifest": f"read_json({str(p)!r})"}.get(ext, f"_readers()[{ext!r}]({str(p)!r})")
    code = ("import resource\nfrom tests.test_regular_files import _readers\nfrom sshade.json_file import read_json\n"
            "from sshade.errors import SShaDeError\nr = _readers()\n"
            "base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
            f"try:\n    {call}\nexcept (SShaDeError, OSError, ValueError) as e:\n"
            "    print(str(e).replace(chr(10), ' '))\n"
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base)")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=subprocess_env(), capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    msg, rss_kib = r.stdout.strip().splitlines()
    assert str(p.name) in msg or "larger than" in msg, msg
    assert int(rss_kib) < 64 * 1024, f"{int(rss_kib) / 1024:.0f} MiB more than the import's"

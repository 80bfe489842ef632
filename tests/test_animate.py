"""sshade/animate.py (``python -m sshade animate``): frames from targets or matrices, as
the prepared solves give them, into an .npz or one mesh per frame; outputs it did not write
are refused before any work, with one error line."""
from __future__ import annotations

import json

import numpy as np
import pytest

from sshade import prepare
from sshade.animate import NPZ_KEY
from sshade.cli import main
from sshade.mesh.handle_files import write_sel
from sshade.mesh.io import read_mesh

from .conftest import SHARED_DATA

MESH = SHARED_DATA / "faust_reg" / "tr_reg_000.ply"
KW = ["--n-low", "300", "--k", "2", "--seed", "3"]


@pytest.fixture(scope="module")
def body():
    if not MESH.is_file():
        pytest.skip(f"FAUST registration not found: {MESH}")
    V, F = read_mesh(MESH)
    V2, _ = read_mesh(MESH.with_name("tr_reg_001.ply"))
    return V, F, np.arange(0, len(V), 53), V2


def _lines(capsys):
    return [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]


def test_npz_frames_are_the_prepared_solves_and_a_folder_holds_the_same_meshes(body, tmp_path, capsys):
    V, F, h, V2 = body
    T = np.stack([V[h] + t * (V2[h] - V[h]) for t in (0.25, 0.5, 1.0)])
    (tmp_path / "h.json").write_text(json.dumps({"handles": h.tolist(), "targets": V[h].tolist()}))
    np.save(tmp_path / "frames.npy", T)
    args = [str(MESH), "--handles", str(tmp_path / "h.json"), "--frames", str(tmp_path / "frames.npy"), *KW]
    assert main(["animate", *args, "-o", str(tmp_path / "a.npz")]) == 0
    z = np.load(tmp_path / "a.npz")
    assert z["V"].shape == (3, len(V), 3) and np.array_equal(z["F"], F) and NPZ_KEY in z.files
    p = prepare(V, F, h, n_low=300, n_samplings=2, seed=3)
    for i in range(3):
        assert np.array_equal(z["V"][i], p.solve(T[i]))
    assert main(["animate", *args, "-o", str(tmp_path / "frames_out"), "--format", "obj"]) == 0
    for i in range(3):
        U, G = read_mesh(tmp_path / "frames_out" / f"frame_{i:04d}.obj")
        assert np.array_equal(U, z["V"][i]) and np.array_equal(G, F)
    assert main(["animate", *args, "-o", str(tmp_path / "a.npz")]) == 0  # its own earlier output: replaced


def test_matrices_move_the_handle_region_of_a_selection(body, tmp_path):
    V, F, _, _ = body
    status = np.ones(len(V), int)
    status[V[:, 1] < np.quantile(V[:, 1], 0.1)] = 0  # feet fixed
    status[V[:, 1] > np.quantile(V[:, 1], 0.95)] = 2  # head moved
    write_sel(tmp_path / "s.sel", status)
    M = np.repeat(np.eye(4)[None], 2, axis=0)
    M[1, :3, 3] = [0.05, 0.0, 0.0]  # frame 1: the head 5 cm sideways
    np.save(tmp_path / "m.npy", M)
    assert main(["animate", str(MESH), "--sel", str(tmp_path / "s.sel"), "--frames", str(tmp_path / "m.npy"),
                 *KW, "-o", str(tmp_path / "m.npz")]) == 0
    U = np.load(tmp_path / "m.npz")["V"]
    np.testing.assert_allclose(U[0], V, atol=1e-12)  # the identity frame: the rest pose (rigid)
    head, feet = status == 2, status == 0
    np.testing.assert_allclose(U[1][head], V[head] + [0.05, 0, 0], atol=1e-12)
    np.testing.assert_allclose(U[1][feet], V[feet], atol=1e-12)


def test_outputs_it_did_not_write_and_bad_frames_are_one_error_line(body, tmp_path, capsys):
    V, F, h, _ = body
    (tmp_path / "h.json").write_text(json.dumps({"handles": h.tolist(), "targets": V[h].tolist()}))
    np.save(tmp_path / "f.npy", np.repeat(V[h][None], 2, axis=0))
    args = [str(MESH), "--handles", str(tmp_path / "h.json"), "--frames", str(tmp_path / "f.npy"), *KW]
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    before = other.read_bytes()
    assert main(["animate", *args, "-o", str(other)]) == 2
    assert other.read_bytes() == before and len(_lines(capsys)) == 1
    (tmp_path / "folder").mkdir()
    (tmp_path / "folder" / "notes.txt").write_text("mine")
    assert main(["animate", *args, "-o", str(tmp_path / "folder")]) == 2
    assert _lines(capsys)[0].startswith("error: output folder") and (tmp_path / "folder" / "notes.txt").exists()
    np.save(tmp_path / "bad.npy", np.zeros((2, len(h) + 1, 3)))
    bad = [str(MESH), "--handles", str(tmp_path / "h.json"), "--frames", str(tmp_path / "bad.npy"), *KW]
    assert main(["animate", *bad, "-o", str(tmp_path / "x.npz")]) == 2
    err = _lines(capsys)
    assert len(err) == 1 and err[0].startswith("error:") and not (tmp_path / "x.npz").exists()


def _args(tmp_path, V, h, T):
    (tmp_path / "h.json").write_text(json.dumps({"handles": h.tolist(), "targets": V[h].tolist()}))
    np.save(tmp_path / "frames.npy", T)
    return [str(MESH), "--handles", str(tmp_path / "h.json"), "--frames", str(tmp_path / "frames.npy"), *KW]


def test_a_nan_in_frame_3_is_named_with_the_file_and_frame_before_any_solve(body, tmp_path, capsys, monkeypatch):
    V, F, h, _ = body
    T = np.repeat(V[h][None], 5, axis=0)
    T[3, 7, 1] = np.nan
    args = _args(tmp_path, V, h, T)
    monkeypatch.setattr("sshade.animate.prepare", lambda *a, **k: pytest.fail("prepared before the frames checked"))
    assert main(["animate", *args, "-o", str(tmp_path / "x.npz")]) == 2
    err = _lines(capsys)
    assert len(err) == 1 and "frames.npy: frame 3, row 7 is not finite" in err[0]
    assert not (tmp_path / "x.npz").exists()


def test_an_npz_given_as_frames_is_named_as_an_archive_with_its_arrays(body, tmp_path, capsys):
    V, F, h, _ = body
    args = _args(tmp_path, V, h, np.repeat(V[h][None], 2, axis=0))
    np.savez(tmp_path / "frames.npz", targets=np.zeros((2, len(h), 3)), extra=np.zeros(3))
    args[4] = str(tmp_path / "frames.npz")
    assert main(["animate", *args, "-o", str(tmp_path / "x.npz")]) == 2
    err = _lines(capsys)
    assert len(err) == 1 and "an .npz archive (arrays targets, extra); --frames takes one .npy" in err[0]


@pytest.mark.parametrize("out", ["a.npz", "folder"])
def test_an_interrupted_animation_keeps_its_solved_frames_whole_and_says_so(body, tmp_path, capsys, monkeypatch, out):
    from sshade.prepared import Prepared
    V, F, h, V2 = body
    T = np.stack([V[h] + t * (V2[h] - V[h]) for t in (0.25, 0.5, 0.75, 1.0)])
    args = _args(tmp_path, V, h, T)
    solve, calls = Prepared.solve, []

    def stop_at_third(self, targets, **kw):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return solve(self, targets, **kw)
    monkeypatch.setattr(Prepared, "solve", stop_at_third)
    assert main(["animate", *args, "-o", str(tmp_path / out)]) == 130
    err = _lines(capsys)
    assert any("2 of 4 frames written (frames 0-1, whole)" in ln for ln in err)
    p = prepare(V, F, h, n_low=300, n_samplings=2, seed=3)
    expect = [solve(p, T[i]) for i in range(2)]
    if out == "a.npz":
        z = np.load(tmp_path / out)
        assert z["V"].shape == (2, len(V), 3) and not z["complete"] and int(z["n_frames_planned"]) == 4
        assert len(z["frame_s"]) == 2 and all(np.array_equal(z["V"][i], expect[i]) for i in range(2))
    else:
        files = sorted(q.name for q in (tmp_path / out).iterdir())
        assert files == ["frame_0000.obj", "frame_0001.obj"]
        assert np.array_equal(read_mesh(tmp_path / out / "frame_0001.obj")[0], expect[1])
    assert not [q for q in tmp_path.iterdir() if q.name.startswith(".")]  # no temporary file left


def test_frames_stream_to_the_npz_without_holding_the_animation(tmp_path):
    """200 frames of 10,000 vertices (48 MB): the sink's peak allocation is its 1 MiB copy
    block and a frame or two, not the animation (before: the whole (f, n, 3) array, copied
    again to be written)."""
    import tracemalloc
    from types import SimpleNamespace

    from sshade.animate import _FrameSink
    n, f = 10_000, 200
    F = np.array([[0, 1, 2]])
    frame = np.random.default_rng(0).normal(size=(n, 3))
    tracemalloc.start()
    with _FrameSink(SimpleNamespace(out=str(tmp_path / "a.npz"), format="obj"), F, f, n, print) as sink:
        for i in range(f):
            sink.add(frame + i, 0.01)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 3 * 2 ** 20 < f * frame.nbytes / 8
    z = np.load(tmp_path / "a.npz")
    assert z["V"].shape == (f, n, 3) and bool(z["complete"]) and np.array_equal(z["V"][57], frame + 57)


def test_replacing_an_earlier_animations_frames_says_so(body, tmp_path, capsys):
    V, F, h, _ = body
    args = _args(tmp_path, V, h, np.repeat(V[h][None], 3, axis=0))
    assert main(["animate", *args, "-o", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    args = _args(tmp_path, V, h, np.repeat(V[h][None], 2, axis=0))
    assert main(["animate", *args, "-o", str(tmp_path / "out")]) == 0
    assert "replacing 3 frame file(s) of an earlier animation" in capsys.readouterr().out
    assert sorted(q.name for q in (tmp_path / "out").iterdir()) == ["frame_0000.obj", "frame_0001.obj"]

"""sshade/animate.py (``python -m sshade animate``): frames from targets or matrices, as
the prepared solves give them, into an .npz, a .glb (glTF morph targets) or one mesh per
frame; outputs it did not write are refused before any work, with one error line."""
from __future__ import annotations

import json

import numpy as np
import pytest

from sshade import prepare
from sshade.animate import NPZ_KEY
from sshade.deform_command import main
from sshade.mesh.gltf import glb_extras, read_glb_animation
from sshade.mesh.handle_files import write_sel
from sshade.mesh.io import read_mesh

from .conftest import SHARED_DATA
from .optional import optional_import

MESH = SHARED_DATA / "faust_reg" / "tr_reg_000.ply"
KW = ["--n-low", "300", "--k", "2", "--seed", "3"]
EPS32 = float(np.finfo(np.float32).eps)


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


def test_a_text_file_as_frames_is_named_as_not_a_npy_file(body, tmp_path, capsys):
    V, F, h, _ = body
    args = _args(tmp_path, V, h, np.repeat(V[h][None], 2, axis=0))
    (tmp_path / "frames.txt").write_text("0 0 0\n1 1 1\n")
    args[4] = str(tmp_path / "frames.txt")
    assert main(["animate", *args, "-o", str(tmp_path / "x.npz")]) == 2
    err = _lines(capsys)
    assert len(err) == 1 and "frames.txt: not a .npy file (it starts with b'0 0 0\\n')" in err[0], err
    assert "pickled" not in err[0]


@pytest.mark.parametrize("out", ["a.npz", "a.glb", "folder"])
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
    elif out == "a.glb":
        g = read_glb_animation(tmp_path / out)
        assert g.n_frames == 2 and len(g.targets) == 2 and g.extras["complete"] is False
        assert g.extras["n_frames_planned"] == 4 and len(g.extras["frame_s"]) == 2
        assert all(np.abs(g.frame(i) - expect[i]).max() <= 2 * EPS32 * np.abs(V).max() for i in range(2))
    else:
        files = sorted(q.name for q in (tmp_path / out).iterdir())
        assert files == ["frame_0000.obj", "frame_0001.obj"]
        assert np.array_equal(read_mesh(tmp_path / out / "frame_0001.obj")[0], expect[1])
    assert not [q for q in tmp_path.iterdir() if q.name.startswith(".")]  # no temporary file left


@pytest.mark.parametrize("out", ["a.npz", "a.glb"])
def test_frames_stream_to_the_file_without_holding_the_animation(tmp_path, out):
    """200 frames of 10,000 vertices (48 MB): the sink's peak allocation is its 1 MiB copy
    block and a frame or two, not the animation (before: the whole (f, n, 3) array, copied
    again to be written)."""
    import tracemalloc

    from sshade.animate import _FrameSink
    n, f = 10_000, 200
    F = np.array([[0, 1, 2]])
    frame = np.random.default_rng(0).normal(size=(n, 3))
    tracemalloc.start()
    with _FrameSink(tmp_path / out, "obj", F, f, n, print, rest=frame) as sink:
        for i in range(f):
            sink.add(frame + i, 0.01)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 3 * 2 ** 20 < f * frame.nbytes / 8
    if out == "a.npz":
        z = np.load(tmp_path / out)
        assert z["V"].shape == (f, n, 3) and bool(z["complete"]) and np.array_equal(z["V"][57], frame + 57)
    else:
        g = read_glb_animation(tmp_path / out)
        assert g.n_frames == f and g.extras["complete"] is True
        assert np.abs(g.frame(57) - (frame + 57)).max() <= 2 * EPS32 * np.abs(frame + 57).max()


def test_replacing_an_earlier_animations_frames_says_so(body, tmp_path, capsys):
    V, F, h, _ = body
    args = _args(tmp_path, V, h, np.repeat(V[h][None], 3, axis=0))
    assert main(["animate", *args, "-o", str(tmp_path / "out")]) == 0
    capsys.readouterr()
    args = _args(tmp_path, V, h, np.repeat(V[h][None], 2, axis=0))
    assert main(["animate", *args, "-o", str(tmp_path / "out")]) == 0
    assert "replacing 3 frame file(s) of an earlier animation" in capsys.readouterr().out
    assert sorted(q.name for q in (tmp_path / "out").iterdir()) == ["frame_0000.obj", "frame_0001.obj"]


def test_a_glb_holds_the_npz_frames_to_float32_precision_and_is_replaced_only_when_sshade_wrote_it(
        body, tmp_path, capsys):
    trimesh = optional_import("trimesh", how="a dependency: pip install -e .")
    V, F, h, V2 = body
    T = np.stack([V[h] + t * (V2[h] - V[h]) for t in (0.0, 0.5, 1.0)])
    args = _args(tmp_path, V, h, T)
    assert main(["animate", *args, "-o", str(tmp_path / "a.npz"), "--fps", "30"]) == 0
    assert main(["animate", *args, "-o", str(tmp_path / "a.glb"), "--fps", "30"]) == 0
    z, g = np.load(tmp_path / "a.npz"), read_glb_animation(tmp_path / "a.glb")
    assert float(z["fps"]) == 30.0 and np.array_equal(g.F, z["F"])
    assert np.array_equal(g.base, V.astype(np.float32))  # the base positions: the rest mesh
    for i in range(3):
        assert np.abs(g.frame(i) - z["V"][i]).max() <= 2 * EPS32 * np.abs(z["V"][i]).max()
    assert np.allclose(g.times, np.arange(3) / 30.0, rtol=1e-7, atol=0)
    ex = glb_extras(tmp_path / "a.glb")
    assert ex[NPZ_KEY] == 1 and ex["complete"] is True and ex["n_frames_planned"] == 3 and ex["fps"] == 30.0
    assert main(["animate", *args, "-o", str(tmp_path / "a.glb")]) == 0  # its own earlier output: replaced
    capsys.readouterr()
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "other.glb")  # a .glb sshade did not write
    before = (tmp_path / "other.glb").read_bytes()
    assert main(["animate", *args, "-o", str(tmp_path / "other.glb")]) == 2
    err = _lines(capsys)
    assert len(err) == 1 and "other.glb exists and is not an animation sshade wrote" in err[0]
    assert (tmp_path / "other.glb").read_bytes() == before
    assert main(["animate", *args, "-o", str(tmp_path / "other.glb"), "--force"]) == 0
    assert read_glb_animation(tmp_path / "other.glb").n_frames == 3


@pytest.mark.parametrize("case", ["no pygltflib", "fps 0", "fps 1e308", "fps 1e-300", "too many frames"])
def test_a_glb_that_cannot_be_written_is_one_error_line_before_any_solve(body, tmp_path, capsys, monkeypatch, case):
    V, F, h, _ = body
    n, h = (65536 if case == "too many frames" else 2), h[:2]  # two handles: a 3 MB frames file
    args = _args(tmp_path, V, h, np.broadcast_to(V[h][None], (n, len(h), 3)))
    if case == "no pygltflib":
        monkeypatch.setattr("sshade.mesh.gltf.pygltflib", None)
    monkeypatch.setattr("sshade.animate.prepare", lambda *a, **k: pytest.fail("prepared before the output checked"))
    extra = ["--fps", case.split()[1]] if case.startswith("fps") else []
    assert main(["animate", *args, "-o", str(tmp_path / "x.glb"), *extra]) == 2
    err = _lines(capsys)
    says = {"no pygltflib": "needs pygltflib, a dependency of sshade: pip install -e .",
            "fps 0": "--fps must be a number in [0.001, 10000], got 0.0",
            "fps 1e308": "--fps must be a number in [0.001, 10000], got 1e+308",
            "fps 1e-300": "--fps must be a number in [0.001, 10000], got 1e-300",
            "too many frames": "x.glb: a .glb holds at most 65535 frames, the frames file has 65536"}[case]
    assert len(err) == 1 and err[0].startswith("error:") and says in err[0], err
    assert sorted(q.name for q in tmp_path.iterdir()) == ["frames.npy", "h.json"]

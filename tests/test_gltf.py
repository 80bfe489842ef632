"""sshade/mesh/gltf.py: an animation written as glTF 2.0 binary and read back by pygltflib
and trimesh (independent readers): one morph target per frame, base + target i = frame i to
float32 precision, min/max on every POSITION accessor, an animation with a keyframe per
frame playing the targets in order; a damaged file is one SShaDeError naming the file and
the place. (The Khronos glTF validator is not run: it is not installed here.)"""
from __future__ import annotations

import json
import os
import struct

import numpy as np
import pytest

from sshade.errors import SShaDeError
from sshade.mesh.gltf import GlbAnimationWriter, glb_extras, read_glb_animation
from sshade.mesh.io import read_mesh

from .conftest import SHARED_DATA, icosphere
from .optional import optional_import

BUNNY = SHARED_DATA / "classic" / "bunny.off"
EPS32 = float(np.finfo(np.float32).eps)


@pytest.fixture(scope="module")
def bunny_frames():
    """The bunny and 6 frames twisting it about the vertical axis, more each frame."""
    if not BUNNY.is_file():
        pytest.skip(f"bunny not found: {BUNNY}")
    V, F = read_mesh(BUNNY)
    frames = []
    for t in np.linspace(0.0, 1.0, 6):
        a = t * (V[:, 1] - V[:, 1].min()) / np.ptp(V[:, 1]) * np.pi / 2
        c, s = np.cos(a), np.sin(a)
        frames.append(np.stack([c * V[:, 0] + s * V[:, 2], V[:, 1] + 0.01 * t, -s * V[:, 0] + c * V[:, 2]], 1))
    return V, F, np.stack(frames)


def _write(path, V, F, frames, fps=12.0):
    with GlbAnimationWriter(path, V, F, fps=fps) as w:
        for U in frames:
            w.add(U)
        w.finish({"sshade_animation": 1, "fps": fps})


def _decode(doc, blob, i):
    """Accessor ``i`` through pygltflib's document (tightly packed: a byteStride, where
    given, is the element's own size)."""
    a = doc.accessors[i]
    dt = {5125: np.uint32, 5126: np.float32}[a.componentType]
    width = {"SCALAR": 1, "VEC3": 3}[a.type]
    if a.bufferView is None:
        out = np.zeros(a.count * width, dt)
    else:
        v = doc.bufferViews[a.bufferView]
        assert v.byteStride in (None, width * np.dtype(dt).itemsize)
        out = np.frombuffer(blob, dt, a.count * width, v.byteOffset + (a.byteOffset or 0)).copy()
    if a.sparse is not None:
        s = a.sparse
        idx = np.frombuffer(blob, np.uint32, s.count, doc.bufferViews[s.indices.bufferView].byteOffset)
        out.reshape(-1, width)[idx] = np.frombuffer(blob, dt, s.count * width,
                                                   doc.bufferViews[s.values.bufferView].byteOffset).reshape(-1, width)
    return out.reshape(a.count, width) if width > 1 else out


def test_pygltflib_and_trimesh_read_base_plus_target_i_as_frame_i_and_f_keyframes(bunny_frames, tmp_path):
    pygltflib = optional_import("pygltflib", how="a dependency: pip install -e .")
    trimesh = optional_import("trimesh", how="a dependency: pip install -e .")
    V, F, frames = bunny_frames
    f = len(frames)
    _write(tmp_path / "a.glb", V, F, frames)
    doc = pygltflib.GLTF2().load_binary(str(tmp_path / "a.glb"))
    blob = doc.binary_blob()
    (mesh,) = doc.meshes
    (prim,) = mesh.primitives
    assert prim.mode == pygltflib.TRIANGLES and len(prim.targets) == f
    assert mesh.extras["targetNames"] == [f"frame_{i:04d}" for i in range(f)]
    base = _decode(doc, blob, prim.attributes.POSITION)
    assert np.array_equal(base, V.astype(np.float32))  # the base is the rest mesh
    assert np.array_equal(_decode(doc, blob, prim.indices).reshape(-1, 3), F)
    for i, target in enumerate(prim.targets):
        U = base + _decode(doc, blob, target["POSITION"])  # float32, as a player adds them
        assert np.abs(U - frames[i]).max() <= 2 * EPS32 * np.abs(frames[i]).max(), i
    for i in [prim.attributes.POSITION] + [t["POSITION"] for t in prim.targets]:  # required by the spec
        a, X = doc.accessors[i], _decode(doc, blob, i)
        assert a.min == X.min(axis=0).tolist() and a.max == X.max(axis=0).tolist(), i
    (anim,) = doc.animations
    (channel,) = anim.channels
    assert channel.target.path == "weights" and doc.nodes[channel.target.node].mesh == 0
    sampler = anim.samplers[channel.sampler]
    times = _decode(doc, blob, sampler.input)
    assert sampler.interpolation == "LINEAR" and np.array_equal(times, (np.arange(f) / 12.0).astype(np.float32))
    assert doc.accessors[sampler.input].min == [0.0] and doc.accessors[sampler.input].max == [float(times[-1])]
    weights = _decode(doc, blob, sampler.output).reshape(f, f)
    assert np.array_equal(weights, np.eye(f))  # keyframe i: frame i alone
    assert doc.asset.version == "2.0" and doc.asset.extras == {"sshade_animation": 1, "fps": 12.0}

    scene = trimesh.load(tmp_path / "a.glb", process=False)
    (geometry,) = scene.geometry.values()  # trimesh reads the base mesh, not the targets
    assert np.array_equal(geometry.vertices, base.astype(np.float64)) and np.array_equal(geometry.faces, F)

    ours = read_glb_animation(tmp_path / "a.glb")
    assert ours.n_frames == f and np.array_equal(ours.times, times.astype(np.float64))
    assert max(np.abs(ours.frame(i) - frames[i]).max() for i in range(f)) <= 2 * EPS32 * np.abs(frames).max()
    assert glb_extras(tmp_path / "a.glb") == {"sshade_animation": 1, "fps": 12.0}


def test_a_writer_left_without_finish_writes_nothing(tmp_path):
    V, F = np.eye(3), np.array([[0, 1, 2]])
    with pytest.raises(KeyboardInterrupt), GlbAnimationWriter(tmp_path / "a.glb", V, F, fps=24) as w:
        w.add(V)
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []  # no .glb, no temporary file


def _glb(path) -> tuple[dict, bytes]:
    data = path.read_bytes()
    (jlen,) = struct.unpack("<I", data[12:16])
    return json.loads(data[20:20 + jlen]), data[20 + jlen:]


def _rewrite(path, doc: dict, tail: bytes) -> None:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    path.write_bytes(b"glTF" + struct.pack("<III", 2, 20 + len(text) + len(tail), len(text)) + b"JSON" + text + tail)


def _damage(kind, path):
    doc, tail = _glb(path)
    if kind == "cut":
        path.write_bytes(path.read_bytes()[:-100])
    elif kind == "not glTF":
        path.write_text("v 0 0 0\n")
    elif kind == "accessor":
        doc["accessors"][3]["byteOffset"] = 10 ** 9
        _rewrite(path, doc, tail)
    elif kind == "faces":
        tail = tail[:8] + struct.pack("<I", 10 ** 6) + tail[12:]  # the first index of the first face
        _rewrite(path, doc, tail)
    elif kind == "nan":
        view = doc["bufferViews"][2]["byteOffset"] + 12 * 3  # target 1 (after target 0's 3 vertices), vertex 0
        tail = tail[:8 + view] + struct.pack("<f", float("nan")) + tail[8 + view + 4:]
        _rewrite(path, doc, tail)
    elif kind == "times":  # the weights (mostly 0) as keyframe times
        doc["animations"][0]["samplers"][0]["input"] = doc["animations"][0]["samplers"][0]["output"]
        _rewrite(path, doc, tail)
    elif kind == "zeros":  # a 2.4 GB position accessor claimed by a small file (no bufferView: all zeros)
        doc["accessors"][1].pop("bufferView")
        doc["accessors"][1].pop("byteOffset", None)
        doc["accessors"][1]["count"] = 200_000_000
        _rewrite(path, doc, tail)
    elif kind == "weights":  # the keyframe times as weights
        doc["animations"][0]["samplers"][0]["output"] = doc["animations"][0]["samplers"][0]["input"]
        _rewrite(path, doc, tail)


@pytest.mark.parametrize("kind, says", [
    ("cut", "its header gives"), ("not glTF", "not a glTF binary"),
    ("accessor", "accessor 3 (morph target 1 POSITION): 3 elements of 12 bytes every 12 from byte 1000000000"),
    ("faces", "mesh 0 faces"),
    ("zeros", "accessor 1 (POSITION): 200000000 elements without a bufferView (2400000000 bytes of zeros)"),
    ("nan", "mesh 0 morph target 1: NaN or inf"),
    ("times", "animation 0 channel 0: keyframe times not finite and increasing"),
    ("weights", "animation 0 channel 0: 3 weights for 1 x 3 keyframes x 3 targets")])
def test_a_damaged_glb_is_one_error_naming_the_file_and_the_place(tmp_path, kind, says):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2]])
    _write(tmp_path / "a.glb", V, F, [V, V * 2, V * 3])
    _damage(kind, tmp_path / "a.glb")
    with pytest.raises(SShaDeError) as e:
        read_glb_animation(tmp_path / "a.glb")
    msg = str(e.value)
    assert msg.startswith(f"{tmp_path / 'a.glb'}: ") and says in msg and "\n" not in msg, msg


def test_any_byte_of_the_json_changed_is_read_or_refused_with_an_sshade_error(tmp_path):
    """200 mutations of the JSON chunk (a character replaced by another of the document's):
    each file is read, or refused with SShaDeError, never another exception."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    _write(tmp_path / "a.glb", V, np.array([[0, 1, 2]]), [V, V * 2])
    data = (tmp_path / "a.glb").read_bytes()
    (jlen,) = struct.unpack("<I", data[12:16])
    rng = np.random.default_rng(0)
    alphabet = sorted(set(data[20:20 + jlen]))
    refused = 0
    for _ in range(200):
        b = bytearray(data)
        b[20 + rng.integers(jlen)] = alphabet[rng.integers(len(alphabet))]
        (tmp_path / "m.glb").write_bytes(bytes(b))
        try:
            read_glb_animation(tmp_path / "m.glb")
        except SShaDeError:
            refused += 1
    assert refused > 50


def test_a_killed_writers_frames_file_is_removed_by_the_next_writer_and_a_live_ones_kept(tmp_path):
    V, F = np.eye(3), np.array([[0, 1, 2]])
    dead = tmp_path / ".a.glb.99999999.x1.frames"  # above any pid_max: no such process
    live = tmp_path / f".a.glb.{os.getppid()}.x2.frames"
    dead.write_bytes(b"\0" * 1000)
    live.write_bytes(b"\0" * 10)
    _write(tmp_path / "a.glb", V, F, [V, V * 2])
    assert not dead.exists() and live.exists() and (tmp_path / "a.glb").is_file()


VALIDATE_JS = """
const fs = require('fs'); const v = require('gltf-validator');
v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[1]))).then(r => {
  console.log(JSON.stringify({errors: r.issues.numErrors, warnings: r.issues.numWarnings,
                              messages: r.issues.messages.slice(0, 5)}));
}).catch(e => { console.error(String(e)); process.exit(3); });
"""


def _gltf_validator_env() -> dict:
    """The environment in which ``node`` finds the Khronos glTF-Validator (npm package
    ``gltf-validator``: ``$GLTF_VALIDATOR_NODE_PATH``, else npm's global root), or skip
    with one line when node or the package is absent."""
    import shutil
    import subprocess
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not on PATH: the Khronos glTF-Validator runs on it (Debian: apt-get install nodejs npm; "
                    "npm install -g gltf-validator); .ci/run installs both and reruns the tests marked 'gltf'")
    paths = [os.environ.get("GLTF_VALIDATOR_NODE_PATH", "")]
    if shutil.which("npm"):
        r = subprocess.run(["npm", "root", "-g"], capture_output=True, text=True, timeout=60)
        paths.append(r.stdout.strip())
    env = dict(os.environ, NODE_PATH=os.pathsep.join(p for p in paths if p))
    r = subprocess.run([node, "-e", "require.resolve('gltf-validator')"], env=env, capture_output=True, timeout=60)
    if r.returncode != 0:
        pytest.skip("the npm package gltf-validator is not installed (npm install -g gltf-validator); .ci/run "
                    "installs it and reruns the tests marked 'gltf'")
    return env


@pytest.mark.gltf
def test_the_khronos_validator_reports_no_error_and_no_warning_on_an_animation(tmp_path):
    import subprocess
    env = _gltf_validator_env()
    V, F = icosphere()
    _write(tmp_path / "a.glb", V, F, [V * (1 + 0.01 * i) for i in range(24)])
    r = subprocess.run(["node", "-e", VALIDATE_JS, str(tmp_path / "a.glb")], env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    report = json.loads(r.stdout)
    assert report["errors"] == 0 and report["warnings"] == 0, report

"""glTF 2.0 binary (``.glb``) animations of one triangle mesh: the mesh, one morph target
per frame, one animation whose ``weights`` channel plays them (glTF 2.0 specification:
"Morph Targets", "Animations", "GLB File Format").

:class:`GlbAnimationWriter` (frames in, a ``.glb`` out, atomically),
:func:`read_glb_animation` (a :class:`GlbAnimation`, its arrays memory-mapped),
:func:`glb_extras`, :func:`check_glb_output`. pygltflib builds and parses the JSON; the
binary chunk is streamed and mapped here, so neither side holds the animation in memory.
"""
from __future__ import annotations

import contextlib
import glob
import mmap
import os
import shutil
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import SShaDeError
from ..files import atomic_write
from ..json_file import loads, regular_file
from .bounds import bounding_box
from .validate import check_faces

try:  # a dependency; an environment installed before it became one may lack it
    import pygltflib
except ImportError:
    pygltflib = None

__all__ = ["GlbAnimationWriter", "frames_tempfile", "GlbAnimation", "read_glb_animation", "glb_extras",
           "check_glb_output", "MAX_FRAMES"]

#: The most frames a .glb holds: the one-hot keyframe weights are a sparse accessor of
#: f * f scalars whose indices are 32-bit.
MAX_FRAMES = 65535
_MAGIC, _JSON, _BIN = b"glTF", 0x4E4F534A, 0x004E4942
_MAX_BYTES = 2 ** 32 - 1  # a GLB's length field is 32-bit
_JSON_ROOM = 2 ** 26  # what check_glb_output keeps for the JSON chunk (about 1 kB a frame)
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_COMPONENTS = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def _pygltflib():
    if pygltflib is None:
        raise SShaDeError("writing or reading a .glb needs pygltflib, a dependency of sshade: pip install -e . "
                          "(or pip install pygltflib)")
    return pygltflib


def check_glb_output(path, n: int, m: int, f: int) -> None:
    """Raise SShaDeError, naming ``path``, unless pygltflib imports and ``f`` frames of a
    mesh of ``n`` vertices and ``m`` triangles fit one ``.glb`` (at most
    :data:`MAX_FRAMES` frames, 4 GiB): the checks to make before solving any frame."""
    _pygltflib()
    if f > MAX_FRAMES:
        raise SShaDeError(f"{path}: a .glb holds at most {MAX_FRAMES} frames, the frames file has {f}; "
                          "write an .npz or a folder")
    size = 12 * m + 12 * n * (f + 1) + 12 * f
    if size > _MAX_BYTES - _JSON_ROOM:
        raise SShaDeError(f"{path}: {f} frames of {n} vertices take {size / 2 ** 30:.1f} GiB, over the 4 GiB of a "
                          ".glb (glTF's 32-bit lengths); write an .npz or a folder, or fewer frames per file")


class GlbAnimationWriter:
    """Write an animation into ``path`` (``.glb``), a frame at a time.

    The file holds one mesh whose base positions are ``base``, one morph target per frame
    (float32 displacements from the base) and one animation whose ``weights`` channel
    shows frame i at ``i / fps`` seconds. Frames go to a temporary file beside ``path``
    as they come; :meth:`finish` writes the ``.glb`` atomically (nothing is written at
    ``path`` without it). The layout and memory: docs/implementation.md ("Implementation notes:
    sshade/mesh/gltf.py").

    Parameters
    ----------
    path : the ``.glb`` to write; its folder must exist.
    base : (n, 3) float, the base positions. F : (m, 3) int, triangles into ``base``.
    fps : float > 0, frames per second of the keyframe times.

    Raises
    ------
    SShaDeError without pygltflib; OSError when the temporary file cannot be written.

    Examples
    --------
    >>> import pathlib, tempfile, numpy as np
    >>> V, F = np.eye(3), np.array([[0, 1, 2]])
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "a.glb"
    >>> with GlbAnimationWriter(path, V, F, fps=24) as w:
    ...     for t in (0.0, 0.5, 1.0):
    ...         w.add(V + [t, 0, 0])
    ...     w.finish({"note": "three frames"})
    >>> a = read_glb_animation(path)
    >>> a.n_frames, a.frame(2)[0].tolist(), a.extras
    (3, [2.0, 0.0, 0.0], {'note': 'three frames'})
    """

    def __init__(self, path, base, F, *, fps: float):
        self.gltf = _pygltflib()
        self.path, self.fps = Path(path), float(fps)
        self.base = np.ascontiguousarray(base, "<f4")
        self.F = np.ascontiguousarray(F, "<u4")
        self.base64 = self.base.astype(np.float64)  # what a reader adds the targets to
        self.bounds: list = []  # (min, max) of each target
        fd, self.tmp = frames_tempfile(self.path)
        self.fh = os.fdopen(fd, "wb")
        self.F.tofile(self.fh)
        self.base.tofile(self.fh)

    @property
    def n_frames(self) -> int:
        """The frames added so far."""
        return len(self.bounds)

    def add(self, U) -> None:
        """Append a frame: ``U`` (n, 3) float positions, stored as float32 displacements
        from the base."""
        d = (np.asarray(U, np.float64) - self.base64).astype("<f4")
        d.tofile(self.fh)
        self.bounds.append(tuple(c.tolist() for c in bounding_box(d)))

    def finish(self, extras: dict | None = None) -> None:
        """Write the ``.glb`` with the frames added so far (at least one), ``extras`` (a
        JSON-able dict) as its ``asset.extras``. Raises ValueError with no frame,
        SShaDeError when the file would pass 4 GiB, OSError when writing fails."""
        k = self.n_frames
        if not k:
            raise ValueError("a .glb animation needs at least one frame")
        times = (np.arange(k) / self.fps).astype("<f4")
        for tail in (times, (np.arange(k, dtype=np.int64) * (k + 1)).astype("<u4"), np.ones(k, "<f4")):
            tail.tofile(self.fh)
        self.fh.close()
        size = os.path.getsize(self.tmp)
        text = self._document(k, times, size, extras or {}).encode()
        text += b" " * (-len(text) % 4)
        total = 12 + 8 + len(text) + 8 + size
        if total > _MAX_BYTES:
            raise SShaDeError(f"{self.path}: {total / 2 ** 30:.1f} GiB, over the 4 GiB of a .glb")
        with atomic_write(self.path, "wb") as out, open(self.tmp, "rb") as src:
            out.write(_MAGIC + struct.pack("<II", 2, total) + struct.pack("<I", len(text)) + struct.pack("<I", _JSON))
            out.write(text)
            out.write(struct.pack("<II", size, _BIN))  # 4-byte aligned: every block is
            shutil.copyfileobj(src, out, 1 << 20)

    def _document(self, k: int, times: np.ndarray, size: int, extras: dict) -> str:
        """The JSON chunk: bufferViews 0 faces, 1 base, 2 targets, 3 times, 4 and 5 the
        sparse weights' indices and values; accessors 0 faces, 1 base, 2 .. k+1 targets,
        k+2 times, k+3 weights."""
        g, n = self.gltf, len(self.base)
        lengths = [self.F.nbytes, self.base.nbytes, 12 * n * k, 4 * k, 4 * k, 4 * k]
        starts = np.concatenate([[0], np.cumsum(lengths)]).tolist()
        assert starts[-1] == size
        views = [g.BufferView(buffer=0, byteOffset=s, byteLength=ln, target=t) for s, ln, t in
                 zip(starts, lengths, [_ELEMENT_ARRAY_BUFFER, _ARRAY_BUFFER, _ARRAY_BUFFER, None, None, None])]
        views[2].byteStride = 12  # the targets' accessors share this view: glTF wants its stride said
        base_lo, base_hi = bounding_box(self.base)
        acc = [g.Accessor(bufferView=0, componentType=g.UNSIGNED_INT, count=self.F.size, type=g.SCALAR),
               g.Accessor(bufferView=1, componentType=g.FLOAT, count=n, type=g.VEC3,
                          min=base_lo.tolist(), max=base_hi.tolist())]
        acc += [g.Accessor(bufferView=2, byteOffset=12 * n * i, componentType=g.FLOAT, count=n, type=g.VEC3,
                           min=lo, max=hi) for i, (lo, hi) in enumerate(self.bounds)]
        acc += [g.Accessor(bufferView=3, componentType=g.FLOAT, count=k, type=g.SCALAR,
                           min=[float(times[0])], max=[float(times[-1])]),
                g.Accessor(byteOffset=None, componentType=g.FLOAT, count=k * k, type=g.SCALAR, sparse=g.Sparse(
                    count=k, indices=g.AccessorSparseIndices(bufferView=4, componentType=g.UNSIGNED_INT),
                    values=g.AccessorSparseValues(bufferView=5)))]
        prim = g.Primitive(attributes=g.Attributes(POSITION=1), indices=0, mode=g.TRIANGLES,
                           targets=[g.Attributes(POSITION=2 + i) for i in range(k)])
        anim = g.Animation(name="frames", samplers=[g.AnimationSampler(input=k + 2, output=k + 3,
                                                                       interpolation=g.ANIM_LINEAR)],
                           channels=[g.AnimationChannel(sampler=0, target=g.AnimationChannelTarget(
                               node=0, path=g.WEIGHTS))])
        doc = g.GLTF2(asset=g.Asset(generator=f"sshade (pygltflib {g.__version__})", extras=extras), scene=0,
                      scenes=[g.Scene(nodes=[0])], nodes=[g.Node(mesh=0, name="mesh")],
                      meshes=[g.Mesh(primitives=[prim], name="mesh",
                                     extras={"targetNames": [f"frame_{i:04d}" for i in range(k)]})],
                      accessors=acc, bufferViews=views, buffers=[g.Buffer(byteLength=size)], animations=[anim])
        return doc.gltf_to_json(separators=(",", ":"), indent=None)

    def close(self) -> None:
        """Close and remove the temporary file (after :meth:`finish` or instead of it)."""
        self.fh.close()
        Path(self.tmp).unlink(missing_ok=True)

    def __enter__(self) -> GlbAnimationWriter:
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False


def _chunks(path, map_bin: bool = True) -> tuple[bytes, int, int, mmap.mmap | None]:
    """(JSON text, BIN offset, BIN length, the file mapped or None) of a ``.glb``, its
    header and chunk lengths checked against the file's size (``map_bin=False``: the
    JSON chunk only)."""
    p = regular_file(path, "glTF binary")
    try:
        with open(p, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            head = fh.read(20)
            if len(head) < 20 or head[:4] != _MAGIC:
                raise SShaDeError(f"{p}: not a glTF binary (it does not start with 'glTF')")
            version, length, jlen, jtype = struct.unpack("<IIII", head[4:])
            if version != 2:
                raise SShaDeError(f"{p}: glTF binary version {version}; only version 2 is read")
            if length != size:
                raise SShaDeError(f"{p}: its header gives {length} bytes, the file has {size} (cut short?)")
            if jtype != _JSON or 20 + jlen > size:
                raise SShaDeError(f"{p}: byte 12: the first chunk is not a JSON chunk within the file")
            text = fh.read(jlen)
            at = 20 + jlen + (-jlen % 4)
            if not map_bin or at + 8 > size:
                return text, 0, 0, None
            fh.seek(at)
            blen, btype = struct.unpack("<II", fh.read(8))
            if btype != _BIN or at + 8 + blen > size:
                raise SShaDeError(f"{p}: byte {at}: the second chunk is not a BIN chunk within the file")
            return text, at + 8, blen, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except OSError as e:
        raise SShaDeError(f"{p}: cannot read it ({e.strerror or e})") from None


def glb_extras(path) -> dict | None:
    """The ``asset.extras`` dict of the ``.glb`` at ``path`` (only its JSON chunk is
    read), or None: no such file, not a glTF binary, no such dict."""
    try:
        doc = loads(_chunks(path, map_bin=False)[0])
        extras = doc.get("asset", {}).get("extras")
    except (SShaDeError, ValueError, AttributeError, RecursionError):
        return None
    return extras if isinstance(extras, dict) else None


@dataclass
class GlbAnimation:
    """A mesh with morph targets and the keyframes that weight them.

    Attributes
    ----------
    base : (n, 3) float32, the base positions. F : (m, 3) int64, triangles.
    targets : list of t (n, 3) float32, the morph targets' displacements (views of the
    mapped file where it stores them densely).
    times : (f,) float64 keyframe seconds, increasing; None when the file has no animation
    (then frame i is target i). weights : (f, t) scipy.sparse CSR float64.
    extras : dict, the file's ``asset.extras``.
    """
    base: np.ndarray
    F: np.ndarray
    targets: list
    times: np.ndarray | None
    weights: sp.csr_matrix
    extras: dict

    @property
    def n_frames(self) -> int:
        """f, the keyframes (one per target without an animation; 1 without targets)."""
        return self.weights.shape[0]

    def frame(self, i: int) -> np.ndarray:
        """(n, 3) float64, keyframe ``i``'s positions: the base plus its weighted targets."""
        row = self.weights[i]
        U = self.base.astype(np.float64)
        for j, w in zip(row.indices, row.data):
            U += w * self.targets[j]
        return U


def frames_tempfile(path: Path) -> tuple[int, str]:
    """A temporary file beside ``path`` for the frames written before it (``.NAME.PID.*.frames``):
    ``(fd, name)`` as :func:`tempfile.mkstemp`. Those left by processes that no longer run
    (killed before they could remove theirs) are removed first; a live process's are kept."""
    path = Path(path)
    for q in path.parent.glob(f".{glob.escape(path.name)}.*.frames"):
        pid = q.name[len(path.name) + 2:].split(".")[0]
        if pid.isdigit() and not _alive(int(pid)):
            with contextlib.suppress(OSError):
                q.unlink()
    return tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}.", suffix=".frames", dir=path.parent)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


_MIN_ZEROS = 64 << 20  #: bytes of zeros an accessor without a bufferView may stand for, at least


class _Reader:
    """The checks and accessors of :func:`read_glb_animation` for one file."""

    def __init__(self, path, doc, blob, start: int, length: int):
        self.p, self.doc, self.blob, self.start, self.length = Path(path), doc, blob, start, length

    def fail(self, where: str, what: str) -> SShaDeError:
        return SShaDeError(f"{self.p}: {where}: {what}")

    def integer(self, v, where: str, lo: int = 0, hi: int | None = None) -> int:
        if isinstance(v, bool) or not isinstance(v, int) or v < lo or (hi is not None and v >= hi):
            rng = f"in [{lo}, {hi})" if hi is not None else f">= {lo}"
            raise self.fail(where, f"expected an integer {rng}, got {v!r}")
        return v

    def view(self, i, where: str) -> tuple[int, int, int | None]:
        """(start in the mapped file, length, stride) of bufferView ``i``."""
        views = self.doc.bufferViews or []
        i = self.integer(i, f"{where} bufferView", 0, len(views))
        v, w = views[i], f"bufferView {i}"
        self.integer(v.buffer, f"{w} buffer", 0, 1)
        if (self.doc.buffers or [None])[0] is None or self.doc.buffers[0].uri is not None or self.blob is None:
            raise self.fail(w, "its buffer is not the file's BIN chunk (an external or missing buffer)")
        off, ln = self.integer(v.byteOffset or 0, f"{w} byteOffset"), self.integer(v.byteLength, f"{w} byteLength")
        if off + ln > self.length:
            raise self.fail(w, f"bytes {off}-{off + ln} run past the BIN chunk's {self.length}")
        stride = None if v.byteStride is None else self.integer(v.byteStride, f"{w} byteStride", 4, 253)
        return self.start + off, ln, stride

    def head(self, i, what: str, types: tuple, components: tuple):
        """(accessor, its name in errors, width, dtype, count) of accessor ``i``, its type
        and component type checked."""
        acc_list = self.doc.accessors or []
        i = self.integer(i, what + " accessor", 0, len(acc_list))
        a, w = acc_list[i], f"accessor {i} ({what})"
        if a.type not in types or a.componentType not in components or a.normalized:
            raise self.fail(w, f"{a.type} of component type {a.componentType}{' normalized' if a.normalized else ''}"
                               f"; expected {'/'.join(types)} of {'/'.join(map(str, components))}")
        return a, w, _WIDTH[a.type], np.dtype(_COMPONENTS[a.componentType]), self.integer(a.count, f"{w} count", 1)

    def accessor(self, i, what: str, types: tuple, components: tuple) -> np.ndarray:
        """Accessor ``i`` as (count,) or (count, width): a view of the mapped file when it
        is dense (sparse values applied to a copy). ``what`` names it in errors."""
        a, w, width, dt, count = self.head(i, what, types, components)
        if a.bufferView is None:
            need, most = count * width * dt.itemsize, max(_MIN_ZEROS, 8 * (self.start + self.length))
            if need > most:  # zeros the file does not hold: bounded by its size, not by its claim
                raise self.fail(w, f"{count} elements without a bufferView ({need} bytes of zeros), more than "
                                   f"{most} for a file of its size")
            out = np.zeros((count, width), dt)
        else:
            at, ln, stride = self.view(a.bufferView, w)
            off, elem = self.integer(a.byteOffset or 0, f"{w} byteOffset"), width * dt.itemsize
            stride = stride or elem
            if stride < elem or off + (count - 1) * stride + elem > ln:
                raise self.fail(w, f"{count} elements of {elem} bytes every {stride} from byte {off} run past its "
                                   f"bufferView's {ln} bytes")
            raw = np.frombuffer(self.blob, np.uint8, off + (count - 1) * stride + elem, at)
            out = np.lib.stride_tricks.as_strided(raw[off:], (count, elem), (stride, 1)).view(dt)
        if a.sparse is not None:
            idx, vals = self.sparse(a, w, count, width, dt)
            out = np.array(out)
            out[idx] = vals
        return out[:, 0] if a.type == "SCALAR" else out

    def nonzero(self, i, what: str) -> tuple[np.ndarray, np.ndarray, int]:
        """(positions (s,) int64, values (s,) float32, count) of the non-zero elements of the
        float SCALAR accessor ``i``; a sparse accessor without a bufferView is never made
        dense (the one-hot weights of f keyframes: f values, not f * f)."""
        a, w, width, dt, count = self.head(i, what, ("SCALAR",), (5126,))
        if a.bufferView is None and a.sparse is not None:
            idx, vals = self.sparse(a, w, count, width, dt)
            vals = vals.reshape(-1)
        else:
            vals = self.accessor(i, what, ("SCALAR",), (5126,))
            idx = np.flatnonzero(vals)
            vals = vals[idx]
        keep = vals != 0
        return idx[keep], vals[keep], count

    def sparse(self, a, w: str, count: int, width: int, dt) -> tuple[np.ndarray, np.ndarray]:
        """(indices (s,) int64 in [0, count), values (s, width)) of accessor ``a``'s sparse part."""
        s = self.integer(a.sparse.count, f"{w} sparse count", 1)
        ind, val = a.sparse.indices, a.sparse.values
        if ind is None or val is None or ind.componentType not in (5121, 5123, 5125):
            raise self.fail(w, "its sparse part lacks indices/values of an unsigned component type")
        at, ln, _ = self.view(ind.bufferView, f"{w} sparse indices")
        it = np.dtype(_COMPONENTS[ind.componentType])
        o = self.integer(ind.byteOffset or 0, f"{w} sparse indices byteOffset")
        at2, ln2, _ = self.view(val.bufferView, f"{w} sparse values")
        o2 = self.integer(val.byteOffset or 0, f"{w} sparse values byteOffset")
        if o + s * it.itemsize > ln or o2 + s * width * dt.itemsize > ln2:
            raise self.fail(w, f"its {s} sparse indices or values run past their bufferViews")
        idx = np.frombuffer(self.blob, it, s, at + o).astype(np.int64)
        if idx.max() >= count or np.any(np.diff(idx) <= 0):
            raise self.fail(w, f"sparse indices not increasing within [0, {count})")
        return idx, np.frombuffer(self.blob, dt, s * width, at2 + o2).reshape(s, width)


def _attr(obj, name):
    """``obj.name`` of a pygltflib Attributes, or ``obj[name]`` of the dict it leaves
    for a morph target."""
    return obj.get(name) if isinstance(obj, dict) else getattr(obj, name, None)


def read_glb_animation(path) -> GlbAnimation:
    """Read a ``.glb`` of one triangle mesh with morph targets (as
    :class:`GlbAnimationWriter` writes it; others of that kind too).

    The keyframes are those of the first animation's ``weights`` channel on a node of
    the mesh (STEP, LINEAR, or CUBICSPLINE whose tangents are not used); without an
    animation, one frame per target (one frame, the base, without targets). Memory: the
    file is memory-mapped; the targets are views of it where stored densely.

    Returns
    -------
    :class:`GlbAnimation`.

    Raises
    ------
    SShaDeError naming the file and the place: not a glTF binary, a cut-short file, a
    JSON that is not glTF, not one mesh of one triangle primitive, an accessor out of its
    buffer, face indices out of range, NaN/inf positions, keyframe times not increasing.
    """
    g, p = _pygltflib(), Path(path)
    text, start, length, blob = _chunks(p)
    try:
        doc = g.GLTF2.from_json(text.decode("utf-8"), infer_missing=True)
    except (ValueError, TypeError, AttributeError, KeyError, ArithmeticError, RecursionError) as e:
        raise SShaDeError(f"{p}: its JSON chunk is not a glTF document ({type(e).__name__}: {e})") from None
    r = _Reader(p, doc, blob, start, length)
    if len(doc.meshes or []) != 1 or len(doc.meshes[0].primitives or []) != 1:
        raise r.fail("meshes", "expected one mesh of one primitive (as python -m sshade animate writes), got "
                               f"{len(doc.meshes or [])} mesh(es)")
    prim = doc.meshes[0].primitives[0]
    if prim.mode not in (None, 4) or prim.indices is None or _attr(prim.attributes, "POSITION") is None:
        raise r.fail("mesh 0 primitive 0", "expected indexed triangles (mode 4) with POSITION")
    base = r.accessor(_attr(prim.attributes, "POSITION"), "POSITION", ("VEC3",), (5126,))
    F = r.accessor(prim.indices, "indices", ("SCALAR",), (5121, 5123, 5125))
    if len(F) % 3:
        raise r.fail("mesh 0 primitive 0 indices", f"{len(F)} indices, not a multiple of 3")
    F = check_faces(F.reshape(-1, 3).astype(np.int64), len(base), name=f"{p}: mesh 0 faces")
    targets = [r.accessor(_attr(t, "POSITION"), f"morph target {j} POSITION", ("VEC3",), (5126,))
               for j, t in enumerate(prim.targets or [])]
    for j, X in enumerate([base, *targets]):
        if len(X) != len(base) or not np.isfinite(X).all():
            raise r.fail("mesh 0 " + (f"morph target {j - 1}" if j else "POSITION"),
                         f"{len(X)} positions for {len(base)} vertices" if len(X) != len(base) else "NaN or inf")
    times, weights = _keyframes(r, len(targets))
    extras = doc.asset.extras if doc.asset is not None and isinstance(doc.asset.extras, dict) else {}
    return GlbAnimation(base, F, targets, times, weights, extras)


def _keyframes(r: _Reader, t: int) -> tuple[np.ndarray | None, sp.csr_matrix]:
    """(times (f,) or None, weights (f, t) CSR) of the first ``weights`` channel on a node
    of mesh 0; the identity (one frame per target) without one."""
    doc = r.doc
    for a, anim in enumerate(doc.animations or []):
        for c, ch in enumerate(anim.channels or []):
            node = getattr(ch.target, "node", None)
            nodes = doc.nodes or []
            if getattr(ch.target, "path", None) != "weights" or not isinstance(node, int) \
                    or not 0 <= node < len(nodes) or nodes[node].mesh != 0:
                continue
            w = f"animation {a} channel {c}"
            s = (anim.samplers or [])[r.integer(ch.sampler, f"{w} sampler", 0, len(anim.samplers or []))]
            if s.interpolation not in (None, "LINEAR", "STEP", "CUBICSPLINE"):
                raise r.fail(w, f"interpolation {s.interpolation!r}")
            times = r.accessor(s.input, f"{w} keyframe times", ("SCALAR",), (5126,)).astype(np.float64)
            if not np.isfinite(times).all() or np.any(np.diff(times) <= 0):
                raise r.fail(w, "keyframe times not finite and increasing")
            per = 3 if s.interpolation == "CUBICSPLINE" else 1
            at, values, count = r.nonzero(s.output, f"{w} weights")
            if count != per * len(times) * t or not np.isfinite(values).all():
                raise r.fail(w, f"{count} weights for {per} x {len(times)} keyframes x {t} targets, or not finite")
            k, rest = np.divmod(at, per * t)
            lo = (per // 2) * t  # CUBICSPLINE: (in-tangent, value, out-tangent) per keyframe; the value
            keep = (rest >= lo) & (rest < lo + t)
            W = sp.csr_matrix((values[keep].astype(np.float64), (k[keep], rest[keep] - lo)), shape=(len(times), t))
            return times, W
    return None, sp.identity(t, format="csr") if t else sp.csr_matrix((1, 0))

"""Fuzz ``python -m sshade deform`` with mutated mesh and handle files.

Small valid inputs (a subdivided icosahedron as OBJ, OFF, ASCII and binary PLY, STL;
``.sel`` + ``.def``, ``.json``, ``.csv``) are mutated a few hundred times (seeded:
truncation, flipped bytes, numbers scaled by 1e+-200, permuted, dropped and duplicated
lines, inserted garbage). All cases run in ONE child process (a driver calling
:func:`sshade.deform_command.main` in-process, C-level fds 1 and 2 redirected per case) which
logs each case before and after, so a native abort or a hang names its mutation.
Each case must either exit 0 with an output mesh that reads back finite with the input's
referenced vertex count, or exit 2 with exactly one ``error: `` line on stderr; never a
traceback, a signal or a hang; and no file but the output may change.
"""
from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np

from tests.conftest import ROOT, icosphere, subprocess_env, write_lift_selection

N_CASES = 400
SEED = 19
FAST = ["--n-low", "20", "--k", "1", "--param", "workers=1"]

DRIVER = r'''
import json, os, signal, sys, traceback
from sshade.deform_command import main

cases = json.load(open(sys.argv[1]))
log = open(sys.argv[2], "a")

def alarm(signum, frame):
    raise TimeoutError("case took too long")

signal.signal(signal.SIGALRM, alarm)
saved = os.dup(1), os.dup(2)
for c in cases:
    log.write(json.dumps({"start": c["id"]}) + "\n"); log.flush()
    capture = c["dir"] + "/.captured"
    fd = os.open(capture, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    sys.stdout.flush(); sys.stderr.flush()
    os.dup2(fd, 1); os.dup2(fd, 2); os.close(fd)
    signal.alarm(30)
    out_fd = os.open(c["dir"] + "/.stdout", os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    try:
        with open(c["dir"] + "/.stderr", "w") as err, os.fdopen(out_fd, "w") as out:
            so, se = sys.stdout, sys.stderr
            sys.stdout, sys.stderr = out, err
            try:
                rc = main(["deform", *c["args"]])
            except SystemExit as e:
                rc = e.code
            except BaseException:
                rc = "exception: " + traceback.format_exc()[-800:]
            finally:
                sys.stdout, sys.stderr = so, se
    finally:
        signal.alarm(0)
        sys.stdout.flush(); sys.stderr.flush()
        os.dup2(saved[0], 1); os.dup2(saved[1], 2)
    err = open(c["dir"] + "/.stderr").read()
    native = open(capture, "rb").read().decode("utf-8", "replace")
    log.write(json.dumps({"id": c["id"], "rc": rc, "stderr": err, "native": native}) + "\n"); log.flush()
'''


def _inputs(d):
    """Write the valid inputs into ``d``; returns {kind: file name}, vertex count."""
    import trimesh

    from sshade.mesh.io import write_mesh
    V, F = icosphere()
    write_mesh(d / "m.obj", V, F)
    write_mesh(d / "m.off", V, F)
    write_mesh(d / "mb.ply", V, F)
    trimesh.Trimesh(V, F, process=False).export(d / "m.ply", encoding="ascii")
    trimesh.Trimesh(V, F, process=False).export(d / "m.stl")
    status = write_lift_selection(d, V)
    h = np.flatnonzero(status != 1)
    T = V[h] + (status[h] == 2)[:, None] * [0, 0, 0.3]
    (d / "m.json").write_text(json.dumps({"handles": h.tolist(), "targets": T.tolist()}))
    (d / "m.csv").write_text("index,x,y,z\n" + "".join(f"{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in zip(h, T)))
    return ["m.obj", "m.off", "m.ply", "mb.ply", "m.stl"], ["m.sel", "m.def", "m.json", "m.csv"]


NUM = re.compile(rb"-?\d+\.?\d*(?:[eE][-+]?\d+)?")


def _mutate(data: bytes, rng) -> tuple[str, bytes]:
    """One seeded mutation of ``data``: (description, new bytes)."""
    kind = rng.choice(["truncate", "flip", "scale", "permute", "drop", "duplicate", "garbage"])
    lines = data.splitlines(keepends=True)
    if kind == "truncate":
        k = int(rng.integers(0, len(data) + 1))
        return f"truncate at {k}", data[:k]
    if kind == "flip":
        b = bytearray(data)
        pos = rng.integers(0, len(b), size=int(rng.integers(1, 6)))
        for p in pos:
            b[p] = int(rng.integers(0, 256))
        return f"flip bytes {pos.tolist()}", bytes(b)
    if kind == "scale":
        f = 10.0 ** float(rng.choice([200, -200, 160, -160, 30]))
        every = int(rng.integers(1, 4))
        count = [0]

        def sub(m):
            count[0] += 1
            return (b"%.17g" % (float(m.group()) * f)) if count[0] % every == 0 else m.group()
        return f"scale every {every}th number by {f:g}", NUM.sub(sub, data)
    if kind == "permute":
        idx = rng.permutation(len(lines))
        return "permute lines", b"".join(lines[i] for i in idx)
    if kind == "drop":
        k = int(rng.integers(0, max(len(lines), 1)))
        return f"drop line {k}", b"".join(lines[:k] + lines[k + 1:])
    if kind == "duplicate":
        k = int(rng.integers(0, max(len(lines), 1)))
        return f"duplicate line {k}", b"".join(lines[:k + 1] + lines[k:])
    k = int(rng.integers(0, len(data) + 1))
    junk = rng.integers(0, 256, size=int(rng.integers(1, 40)), dtype=np.uint8).tobytes()
    return f"insert {len(junk)} garbage bytes at {k}", data[:k] + junk + data[k:]


def _cases(base, work, meshes, handles, rng):
    cases = []
    for i in range(N_CASES):
        mesh = meshes[i % len(meshes)] if i % 10 else "m.stl"
        mesh = mesh if mesh != "m.stl" or i % 10 == 0 else "m.off"
        hkind = ["sel", "json", "csv"][(i // len(meshes)) % 3]
        files = {"mesh": mesh, **({"sel": "m.sel", "def": "m.def"} if hkind == "sel" else {hkind: f"m.{hkind}"})}
        role = rng.choice(list(files))
        d = work / f"c{i:03d}"
        d.mkdir()
        paths = {}
        for r, name in files.items():
            data = (base / name).read_bytes()
            if r == role:
                desc, data = _mutate(data, rng)
                desc = f"{name}: {desc}"
            (d / name).write_bytes(data)
            paths[r] = str(d / name)
        out = str(d / ("out" + [".ply", ".off", ".obj"][i % 3]))
        args = [paths["mesh"], "-o", out, *FAST]
        args += ["--sel", paths["sel"], "--def", paths["def"]] if hkind == "sel" else ["--handles", paths[hkind]]
        cases.append({"id": i, "dir": str(d), "args": args, "out": out, "mutation": desc, "mesh": paths["mesh"]})
    return cases


def _snapshot(folder, skip) -> dict:
    return {str(p): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and str(p) not in skip and p.name not in (".captured", ".stdout", ".stderr")}


def _referenced(mesh) -> int | None:
    from sshade.mesh.io import read_mesh
    try:
        _, F = read_mesh(mesh, validate=False)
    except ValueError:
        return None
    return len(np.unique(F))


def test_fuzzed_inputs_never_crash_hang_or_write_a_wrong_mesh(tmp_path):
    from sshade.mesh.io import read_mesh
    base, work = tmp_path / "base", tmp_path / "work"
    base.mkdir()
    work.mkdir()
    meshes, handles = _inputs(base)
    cases = _cases(base, work, meshes, handles, np.random.default_rng(SEED))
    (tmp_path / "cases.json").write_text(json.dumps(cases))
    (tmp_path / "driver.py").write_text(DRIVER)
    outs = {c["out"] for c in cases}
    before = _snapshot(tmp_path, outs)
    log = tmp_path / "log.jsonl"
    try:
        r = subprocess.run([sys.executable, str(tmp_path / "driver.py"), str(tmp_path / "cases.json"), str(log)],
                           cwd=ROOT, env=subprocess_env(), capture_output=True, timeout=150)
        rc, died = r.returncode, r.stderr.decode("utf-8", "replace")[-600:]
    except subprocess.TimeoutExpired:
        rc, died = "hang (child timeout)", ""
    events = [json.loads(ln) for ln in log.read_text().splitlines()]
    done = {e["id"]: e for e in events if "id" in e}
    started = [e["start"] for e in events if "start" in e]
    if rc != 0 or len(done) != len(cases):
        last = cases[started[-1]] if started else None
        raise AssertionError(f"driver ended with {rc} at case {last and last['id']} "
                             f"({last and last['mutation']}; args {last and last['args']}): {died}")
    problems = []
    for c in cases:
        e = done[c["id"]]
        lines = [ln for ln in e["stderr"].splitlines() if ln.strip()]
        why = None
        if e["native"]:
            why = f"native output {e['native'][:200]!r}"
        elif e["rc"] == 0:
            n = _referenced(c["mesh"])
            try:
                V, _ = read_mesh(c["out"], validate=False)
                if not np.isfinite(V).all() or len(V) != n:
                    why = f"output has {len(V)} vertices (input references {n}) or non-finite values"
            except ValueError as ex:
                why = f"output unreadable: {ex}"
        elif e["rc"] == 2:
            errs = [ln for ln in lines if not ln.startswith("warning: ")]
            if len(errs) != 1 or not errs[0].startswith("error: ") or len(errs[0]) <= 7:
                why = f"stderr is not one error line: {e['stderr'][-300:]!r}"
        else:
            why = f"exit {str(e['rc'])[:600]}"
        if why:
            problems.append(f"case {c['id']} ({c['mutation']}): {why}")
    after = _snapshot(tmp_path, outs | {str(log)})
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k) and k != str(log))
    assert not problems, "\n".join(problems[:20])
    assert not changed, changed[:10]
    statuses = [done[c["id"]]["rc"] for c in cases]
    assert statuses.count(0) >= 10 and statuses.count(2) >= 50, (statuses.count(0), statuses.count(2))

"""``python -m defaust pack``: one zip archive of a build with its manifest, Croissant file
and datasheet, the same bytes for the same build; defaust.load, verify, describe and
export read it in place and give the folder's arrays bit for bit; the output rules (a
foreign file, a folder, a path inside the build or a build with a problem is refused and
nothing is written; its own earlier archive is replaced); an archive member with '..', an
absolute path or a link, a compressed member, and a bad handles file inside the archive
are refused with one line naming the member."""
from __future__ import annotations

import io
import json
import shutil
import stat
import subprocess
import sys
import tracemalloc
import zipfile

import numpy as np
import pytest

from defaust.archive import ArchiveBuild
from defaust.croissant import LICENCES
from defaust.dataset import load, read_manifest, verify
from defaust.describe import describe
from defaust.export import export
from defaust.packing import is_pack, pack
from defaust.store import sha256_bytes, sha256_file, write_npz
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env

ARRAYS = ("V", "F", "handles", "targets", "static", "group", "V_gt", "snap_distance")
TOP = "DeFAUST-synthetic"
H01 = f"{TOP}/subject_00/pose_01_handles.npz"


@pytest.fixture(scope="module")
def archive(defaust_ci, tmp_path_factory):
    """The ci build packed (read-only: copy it to change it)."""
    out = tmp_path_factory.mktemp("pack") / "defaust-ci.zip"
    pack(defaust_ci, out)
    return out


def _cli(*argv):
    return subprocess.run([sys.executable, "-m", "defaust", *map(str, argv)], capture_output=True, text=True,
                          cwd=ROOT, env=subprocess_env(), timeout=300)


def _one_line_error(fn, *args, **kw) -> str:
    with pytest.raises(SShaDeError) as e:
        fn(*args, **kw)
    assert "\n" not in str(e.value), str(e.value)
    return str(e.value)


def _rezip(src, dst, *, replace=None, extra=(), compression=zipfile.ZIP_STORED):
    """Copy the zip ``src`` to ``dst`` member by member, some members' bytes replaced
    (``{name: bytes}``) and ``extra`` ``(ZipInfo or name, bytes)`` members added."""
    replace = replace or {}
    with zipfile.ZipFile(src) as zi, zipfile.ZipFile(dst, "w", compression) as zo:
        for info in zi.infolist():
            data = replace.get(info.filename) or zi.read(info)
            info.compress_type = compression
            zo.writestr(info, data)
        for info, data in extra:
            zo.writestr(info, data)
        zo.comment = zi.comment
    return dst


def _tree(p):
    return {str(f.relative_to(p)): f.read_bytes() for f in sorted(p.rglob("*")) if f.is_file()}


@pytest.mark.parametrize("resolution", ["low", "high"])
def test_pack_then_load_gives_identical_arrays(defaust_ci, archive, resolution):
    folder, packed = load(defaust_ci, resolution=resolution), load(archive, resolution=resolution)
    assert packed.names == folder.names and packed.root == archive
    for a, b in zip(folder, packed, strict=True):
        assert (a.name, a.pose_name, a.seed, a.n_dropped, a.source, a.landmark_names) == \
            (b.name, b.pose_name, b.seed, b.n_dropped, b.source, b.landmark_names)
        for k in ARRAYS:
            np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
            assert getattr(a, k).dtype == getattr(b, k).dtype


def test_the_archive_holds_the_build_manifest_croissant_and_datasheet(defaust_ci, archive):
    m_bytes = (defaust_ci / "manifest.json").read_bytes()
    sha = sha256_bytes(m_bytes)
    with zipfile.ZipFile(archive) as zf:
        names = zf.namelist()
        assert names[:3] == [f"{TOP}/manifest.json", f"{TOP}/croissant.json", f"{TOP}/DATASHEET.md"]
        files = json.loads(m_bytes)["files"]
        assert names[3:] == [f"{TOP}/{rel}" for rel in sorted(files)]
        assert zf.read(f"{TOP}/manifest.json") == m_bytes
        assert all(sha256_bytes(zf.read(f"{TOP}/{rel}")) == h for rel, h in files.items())
        assert all(i.compress_type == zipfile.ZIP_STORED for i in zf.infolist())
        meta = json.loads(zf.read(f"{TOP}/croissant.json"))
        sheet = zf.read(f"{TOP}/DATASHEET.md").decode()
    assert meta["distribution"][0]["sha256"] == sha and meta["license"] == LICENCES["synthetic"]
    assert f"manifest.json sha256: {sha}" in sheet and "CC0 1.0" in sheet and "@article{maggioli_sshade" in sheet
    assert is_pack(archive) and read_manifest(archive) == read_manifest(defaust_ci)


def test_pack_is_deterministic_and_replaces_its_own_earlier_archive(defaust_ci, archive, tmp_path):
    out = tmp_path / "again.zip"
    first = pack(defaust_ci, out)
    assert first["sha256"] == sha256_file(archive) == sha256_file(out)  # same build, same bytes
    r = _cli("pack", defaust_ci, "-o", out)  # its own output: replaced
    assert r.returncode == 0 and r.stdout.startswith("packed 17 file(s)"), r.stderr
    assert sha256_file(out) == first["sha256"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["again.zip"]  # no temporary file left


def test_pack_refuses_a_foreign_file_unless_forced(defaust_ci, tmp_path):
    out = tmp_path / "thesis.zip"
    out.write_bytes(b"not mine")
    r = _cli("pack", defaust_ci, "-o", out)
    assert r.returncode == 2 and r.stdout == "" and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.startswith(f"error: refusing to replace {out}") and "--force" in r.stderr
    assert out.read_bytes() == b"not mine"
    r = _cli("pack", defaust_ci, "-o", out, "--force")
    assert r.returncode == 0, r.stderr
    assert is_pack(out) and verify(out) == []


@pytest.mark.parametrize("where", ["inside", "folder", "no_folder", "link"])
def test_pack_refuses_an_output_it_may_not_write_and_writes_nothing(defaust_ci, tmp_path, where):
    c = shutil.copytree(defaust_ci, tmp_path / "c")
    out = {"inside": c / "subject_00" / "x.zip", "folder": tmp_path / "dir", "no_folder": tmp_path / "no" / "x.zip",
           "link": tmp_path / "link.zip"}[where]
    if where == "folder":
        out.mkdir()
    if where == "link":
        out.symlink_to(tmp_path / "elsewhere.zip")
    before, outside = _tree(c), sorted(p.name for p in tmp_path.iterdir())
    msg = _one_line_error(pack, c, out, force=True)
    assert msg.startswith(f"refusing to write {out}")
    assert _tree(c) == before and sorted(p.name for p in tmp_path.iterdir()) == outside


def test_pack_refuses_a_build_with_a_problem(defaust_ci, tmp_path):
    c = shutil.copytree(defaust_ci, tmp_path / "c")
    (c / "subject_00" / "notes.txt").write_text("mine")
    r = _cli("pack", c, "-o", tmp_path / "x.zip")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert r.stderr.startswith(f"error: refusing to pack {c}: 1 problem(s), the first: {c}/subject_00/notes.txt")
    assert not (tmp_path / "x.zip").exists()


def test_verify_and_describe_read_an_archive_in_place(archive, defaust_ci, tmp_path):
    r = _cli("verify", archive)
    assert r.returncode == 0 and "every file matches" in r.stdout, r.stdout + r.stderr
    assert describe(archive, resolution="low") == describe(defaust_ci, resolution="low")
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(archive) as zf:
        ply = bytearray(zf.read(f"{TOP}/subject_00/pose_02_low.ply"))
    ply[-5] ^= 0x01
    _rezip(archive, bad, replace={f"{TOP}/subject_00/pose_02_low.ply": bytes(ply)},
           extra=[(f"{TOP}/notes.txt", b"mine")])
    assert verify(bad) == [f"{bad}/{TOP}/subject_00/pose_02_low.ply: checksum differs from manifest.json",
                           f"{bad}/{TOP}/notes.txt: not in manifest.json"]
    r = _cli("verify", bad)
    assert r.returncode == 2 and "2 problem(s)" in r.stdout
    cases = load(bad, resolution="low")
    assert cases[0].name == "s00_p01"
    msg = _one_line_error(lambda: cases[1])
    assert msg.startswith(f"{bad}/{TOP}/subject_00/pose_02_low.ply: checksum differs")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.zip"]  # nothing unpacked


def test_export_of_an_archive_equals_export_of_its_folder(archive, defaust_ci, tmp_path):
    a = export(archive, tmp_path / "a", fmt="npz", resolution="low")
    b = export(defaust_ci, tmp_path / "b", fmt="npz", resolution="low")
    assert [f.name for f in a] == [f.name for f in b]
    assert all(f.read_bytes() == g.read_bytes() for f, g in zip(a[:-1], b[:-1]))
    marker = json.loads((tmp_path / "a" / "export.json").read_text())
    assert marker["build_manifest_sha256"] == sha256_file(defaust_ci / "manifest.json")


def _link(name):
    info = zipfile.ZipInfo(name)
    info.create_system, info.external_attr = 3, (stat.S_IFLNK | 0o777) << 16
    return info


@pytest.mark.parametrize("member, why", [
    ("../evil.txt", "has '..'"),
    (f"{TOP}/subject_00/../../evil.txt", "has '..'"),
    ("/tmp/evil.txt", "is an absolute path"),
    ("C:/evil.txt", "is an absolute path"),
    (f"{TOP}\\..\\evil.txt", "has a backslash"),
    (_link(f"{TOP}/subject_00/rest_low_link.ply"), "is a symbolic link"),
])
def test_archive_member_escaping_is_refused(archive, tmp_path, member, why):
    bad = _rezip(archive, tmp_path / "bad.zip", extra=[(member, b"/etc/passwd")])
    name = member.filename if isinstance(member, zipfile.ZipInfo) else member
    line = f"{bad}: member {name!r} {why}"
    for fn in (load, read_manifest, ArchiveBuild):
        msg = _one_line_error(fn, bad)
        assert msg.startswith(line) and msg.endswith("refusing the archive")
    problems = verify(bad)
    assert len(problems) == 1 and problems[0].startswith(line)
    r = _cli("verify", bad)
    assert r.returncode == 2 and line in r.stdout
    r = _cli("describe", bad)
    assert r.returncode == 2 and r.stderr.startswith(f"error: {line}") and len(r.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.zip"]  # nothing was written beside it


def test_a_compressed_or_foreign_archive_is_refused_in_one_line(archive, tmp_path):
    deflated = _rezip(archive, tmp_path / "deflated.zip", compression=zipfile.ZIP_DEFLATED)
    msg = _one_line_error(load, deflated)
    assert msg.startswith(f"{deflated}: member '{TOP}/manifest.json' is compressed (method 8)")
    other = tmp_path / "other.zip"
    with zipfile.ZipFile(other, "w") as zf:
        zf.writestr("readme.txt", b"x")
    assert "no manifest.json at its top level or in one folder" in _one_line_error(load, other)
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    assert "not a DeFAUST build (a folder, or a zip archive" in _one_line_error(load, text)


def _handles_member(archive, **change) -> bytes:
    """The ``pose_01`` handles file of ``archive`` with arrays changed (np.savez)."""
    with zipfile.ZipFile(archive) as zf, np.load(io.BytesIO(zf.read(H01))) as z:
        d = {k: z[k] for k in z.files}
    d.update(change)
    buf = io.BytesIO()
    np.savez(buf, **d)
    return buf.getvalue()


def test_a_nan_handle_inside_an_archive_is_refused_at_first_access_naming_member_and_array(archive, tmp_path):
    with zipfile.ZipFile(archive) as zf, np.load(io.BytesIO(zf.read(H01))) as z:
        T = z["target_positions"].copy()
    T[2, 0] = np.nan
    bad = _rezip(archive, tmp_path / "nan.zip", replace={H01: _handles_member(archive, target_positions=T)})
    cases = load(bad, resolution="low", verify=False)  # no checksum: the content itself is refused
    msg = _one_line_error(lambda: cases[0])
    assert msg.startswith(f"{bad}/{H01}: array 'target_positions'") and "NaN or infinite" in msg
    assert f"{bad}/{H01}: checksum differs from manifest.json" in verify(bad)


def test_an_oversized_array_inside_an_archive_is_refused_before_decompressing(archive, tmp_path):
    with zipfile.ZipFile(archive) as zf, np.load(io.BytesIO(zf.read(H01))) as z:
        write_npz(tmp_path / "h.npz", {k: z[k] for k in z.files if k != "delta"})
    with zipfile.ZipFile(tmp_path / "h.npz", "a", compression=zipfile.ZIP_DEFLATED) as zf, \
            zf.open("delta.npy", "w") as fh:  # 50 MiB of zeros, about 50 KB deflated
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": (50 << 17,)})
        for _ in range(50):
            fh.write(bytes(1 << 20))
    buf = (tmp_path / "h.npz").read_bytes()
    assert len(buf) < 1 << 20
    bad = _rezip(archive, tmp_path / "big.zip", replace={H01: buf})
    cases = load(bad, resolution="low", verify=False)
    tracemalloc.start()
    try:
        msg = _one_line_error(lambda: cases[0])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert msg.startswith(f"{bad}/{H01}: array 'delta' is ") and "bytes uncompressed" in msg
    assert peak < 10 << 20, peak

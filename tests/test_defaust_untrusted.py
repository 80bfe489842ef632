"""defaust.load, load_handles, verify and the dataset commands read a build as untrusted
input: a link in the build folder, a handles file with NaN/inf or non-real values, a bad
parameter of ``load``, and an ``.npz`` with an unexpected, missing or oversized array
(even with its checksum recomputed in the manifest) are each one ``SShaDeError`` line
naming the file and the place (``error: ...`` and exit 2 on the command line), and an
oversized array is refused before it is decompressed. ``load`` itself refuses a bad
parameter and a link; a file's content is refused when its case is first read
(:func:`_read_every_case`)."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tracemalloc
import zipfile

import numpy as np
import pytest

from defaust.croissant import write_croissant
from defaust.dataset import load, load_handles, verify
from defaust.store import read_npz, sha256_file, write_npz
from sshade.errors import SShaDeError

from .conftest import ROOT, subprocess_env

H01 = "subject_00/pose_01_handles.npz"


def _copy(defaust_ci, tmp_path, name="c"):
    return shutil.copytree(defaust_ci, tmp_path / name)


def _reseal(root, rel):
    """Recompute ``rel``'s sha256 in the manifest and the croissant.json, as whoever edits
    a copy can: the checksums then say nothing about the file's content."""
    m = json.loads((root / "manifest.json").read_text())
    m["files"][rel] = sha256_file(root / rel)
    (root / "manifest.json").write_text(json.dumps(m, indent=1))
    write_croissant(root)


def _edit_handles(root, rel=H01, drop=(), **change):
    """Rewrite a handles file with arrays changed (np.savez: any dtype), and reseal it."""
    with np.load(root / rel) as z:
        d = {k: z[k] for k in z.files if k not in drop}
    d.update(change)
    np.savez(root / rel, **d)
    _reseal(root, rel)
    return root / rel


def _add_zero_member(path, name, nbytes=50 << 20):
    """Append ``name.npy``: ``nbytes`` of float64 zeros, deflated (about 50 KB on disk),
    streamed so that the test itself never holds it."""
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf, zf.open(f"{name}.npy", "w") as fh:
        np.lib.format.write_array_header_1_0(fh, {"descr": "<f8", "fortran_order": False, "shape": (nbytes // 8,)})
        chunk = bytes(1 << 20)
        for _ in range(nbytes >> 20):
            fh.write(chunk)


def _one_line_error(fn, *args, **kw) -> str:
    with pytest.raises(SShaDeError) as e:
        fn(*args, **kw)
    msg = str(e.value)
    assert "\n" not in msg, msg
    return msg


def _read_every_case(root, **kw) -> list:
    """``load(root, **kw)``, then every case read (``load`` reads a case's files at its
    first access)."""
    return list(load(root, **kw))


def _cli(*argv):
    return subprocess.run([sys.executable, "-m", "defaust", *map(str, argv)], capture_output=True, text=True,
                          cwd=ROOT, env=subprocess_env(), timeout=300)


# --- 1. links ---------------------------------------------------------------------


def test_verify_reports_a_listed_file_linked_to_an_identical_copy_and_load_refuses_it(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path)
    f = c / H01
    outside = tmp_path / "outside.npz"
    shutil.move(f, outside)
    f.symlink_to(outside)  # same bytes: the checksum matches
    assert sha256_file(f) == json.loads((c / "manifest.json").read_text())["files"][H01]
    problems = verify(c)
    assert len(problems) == 1 and str(f) in problems[0] and "is a link" in problems[0], problems
    r = _cli("verify", c)
    assert r.returncode == 2 and str(f) in r.stdout and "1 problem(s)" in r.stdout
    for check in (True, False):
        msg = _one_line_error(load, c, resolution="low", verify=check)
        assert str(f) in msg and "is a link" in msg


def test_verify_reports_a_linked_folder_and_an_unlisted_link_without_following_them(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.move(c / "subject_00", elsewhere / "subject_00")
    (elsewhere / "subject_00" / "notes.txt").write_text("not looked at: the folder is a link")
    (c / "subject_00").symlink_to(elsewhere / "subject_00")
    (c / "more").symlink_to(elsewhere)  # an unlisted linked folder
    problems = verify(c)
    named = sorted(p.split(" is a link")[0] for p in problems)  # one line per link, nothing inside them
    assert named == [f"DeFAUST build: {c / 'more'}", f"DeFAUST build: {c / 'subject_00'}"], problems
    msg = _one_line_error(load, c, resolution="low")
    assert str(c / "subject_00") in msg and "is a link" in msg


def test_a_manifest_that_is_a_link_is_refused(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path)
    shutil.move(c / "manifest.json", tmp_path / "manifest.json")
    (c / "manifest.json").symlink_to(tmp_path / "manifest.json")
    msg = _one_line_error(load, c)
    assert str(c / "manifest.json") in msg and "is a link" in msg
    assert len(verify(c)) == 1 and str(c / "manifest.json") in verify(c)[0]


# --- 2. handle values -------------------------------------------------------------


@pytest.mark.parametrize("key", ["target_positions", "rest_positions"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_handle_positions_or_targets_are_refused_naming_file_and_array(defaust_ci, tmp_path, key, bad):
    c = _copy(defaust_ci, tmp_path)
    with np.load(c / H01) as z:
        a = z[key].copy()
    a[3, 1] = bad
    f = _edit_handles(c, **{key: a})
    for msg in (_one_line_error(load_handles, f), _one_line_error(_read_every_case, c, resolution="low")):
        assert str(f) in msg and repr(key) in msg and "NaN or infinite" in msg
    assert verify(c) == [_one_line_error(load_handles, f)]


@pytest.mark.parametrize("key, value", [
    ("target_positions", lambda a: a.astype(np.complex128)),
    ("rest_positions", lambda a: a.astype(str)),
    ("target_positions", lambda a: a.astype(object)),
    ("static", lambda a: a.astype(np.float64)),
    ("group", lambda a: a.astype(np.float64)),
])
def test_non_real_handle_dtypes_are_refused_naming_file_and_array(defaust_ci, tmp_path, key, value):
    c = _copy(defaust_ci, tmp_path)
    with np.load(c / H01) as z:
        a = value(z[key])
    f = _edit_handles(c, **{key: a})
    msg = _one_line_error(load_handles, f)
    assert str(f) in msg and repr(key) in msg and ("dtype" in msg or "values other than 0 and 1" in msg)
    problems = verify(c)  # bounded by the manifest's counts: refused by size, or as load_handles says
    assert len(problems) == 1 and str(f) in problems[0] and repr(key) in problems[0], problems
    assert _one_line_error(_read_every_case, c, resolution="low").startswith(f"{f}: array {key!r}")


def test_describe_and_export_of_a_nan_target_are_one_error_line_and_exit_2(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path)
    with np.load(c / H01) as z:
        T = z["target_positions"].copy()
    T[0, 0] = np.nan
    f = _edit_handles(c, target_positions=T)
    for argv in (("describe", c, "--resolution", "low"), ("export", c, "--to", tmp_path / "x", "--format", "obj")):
        r = _cli(*argv)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1, r.stderr
        assert lines[0].startswith("error: ") and str(f) in lines[0] and "'target_positions'" in lines[0]
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").iterdir())


def test_describe_and_export_name_a_fifo_case_file_as_a_fifo_without_blocking(defaust_ci, tmp_path):
    """A FIFO where a case's handle file belongs: ``describe`` and ``export`` end with one
    error line that names it as a FIFO (not as missing), without blocking on it."""
    import os
    c = _copy(defaust_ci, tmp_path)
    (c / H01).unlink()
    os.mkfifo(c / H01)
    for argv in (("describe", c, "--resolution", "low"), ("export", c, "--to", tmp_path / "x", "--format", "obj")):
        r = _cli(*argv)
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1, r.stderr
        assert lines[0].startswith("error: ") and str(c / H01) in lines[0] and "FIFO" in lines[0], lines[0]


# --- 3. parameters of load ----------------------------------------------------------


@pytest.mark.parametrize("kw, words", [
    ({"subjects": 0.5}, "subjects must be None, an int or a non-empty list of ints, got 0.5"),
    ({"subjects": "abc"}, "subjects must be None, an int or a non-empty list of ints, got 'abc'"),
    ({"subjects": True}, "subjects must be None, an int or a non-empty list of ints, got True"),
    ({"subjects": [0, True]}, "got [0, True]"),
    ({"subjects": [0.0]}, "got [0.0]"),
    ({"subjects": []}, "got []"),
    ({"limit": 0}, "limit must be None or an integer >= 1, got 0"),
    ({"limit": 1.5}, "limit must be None or an integer >= 1, got 1.5"),
    ({"limit": "2"}, "limit must be None or an integer >= 1, got '2'"),
    ({"limit": True}, "got True"),
    ({"tol": float("nan")}, "tol must be None or a finite number >= 0 (metres), got nan"),
    ({"tol": float("inf")}, "got inf"),
    ({"tol": -1}, "tol must be None or a finite number >= 0 (metres), got -1"),
    ({"tol": "0.1"}, "got '0.1'"),
    ({"verify": "no"}, "verify must be True or False, got 'no'"),
    ({"resolution": "mid"}, "resolution must be 'high', 'low' or 'rN' (an extra resolution of N vertices), got 'mid'"),
])
def test_load_refuses_a_bad_parameter_naming_it_before_reading_anything(tmp_path, kw, words):
    msg = _one_line_error(load, tmp_path / "no_such_build", **kw)  # the parameter, not the folder
    assert words in msg


@pytest.mark.parametrize("subjects", [[3], [-1], 7])
def test_load_refuses_subjects_outside_the_build(defaust_ci, subjects):
    msg = _one_line_error(load, defaust_ci, resolution="low", subjects=subjects)
    assert "subjects" in msg and "are not in" in msg


def test_load_takes_ints_numpy_ints_iterables_and_a_zero_tolerance(defaust_ci):
    names = [c.name for c in load(defaust_ci, resolution="low", subjects=np.int64(0), limit=np.int64(2), tol=0.0)]
    assert names == ["s00_p01", "s00_p02"]
    assert [c.name for c in load(defaust_ci, resolution="low", subjects=range(1), limit=1)] == ["s00_p01"]
    assert len(load(defaust_ci, resolution="low", subjects=(np.int32(0),), tol=np.float32(1e-3))) == 4


# --- 4. what an npz may hold -------------------------------------------------------


def _peak_of(fn, *args, **kw) -> tuple[str, int]:
    tracemalloc.start()
    try:
        msg = _one_line_error(fn, *args, **kw)
        return msg, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_an_unexpected_array_is_refused_without_decompressing_it(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path)
    f = c / H01
    _add_zero_member(f, "extra")
    _reseal(c, H01)
    assert f.stat().st_size < 1 << 20  # 50 MiB of zeros, compressed
    msg, peak = _peak_of(_read_every_case, c, resolution="low", limit=1)
    assert str(f) in msg and "unexpected array 'extra'" in msg
    assert peak < 10 << 20, peak  # the member is 50 MiB: it was never decompressed
    assert verify(c) == [msg]


@pytest.mark.parametrize("counts", [True, False])
def test_an_oversized_expected_array_is_refused_before_decompressing(defaust_ci, tmp_path, counts):
    """``delta`` holds 6 floats; a 50 MiB (or, without the manifest's counts, 100 MiB)
    member of that name is refused from its zip header."""
    c = _copy(defaust_ci, tmp_path)
    f = c / H01
    with np.load(f) as z:
        d = {k: z[k] for k in z.files if k != "delta"}
    write_npz(f, d)
    _add_zero_member(f, "delta", (50 if counts else 100) << 20)
    _reseal(c, H01)
    msg, peak = _peak_of(_read_every_case, c, resolution="low", limit=1) if counts else _peak_of(load_handles, f)
    assert str(f) in msg and "array 'delta'" in msg and "bytes uncompressed" in msg
    assert peak < 10 << 20, peak


def test_a_missing_array_is_refused_naming_it(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path)
    f = _edit_handles(c, drop=("group_static",))
    msg = _one_line_error(_read_every_case, c, resolution="low")
    assert str(f) in msg and "missing array 'group_static'" in msg
    assert verify(c) == [msg]


def test_a_handle_count_other_than_the_manifests_is_refused(defaust_ci, tmp_path):
    c = _copy(defaust_ci, tmp_path)
    with np.load(c / H01) as z:
        d = {k: z[k] for k in z.files}
    f = _edit_handles(c, **{k: d[k][:-1] for k in ("rest_positions", "target_positions", "static", "group",
                                                    "low_index")})
    msg = _one_line_error(_read_every_case, c, resolution="low")
    assert str(f) in msg and "179 handles, expected 180" in msg
    assert len(load_handles(f)) == 179  # without the manifest's count: a consistent file


def test_read_npz_reads_only_the_expected_keys_within_their_bounds(tmp_path):
    p = tmp_path / "a.npz"
    write_npz(p, {"a": np.arange(4), "b": np.eye(2)})
    assert set(read_npz(p)) == {"a", "b"}
    d = read_npz(p, ["a"], optional=["b", "c"], max_bytes={"a": 4096})
    assert d["a"].tolist() == [0, 1, 2, 3] and d["a"].flags.writeable
    assert "unexpected array 'b'" in _one_line_error(read_npz, p, ["a"])
    assert "missing array 'c'" in _one_line_error(read_npz, p, ["a", "b", "c"])
    assert "array 'a' is 160 bytes uncompressed" in _one_line_error(read_npz, p, ["a", "b"], max_bytes=100)

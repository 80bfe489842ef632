"""defaust.load's sequence: it reads no array and no checksum before a case is asked for,
then reads that case's files once (a subject's rest mesh once for all its cases, also
under concurrent first access); by name it gives the same case as by position; a bad
file is refused when its case is first read (one line naming it), by load itself with
eager=True; unknown names and positions are refused with messages that help."""
from __future__ import annotations

import pickle
import shutil
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import defaust.dataset as dataset
from defaust.case_sequence import CaseSequence
from defaust.dataset import load
from defaust.store import read_npz, write_npz
from sshade.errors import SShaDeError

ARRAYS = ("V", "F", "handles", "targets", "static", "group", "V_gt", "snap_distance")


@pytest.fixture
def reads(monkeypatch):
    """Every file read by the loader, as ``(kind, file name)``: meshes, handles files and
    checksums (thread-safe: list.append)."""
    log: list[tuple[str, str]] = []
    read_mesh, load_handles, sha256_file = dataset.read_mesh, dataset.load_handles, dataset.sha256_file

    def mesh(path, **kw):
        log.append(("mesh", str(path).rsplit("/", 1)[-1]))
        return read_mesh(path, **kw)

    def handles(path, **kw):
        log.append(("handles", str(kw.get("name", path)).rsplit("/", 1)[-1]))
        return load_handles(path, **kw)

    def sha(path, *a):
        log.append(("sha256", str(path).rsplit("/", 1)[-1]))
        return sha256_file(path, *a)
    monkeypatch.setattr(dataset, "read_mesh", mesh)
    monkeypatch.setattr(dataset, "load_handles", handles)
    monkeypatch.setattr(dataset, "sha256_file", sha)
    return log


def _same_case(a, b):
    assert (a.name, a.subject, a.pose, a.pose_name, a.seed, a.n_dropped, a.resolution) == \
        (b.name, b.subject, b.pose, b.pose_name, b.seed, b.n_dropped, b.resolution)
    for k in ARRAYS:
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))


def test_load_reads_no_array_before_first_access(defaust_ci, reads):
    cases = load(defaust_ci, resolution="low")
    assert isinstance(cases, CaseSequence) and len(cases) == 4 and reads == []
    assert cases.names == ("s00_p01", "s00_p02", "s00_p03", "s00_p04") and reads == []
    c = cases[1]
    assert sorted(reads) == [("handles", "pose_02_handles.npz"), ("mesh", "pose_02_low.ply"), ("mesh", "rest_low.ply"),
                             ("sha256", "pose_02_handles.npz"), ("sha256", "pose_02_low.ply"),
                             ("sha256", "rest_low.ply")]
    reads.clear()
    assert cases[1] is c and cases["s00_p02"] is c and reads == []  # kept, not read again
    cases[2]  # the rest mesh is shared: read and checked once
    assert sorted(reads) == [("handles", "pose_03_handles.npz"), ("mesh", "pose_03_low.ply"),
                             ("sha256", "pose_03_handles.npz"), ("sha256", "pose_03_low.ply")]


def test_lazy_cases_equal_the_eagerly_read_ones(defaust_ci):
    lazy, eager = load(defaust_ci, resolution="high"), load(defaust_ci, resolution="high", eager=True)
    assert "4 read" in repr(eager) and "0 read" in repr(lazy)
    for a, b in zip(lazy, eager, strict=True):
        _same_case(a, b)
    assert lazy[0].F is lazy[3].F  # one subject: one face array, as the list before


def test_indexing_by_name_equals_indexing_by_position(defaust_ci):
    cases = load(defaust_ci, resolution="low")
    for i, name in enumerate(cases.names):
        s, p = int(name[1:3]), int(name[5:7])
        assert cases[name] is cases[i] is cases[f"subject_{s:02d}/pose_{p:02d}"] is cases[np.int64(i)]
        assert cases[i - len(cases)] is cases[i] and cases.index(name) == i and name in cases
        assert cases[i].name == name and (cases[i].subject, cases[i].pose) == (s, p)
    assert [c.name for c in cases] == list(cases.names)
    part = cases[1:3]
    assert isinstance(part, CaseSequence) and part.names == cases.names[1:3] and part[0] is cases[1]
    assert cases[::-1].names == cases.names[::-1] and cases[5:].names == ()
    assert list(reversed(cases))[0] is cases[-1]


def test_unknown_names_and_positions_are_refused_helpfully(defaust_ci):
    cases = load(defaust_ci, resolution="low", limit=2)
    with pytest.raises(KeyError, match=r"no case 's09_p01' in .*sXX_pYY.*s00_p01, s00_p02"):
        cases["s09_p01"]
    with pytest.raises(KeyError, match="'s00_p04' is in .* but not in this selection of 2 case"):
        cases["s00_p04"]
    with pytest.raises(IndexError, match=r"case index 2 out of range: this sequence has 2 case\(s\) \(0 to 1"):
        cases[2]
    with pytest.raises(IndexError, match="case index -3 out of range"):
        cases[-3]
    for bad in (1.0, True, None, [0]):
        with pytest.raises(TypeError, match="indexed by position .int., name .'s00_p01'"):
            cases[bad]
    assert "s00_p04" not in cases and cases.count("s00_p01") == 1
    with pytest.raises(ValueError, match="not in this sequence"):
        cases.index("s00_p04")


def test_a_damaged_file_is_refused_at_its_cases_first_access_only(defaust_ci, tmp_path):
    c = shutil.copytree(defaust_ci, tmp_path / "c")
    f = c / "subject_00" / "pose_03_handles.npz"
    d = read_npz(f)
    d["seed"] = d["seed"] + 1  # a valid file, other bytes
    write_npz(f, d)
    cases = load(c, resolution="low")  # no file read yet
    assert cases[0].name == "s00_p01" and cases[3].name == "s00_p04"
    for _ in range(2):  # refused every time it is asked for, not kept
        with pytest.raises(SShaDeError) as e:
            cases["s00_p03"]
        msg = str(e.value)
        assert "\n" not in msg and msg.startswith(f"{f}: checksum differs from manifest.json")
    with pytest.raises(SShaDeError, match="checksum differs"):
        load(c, resolution="low", eager=True)
    assert load(c, resolution="low", verify=False)["s00_p03"].name == "s00_p03"  # no checksum: read


def test_a_link_placed_after_load_is_refused_at_first_access(defaust_ci, tmp_path):
    c = shutil.copytree(defaust_ci, tmp_path / "c")
    cases = load(c, resolution="low")
    f = c / "subject_00" / "pose_02_handles.npz"
    outside = tmp_path / "outside.npz"
    shutil.move(f, outside)
    f.symlink_to(outside)
    with pytest.raises(SShaDeError, match="is a link") as e:
        cases[1]
    assert str(f) in str(e.value) and "\n" not in str(e.value)


def test_concurrent_first_access_reads_each_file_once(defaust_ci, reads):
    cases = load(defaust_ci, resolution="high")
    start = threading.Barrier(8)

    def get(i):
        start.wait()
        return cases[i % 4]
    with ThreadPoolExecutor(8) as pool:
        got = list(pool.map(get, range(8)))
    assert all(got[i] is got[i + 4] is cases[i] for i in range(4))
    meshes = sorted(name for kind, name in reads if kind == "mesh")
    assert meshes == ["pose_01_high.ply", "pose_02_high.ply", "pose_03_high.ply", "pose_04_high.ply", "rest_high.ply"]
    assert len([r for r in reads if r[0] == "sha256"]) == 9  # 4 cases x (handles, truth) + the rest mesh


def test_a_pickled_sequence_holds_no_array_and_reads_the_same(defaust_ci):
    cases = load(defaust_ci, resolution="low")
    first = cases[0]
    blob = pickle.dumps(cases)
    assert len(blob) < first.V.nbytes  # the arrays stay behind
    copy = pickle.loads(blob)
    assert "0 read" in repr(copy) and copy.names == cases.names
    _same_case(copy[0], first)

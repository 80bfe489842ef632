"""sshade/json_file.py and the readers built on it: a FIFO, a device or a folder where a
file is expected is refused at once by the bounded and the prefix reader (never read, never
waited on), a size is counted on the bytes read, a JSON file nested 200,000 deep is an
unreadable file, not a RecursionError; a crafted-input sweep over the evaluator's, the
sweeps' and DeFAUST's JSON readers and the times reader ends every case in their documented outcome."""
from __future__ import annotations

import errno
import os
import signal

import pytest

from defaust.manifest import ManifestError, read_manifest_file
from eval.exchange.layout import read_times
from eval.run.outdir import MARKER, read_marker
from eval.run.result_store import ResultStore
from eval.run.runinfo import read_runinfo
from eval.sweeps.files import read_status
from sshade.errors import SShaDeError
from sshade.json_file import loads, read_bounded, read_json, read_prefix


@pytest.fixture(autouse=True)
def _no_hang():
    """A reader that blocks (on a FIFO) fails the test instead of hanging it."""
    def boom(*_):
        raise TimeoutError("a reader blocked")
    old = signal.signal(signal.SIGALRM, boom)
    signal.alarm(20)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, old)


def _crafted(tmp_path, name: str) -> dict:
    """``kind -> path`` of hostile stand-ins for a file called ``name``, each in its own folder."""
    out = {}
    for kind in ("deep", "fifo", "folder", "garbage", "empty", "device"):
        d = tmp_path / kind
        d.mkdir(parents=True)
        p = d / name
        if kind == "deep":
            p.write_text("[" * 200_000)
        elif kind == "fifo":
            os.mkfifo(p)
        elif kind == "folder":
            p.mkdir()
        elif kind == "garbage":
            p.write_bytes(b"\xff\xfe\x00{" * 1000)
        elif kind == "empty":
            p.write_text("")
        else:
            os.symlink("/dev/zero", p)
        out[kind] = p
    return out


@pytest.mark.parametrize("reader", [read_bounded, read_prefix])
def test_the_bounded_and_the_prefix_reader_refuse_a_fifo_a_device_and_a_folder_without_reading(tmp_path, reader):
    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    for p in (fifo, "/dev/zero", tmp_path):
        with pytest.raises(OSError) as e:
            reader(p, 10)
        assert e.value.errno in (errno.EINVAL, errno.EISDIR)
    with pytest.raises(FileNotFoundError):
        reader(tmp_path / "absent", 10)


def test_read_bounded_counts_what_it_reads_and_read_prefix_reads_at_most_n_bytes(tmp_path):
    (tmp_path / "a").write_bytes(b"x" * 11)
    with pytest.raises(OSError) as e:
        read_bounded(tmp_path / "a", 10)
    assert e.value.errno == errno.EFBIG
    assert read_bounded(tmp_path / "a", 11) == b"x" * 11
    (tmp_path / "b").write_bytes(b"0123456789" * 1000)
    assert read_prefix(tmp_path / "b", 4) == b"0123"
    assert read_prefix(tmp_path / "b", 10**6) == b"0123456789" * 1000


def test_json_nested_200000_deep_is_a_value_error_not_a_recursion_error(tmp_path):
    with pytest.raises(ValueError, match="nested too deeply"):
        loads("[" * 200_000)
    (tmp_path / "x.json").write_text('\ufeff{"a": [1, 2]}', encoding="utf-8")
    assert read_json(tmp_path / "x.json") == {"a": [1, 2]}


def test_every_json_reader_ends_a_crafted_input_in_its_documented_outcome(tmp_path):
    for kind, p in _crafted(tmp_path / "marker", MARKER).items():
        assert read_marker(p.parent) is None, kind
    for kind, p in _crafted(tmp_path / "run", "run.json").items():
        assert read_runinfo(p.parent) == {}, kind
    for kind, p in _crafted(tmp_path / "status", "status.json").items():
        assert read_status(p.parent) is None, kind
    for _kind, p in _crafted(tmp_path / "manifest", "manifest.json").items():
        with pytest.raises(ManifestError):
            read_manifest_file(p)
    for kind, p in _crafted(tmp_path / "store", "ARAP.json").items():
        store_root = p.parent.parent
        (store_root / "runs").mkdir(exist_ok=True)
        case = store_root / "runs" / f"c_{kind}"
        os.rename(p.parent, case)
        try:
            found = ResultStore(store_root).read(f"c_{kind}", "ARAP")
        except SShaDeError as e:  # the store refuses links inside it, in one line
            assert kind == "device" and "is a link" in str(e) and "\n" not in str(e)
            continue
        assert found.record is None and (found.why == "absent" or found.why.startswith("invalid")), (kind, found)


def test_the_times_reader_refuses_a_device_a_fifo_and_a_folder_in_one_line(tmp_path):
    for kind, p in _crafted(tmp_path, "times.csv").items():
        if kind in ("deep", "garbage", "empty"):
            continue
        with pytest.raises(SShaDeError, match="unreadable times file") as e:
            read_times(p)
        assert "\n" not in str(e.value), kind

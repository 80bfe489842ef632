"""sshade/mesh/io.py's dispatch and the format modules under it: every module with format
tables is in :data:`sshade.mesh.io.FORMATS` and every entry of its tables in the
dispatch (a new format is its module and that entry), each module's tables agree with
one another, and each writer's bytes are read back bit for bit by its own reader and
recognised by its own signature check, not by another format's."""
from __future__ import annotations

import importlib
import pkgutil
from pathlib import Path

import numpy as np
import pytest

import sshade.mesh
import sshade.mesh.io as mio
from tests.conftest import icosphere

TABLES = ("READERS", "PREFIX_CHECKS", "WRITERS", "SIGNED")


def _format_modules() -> list:
    """Every module of sshade/mesh but the dispatch that defines a ``READERS`` table (imported)."""
    mods = [importlib.import_module(m.name) for m in pkgutil.iter_modules(sshade.mesh.__path__, "sshade.mesh.")]
    return [m for m in mods if hasattr(m, "READERS") and m is not mio]


def test_the_dispatch_covers_every_format_modules_tables():
    found = _format_modules()
    assert {m.__name__ for m in found} == {"sshade.mesh.obj", "sshade.mesh.off", "sshade.mesh.ply",
                                           "sshade.mesh.stl"}
    assert set(mio.FORMATS) == set(found)
    for table in TABLES:
        merged = getattr(mio, table)
        entries = [(ext, f) for m in found for ext, f in getattr(m, table).items()]
        assert len({ext for ext, _ in entries}) == len(entries), table  # no extension claimed twice
        assert merged == dict(entries), table


@pytest.mark.parametrize("mod", mio.FORMATS, ids=lambda m: m.__name__)
def test_a_format_modules_tables_agree(mod):
    """Each extension read has its prefix check; each one written is read and has its
    signature check; the extensions are lower case with their dot."""
    assert set(mod.READERS) == set(mod.PREFIX_CHECKS)
    assert set(mod.WRITERS) == set(mod.SIGNED) <= set(mod.READERS)
    assert all(ext.startswith(".") and ext == ext.lower() for ext in mod.READERS)


@pytest.mark.parametrize("ext", sorted(mio.WRITERS))
def test_each_writer_is_read_back_bit_for_bit_by_its_reader_and_signed(ext):
    V, F = icosphere()
    V = V * np.random.default_rng(0).uniform(1e-20, 1e20, V.shape)
    data = mio.WRITERS[ext](V, F, mio.SIGNATURE)
    p = Path(f"m{ext}")
    mio.PREFIX_CHECKS[ext](data[:mio.PREFIX_BYTES], len(data), p)  # no refusal
    U, G = mio.READERS[ext](data, p)
    assert np.array_equal(np.asarray(U, np.float64).view(np.int64), V.view(np.int64))
    assert np.array_equal(np.asarray(G, np.int64), F)
    assert mio.SIGNED[ext](data[:512], mio.SIGNATURE) and not mio.SIGNED[ext](data[:512], "written by another")
    assert not any(check(data[:512], mio.SIGNATURE) for e, check in mio.SIGNED.items() if e != ext)


def test_write_mesh_writes_what_the_formats_writer_gives(tmp_path):
    V, F = icosphere()
    for ext, writer in mio.WRITERS.items():
        mio.write_mesh(tmp_path / f"m{ext.upper()}", V, F)  # the extension's case does not matter
        assert (tmp_path / f"m{ext.upper()}").read_bytes() == writer(V, F, mio.SIGNATURE)

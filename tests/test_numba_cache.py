"""sshade/numba_cache.py: a command runs where numba can cache nowhere (read-only
NUMBA_CACHE_DIR, unwritable home and package folders: a shared cluster install) with one
notice, its temporary cache removed at exit; a damaged cache entry is dropped and compiled
again with one notice instead of a pickle traceback."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from examples.twisted_bar import write_case
from tests.conftest import ROOT

NOWHERE = {"NUMBA_CACHE_DIR": "/dev/null/numba", "HOME": "/dev/null", "XDG_CACHE_HOME": "/dev/null/cache"}


def _env(**extra) -> dict:
    import os
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    return {**env, **extra}


@pytest.mark.slow
def test_python_m_sshade_deform_runs_where_no_cache_folder_is_writable_with_one_notice(tmp_path):
    # the package copied where its folders cannot hold a __pycache__ (a file of that name stands there);
    # /dev/null/... cannot be created, even by root
    src = tmp_path / "src"
    shutil.copytree(ROOT / "sshade", src / "sshade", ignore=shutil.ignore_patterns("__pycache__"))
    for d in [src / "sshade", *[p for p in (src / "sshade").rglob("*") if p.is_dir()]]:
        (d / "__pycache__").write_text("not a folder")
    case = write_case(tmp_path, angle=45.0, h=0.25)["paths"]
    out = tmp_path / "out.ply"
    r = subprocess.run([sys.executable, "-m", "sshade", "deform", str(case["off"]), "--sel", str(case["sel"]),
                        "--def", str(case["def"]), "-o", str(out), "--n-low", "100", "--k", "2",
                        "--param", "workers=1"],
                       cwd=tmp_path, env=_env(PYTHONPATH=str(src), **NOWHERE), capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    notices = [ln for ln in r.stderr.splitlines() if ln.startswith("notice: no writable numba cache folder")]
    assert len(notices) == 1 and "Traceback" not in r.stderr and out.is_file()
    tmp_cache = re.search(r"only, in (\S+) \(", notices[0]).group(1)
    assert not Path(tmp_cache).exists()  # removed when the command ended


KERNEL = textwrap.dedent('''
    from numba import njit

    @njit(cache=True)
    def twice(x):
        return 2 * x
''')
RUN = "from sshade.numba_cache import ensure_cache; ensure_cache(); import kern; print(kern.twice(21))"


@pytest.mark.slow
@pytest.mark.parametrize("damage", ["torn", "fifo", "sparse"])
@pytest.mark.parametrize("part", ["nbi", "nbc"])
def test_a_damaged_cache_entry_is_dropped_and_compiled_again_with_one_notice(tmp_path, part, damage):
    """A torn write, a FIFO (which would block the load) or a sparse 2 GB file in place of
    the index or the compiled code: one notice, the kernel compiled again, no traceback,
    no hang; the next run loads the new entry."""
    (tmp_path / "kern.py").write_text(KERNEL)
    cache = tmp_path / "cache"
    env = _env(PYTHONPATH=f"{tmp_path}:{ROOT}", NUMBA_CACHE_DIR=str(cache))

    def run():
        return subprocess.run([sys.executable, "-c", RUN], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300)

    r = run()
    assert r.returncode == 0 and r.stdout.strip() == "42", r.stderr
    (f,) = [p for p in cache.rglob(f"*.{part}")]
    if damage == "torn":
        data = f.read_bytes()
        f.write_bytes(data[: len(data) // 2] + b"\x00garbage" * 8)
    elif damage == "fifo":
        f.unlink()
        os.mkfifo(f)
    else:
        with open(f, "r+b") as fh:
            fh.truncate(2 * 2**30)
    r = run()
    assert r.returncode == 0 and r.stdout.strip() == "42", r.stderr
    notices = [ln for ln in r.stderr.splitlines() if ln.startswith("notice: numba cache entry")]
    assert len(notices) == 1 and "damaged" in notices[0] and "Traceback" not in r.stderr
    r = run()  # compiled again and stored: no notice the next time
    assert r.returncode == 0 and r.stdout.strip() == "42" and "notice" not in r.stderr, r.stderr

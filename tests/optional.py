"""Optional modules in the tests: import one, or skip the test with one line that names the
module, the first line of the error and how to get it.

A module that is installed but does not load counts as absent: open3d's wheel without the
system's libusb raises an ImportError naming the library (not a ModuleNotFoundError, which
is all ``pytest.importorskip`` skips on), and a shared library that fails to load can also
surface as an OSError.
"""
from __future__ import annotations

import importlib
import importlib.util

import pytest

#: How to get each optional module (the tail of the skip line).
HOW = {
    "open3d": "needs open3d-cpu (the test extra, Linux x86_64) and the system's libusb "
              "(Debian: apt-get install libusb-1.0-0); .ci/run installs it and reruns the tests marked 'open3d'",
    "torch": "PyTorch, the [neural] extra: pip install -e .[neural]; "
             ".ci/run installs it and reruns the tests marked 'neural'",
    "polyscope": "the [view] extra: pip install -e .[view]; .ci/run installs it and reruns the tests marked 'view'",
    "mlcroissant": "the test extra: pip install -e .[test]",
    "body_models": "a dependency: pip install -e . (body-models 0.26)",
    "mkdocs": "the [docs] extra: pip install -e .[docs]; .ci/run installs it and reruns the tests marked 'docs'",
}


def error_line(error: BaseException) -> str:
    """``"ImportError: <the first line of its message>"``."""
    first = next((ln.strip() for ln in str(error).splitlines() if ln.strip()), "")
    return f"{type(error).__name__}: {first}"


def skip_reason(name: str, error: str, how: str | None = None) -> str:
    """The one skip line for module ``name`` that failed to load with ``error`` (its
    :func:`error_line`); ``how``: how to get it (default :data:`HOW`)."""
    return f"{name} cannot be imported ({error}): {how or HOW.get(name, 'not installed')}"


def optional_import(name: str, how: str | None = None):
    """The module ``name``, or skip (the test, or the module when called at its top level)
    with :func:`skip_reason` when it cannot be imported for any reason a missing or broken
    install gives (ImportError, OSError). ``how``: how to get it (default :data:`HOW`)."""
    try:
        return importlib.import_module(name)
    except (ImportError, OSError) as e:
        pytest.skip(skip_reason(name, error_line(e), how), allow_module_level=True)


def locate_or_skip(name: str, how: str | None = None) -> None:
    """Skip (as :func:`optional_import`) unless ``name`` is installed, found without
    importing it: for a module that a child process imports."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, OSError, ValueError) as e:
        pytest.skip(skip_reason(name, error_line(e), how), allow_module_level=True)
    if spec is None:
        pytest.skip(skip_reason(name, f"ModuleNotFoundError: No module named {name!r}", how), allow_module_level=True)


def found(name: str) -> bool:
    """``name`` is installed (located without importing it); a finder that raises while
    looking for it counts as not found."""
    try:
        return importlib.util.find_spec(name) is not None
    except (ImportError, OSError, ValueError):
        return False

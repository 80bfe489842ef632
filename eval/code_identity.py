"""The identity of the code that produces a result: part of every result-store key
(:mod:`eval.store`), so that a stored row is reused only by the code that computed it.

A (case, method) row depends on the method's code, on the harness that runs and scores
it (:mod:`sshade.guard`, :mod:`eval.metrics`, the reference columns) and on the
numerical libraries beneath them. :func:`code_identity` names all three:

- ``sources``: SHA-256 of the source of the project's packages (:data:`PACKAGES`: every
  ``.py`` file under them, by relative path and bytes), whether or not they are in a git
  checkout, committed or not. A change to any of them (the method, a metric, the guard)
  makes every stored row stale; a change to the docs, the tests or ``results/`` does not.
  Coarser than it could be, never finer: a module is not second-guessed as irrelevant.
- ``versions``: the installed versions of :data:`NUMERICAL` (None when absent).
- ``plugin``: for a method whose class lives outside the project's packages (a plug-in,
  :func:`sshade.method.is_plugin`), the SHA-256 of the file that defines the class (its
  other modules are not followed: a plug-in spread over several files should name its
  version in a parameter); None for our own methods, which ``sources`` covers.

The git commit and dirty flag are recorded beside (:func:`eval.runinfo.git_info`, in
``run.json`` and each record) but are not part of the key: a commit that changes only the
docs leaves the stored rows valid, an uncommitted edit of a method does not.

Example::

    >>> ident = code_identity(None)
    >>> sorted(ident), len(ident["sources"])
    (['plugin', 'sources', 'versions'], 64)
"""
from __future__ import annotations

import functools
import hashlib
import inspect
from importlib import metadata
from pathlib import Path

from .runinfo import REPO_ROOT

__all__ = ["PACKAGES", "NUMERICAL", "sources_digest", "numerical_versions", "code_identity", "describe_change"]

#: The project's packages whose source makes a row (the four floors of the house).
PACKAGES = ("sshade", "baselines", "defaust", "eval")

#: Distributions whose version can change a row's numbers: the solvers and mesh
#: processing beneath the methods, and PyTorch (Implicit-ARAP, plug-ins).
NUMERICAL = ("numpy", "scipy", "libigl", "pymeshlab", "numba", "cholespy", "trimesh", "torch")


@functools.lru_cache(maxsize=4)
def sources_digest(packages: tuple = PACKAGES, root: str | None = None) -> str:
    """SHA-256 (hex, 64 characters) of every ``.py`` file under the ``packages`` folders
    of ``root`` (default: this checkout or installed tree), each as its path relative to
    ``root`` and its bytes, in sorted order; cached per process (the code of a running
    process does not change under it)."""
    base = Path(root) if root is not None else REPO_ROOT
    h = hashlib.sha256()
    for pkg in packages:
        for p in sorted((base / pkg).rglob("*.py")):
            if "__pycache__" in p.parts:
                continue
            h.update(str(p.relative_to(base)).encode() + b"\0")
            h.update(p.read_bytes() + b"\0")
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def numerical_versions() -> dict:
    """``{distribution: version or None}`` for :data:`NUMERICAL` (installed metadata)."""
    out = {}
    for dist in NUMERICAL:
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    return out


def _plugin_digest(method) -> str | None:
    """SHA-256 of the file defining ``type(method)`` when it lies outside :data:`PACKAGES`
    (a plug-in), None for the project's own methods; ``"unknown"`` when the file cannot
    be found or read (such a plug-in's rows are still keyed, by that word)."""
    cls = type(method)
    if cls.__module__.split(".")[0] in PACKAGES:
        return None
    try:
        f = inspect.getsourcefile(cls) or inspect.getfile(cls)
        return hashlib.sha256(Path(f).read_bytes()).hexdigest()
    except (TypeError, OSError):
        return "unknown"


def code_identity(method) -> dict:
    """The code identity of ``method``'s rows (module docstring): ``{"sources": hex,
    "versions": {dist: version}, "plugin": hex or None}``. ``method``: the built method
    object, or None for the harness alone (``plugin`` None)."""
    return {"sources": sources_digest(), "versions": dict(numerical_versions()),
            "plugin": None if method is None else _plugin_digest(method)}


def describe_change(old, new: dict) -> str:
    """In words, what differs between a stored record's code identity ``old`` (any JSON
    value: records written before code identities were keyed have none) and ``new``:
    e.g. ``"the project's sources changed"``, ``"numpy 1.26.4 -> 2.1.0"``, ``"the
    plug-in's source changed"``; ``""`` when they agree.

    >>> describe_change({"sources": "a", "versions": {"numpy": "1"}, "plugin": None},
    ...                 {"sources": "b", "versions": {"numpy": "2"}, "plugin": None})
    "the project's sources changed; numpy 1 -> 2"
    """
    if not isinstance(old, dict):
        return "a record without the identity of its code (written by an older version)"
    parts = []
    if old.get("sources") != new.get("sources"):
        parts.append("the project's sources changed")
    ov, nv = old.get("versions") if isinstance(old.get("versions"), dict) else {}, new.get("versions") or {}
    parts += [f"{d} {ov.get(d)} -> {nv.get(d)}" for d in sorted(set(ov) | set(nv)) if ov.get(d) != nv.get(d)]
    if old.get("plugin") != new.get("plugin"):
        parts.append("the plug-in's source changed")
    return "; ".join(parts)

"""The CPU cores this process may use (:func:`available_cores`: the affinity mask, capped
by :data:`CORES_VARIABLE` when a job runner gave this process a share of the machine) and
the worker count of a pool over them (:func:`pool_size`), for the sampling pool and the
remesher's threads.

Example::

    >>> pool_size(4, 2), pool_size(3, 0)
    (2, 1)
"""
from __future__ import annotations

import os

__all__ = ["CORES_VARIABLE", "available_cores", "pool_size"]

#: Set by a job runner in its workers to their share of the cores; :func:`available_cores` reads it.
CORES_VARIABLE = "SSHADE_JOB_CORES"


def available_cores() -> int:
    """CPU cores this process may use, >= 1: its affinity mask where the OS has one (else
    the CPU count), at most :data:`CORES_VARIABLE` when set (a job runner's worker)."""
    try:
        n = max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - macOS, Windows
        n = max(1, os.cpu_count() or 1)
    share = os.environ.get(CORES_VARIABLE, "")
    return max(1, min(n, int(share))) if share.isdigit() and int(share) > 0 else n


def pool_size(workers: int | None, n_jobs: int) -> int:
    """Worker processes (or threads) for ``n_jobs`` jobs: ``workers`` (None:
    :func:`available_cores`), capped at ``n_jobs``, at least 1.

    Examples
    --------
    >>> pool_size(4, 2), pool_size(3, 0)
    (2, 1)
    """
    w = available_cores() if workers is None else int(workers)
    return max(1, min(w, int(n_jobs)))

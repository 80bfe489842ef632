"""The cache key of a reference solution (:func:`reference_key`): what decides whether a
cached reference of :mod:`eval.metrics.reference` is reused. It decides which artifact is
read, never its numbers, as :mod:`eval.run.result_store`'s keys do for rows; the code that
solves the reference is its identity (:func:`eval.run.code_identity.artifact_identity`).
Floor 0 of eval/ (eval/run/, the ground floor, tests/test_layering.py); notes: docs/reproduction.md."""
from __future__ import annotations

import hashlib
import json

import numpy as np

from eval.run.code_identity import artifact_identity
from eval.run.library_versions import numerical_versions

__all__ = ["REFERENCE_VERSION", "reference_key"]

#: Bumped whenever the reference solver's output for the same inputs and code changes
#: (e.g. a library's behaviour that no version number shows).
REFERENCE_VERSION = 1


def reference_key(V, F, handles, targets, energy: str, solver: dict) -> str:
    """SHA-256 (hex) of everything a reference depends on: the bytes of ``V`` (n, 3)
    float64, ``F`` (m, 3) int64, ``handles`` (h,) int64, ``targets`` (h, 3) float64, the
    energy, the solver settings, :data:`REFERENCE_VERSION` and the code that solves it
    (:func:`eval.run.code_identity.artifact_identity`: the import closure of
    :mod:`eval.metrics.reference`, the energies, their operators and solvers included),
    with the numerical libraries' versions: a reference cached by other code is computed
    again, never reused (and a row scored against it stays only if it comes out bit for
    bit the same, :mod:`eval.experiments.cases.reference_cutoff`)."""
    h = hashlib.sha256()
    for a, dt in ((V, np.float64), (F, np.int64), (handles, np.int64), (targets, np.float64)):
        h.update(np.ascontiguousarray(a, dt).tobytes())
        h.update(str(np.shape(a)).encode())
    code = {"sources": artifact_identity()["sources"], "versions": numerical_versions()}
    h.update(json.dumps({"energy": energy, "solver": solver, "version": REFERENCE_VERSION, "code": code},
                        sort_keys=True).encode())
    return h.hexdigest()

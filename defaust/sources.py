"""The builder's view of its three sources: what each item of a DeFAUST build needs.

A :class:`Source` plans the build (subjects and their target poses) and gives, per
subject, the low-res rest mesh, its landmarks and each target at low and high resolution
(posable bodies: the same skinning; FAUST: through the subdivision), plus what enters the
items' keys and the manifest. Sources: :class:`AnnySource` (default; :mod:`defaust.anny_source`),
:class:`FaustSource` (a user's MPI-FAUST registrations, :mod:`defaust.faust_source`)
and :class:`SyntheticSource` (the implicit bodies, :mod:`defaust.synthetic`); see
:data:`SOURCES`. Each keeps per-subject caches (only the current subject's data).
"""
from __future__ import annotations

import logging

import numpy as np

from sshade.errors import SShaDeError
from sshade.mesh.io import read_mesh

from .anny_fixed import load_anny_fixed
from .anny_model import assets_fingerprint, find_anny_assets, versions
from .anny_poses import LAST_TARGET_SHIFT, LAST_TARGET_TURN_DEG, REST_CORRECTIONS, pose_to_spec, resolve_poses
from .anny_sampling import SAMPLER_VERSION, sampled_subject
from .anny_source import SUBJECTS, anny_subject
from .config import BuildConfig
from .faust_source import FAUST_LANDMARKS, FAUST_N_VERTICES, discover_faust, faust_subjects
from .registration_gt import change_pct, map_target, surface_map
from .self_intersections import self_intersections
from .skinning import high_res_weights, transfer_weights
from .store import sha256_file
from .synthetic import synthetic_subject
from .synthetic_poses import POSE_NAMES, pose_names

__all__ = ["Source", "FaustSource", "ModelSource", "SyntheticSource", "AnnySource", "SOURCES"]

log = logging.getLogger("defaust")


class Source:
    """Per-source data access with per-subject caches (only what an item needs).

    Subclasses implement :meth:`plan`, :meth:`rest_low`, :meth:`landmarks`,
    :meth:`target_low`, :meth:`rest_inputs`, :meth:`pose_inputs`, :meth:`pose_name` and
    :meth:`subject_record`; a source with ``has_high_gt`` also :meth:`target_high`.
    """

    #: whether the source poses the high-res rest mesh too (ground truth at high res)
    has_high_gt = False

    def __init__(self, cfg: BuildConfig):
        self.cfg = cfg
        self._cache: dict = {}

    def plan(self) -> dict[int, list[int]]:
        """Subject -> its target poses (ids), in build order."""
        raise NotImplementedError

    def start_subject(self, s: int) -> None:
        """Forget cached data of other subjects (bounded memory)."""
        self._cache = {k: v for k, v in self._cache.items() if k[1] == s}

    def cached(self, key: tuple, make):
        """The cached value of ``key`` (``(what, subject, ...)``), made by ``make()`` once."""
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]

    def remember(self, key: tuple, value) -> None:
        """Cache ``value`` under ``key`` (``(what, subject, ...)``)."""
        self._cache[key] = value

    def recalled(self, key: tuple, default=None):
        """The value cached under ``key``, or ``default``."""
        return self._cache.get(key, default)

    def rest_low(self, s: int) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def landmarks(self, s: int) -> dict[str, int]:
        raise NotImplementedError

    def rest_info(self, s: int, Vh, Fh) -> dict:
        """Extra entries of the rest item's ``info`` (none by default); ``Vh``, ``Fh`` the
        high-res rest mesh, None when the build has none."""
        return {}

    def pose_info(self, s: int, p: int, Vg, Fh) -> dict:
        """Extra entries of a pose item's ``info`` (none by default)."""
        return {}

    def ls3_iterations(self, s: int) -> int:
        """The LS3 Loop iterations of subject ``s``'s high-res rest (its rest item's
        ``ls3_iterations``); SShaDeError if the rest item records none."""
        it = self.recalled(("rest_info", s), {}).get("ls3_iterations")
        if it is None:
            raise SShaDeError(f"subject {s}: the rest item records no ls3_iterations; rebuild it "
                              "(delete its rest_high.ply and rerun)")
        return int(it)


#: How a faust pose's high-res ground truth is made; part of the faust pose items' keys, so
#: a build made before it (no ``pose_YY_high.ply``) rebuilds its pose items on resume.
FAUST_HIGH_GT = ("LS3 Loop subdivision of the target registration, read at each rest_high vertex's closest point "
                 "on the subdivided rest (defaust.registration_gt)")


class FaustSource(Source):
    """A user's MPI-FAUST registrations; each item's key holds its files' checksums. The
    high-res ground truth is the target registration's LS3 Loop subdivision read at the
    high-res rest vertices' closest points on the subdivided rest
    (:mod:`defaust.registration_gt`; docs/defaust.md §2)."""

    has_high_gt = True

    def __init__(self, cfg):
        super().__init__(cfg)
        self.files = discover_faust(cfg.faust_root)
        self._sha: dict = {}

    def plan(self):
        return faust_subjects(self.files, n_targets=self.cfg.n_poses - 1, target_poses=self.cfg.faust_target_poses,
                              subjects=self.cfg.subjects)

    def file_sha(self, s, p) -> str:
        if (s, p) not in self._sha:
            self._sha[(s, p)] = sha256_file(self.files[(s, p)])
        return self._sha[(s, p)]

    def mesh(self, s, p):
        return self.cached(("mesh", s, p), lambda: read_mesh(self.files[(s, p)]))

    def rest_low(self, s):
        return self.mesh(s, 0)

    def landmarks(self, s):
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

    def surface_map(self, s, Vh):
        """The high-res rest ``Vh`` ((p, 3) float64 metres) on subject ``s``'s subdivided
        rest (:func:`defaust.registration_gt.surface_map`), made once per subject."""
        V0, F0 = self.rest_low(s)
        return self.cached(("surface_map", s), lambda: surface_map(V0, F0, Vh, self.ls3_iterations(s)))

    def target_high(self, s, p, Vh):
        """Target pose ``p`` at high resolution: :func:`defaust.registration_gt.map_target`
        of the target registration; (p, 3) float64 metres on the faces of ``Vh`` (the
        high-res rest, (p, 3) float64). SShaDeError if the target's faces or subdivided
        topology differ from the rest's, or the rest item records no ``ls3_iterations``."""
        return map_target(self.surface_map(s, Vh), self.target_low(s, p), self.rest_low(s)[1])

    def pose_info(self, s, p, Vg, Fh):
        """Volume and area change of the high-res ground truth (against ``rest_high``) and
        of the target registration (against the rest registration), in %, and the largest
        offset of a high-res rest vertex from the subdivided rest (metres). Called after
        :meth:`target_high` (the build does), whose rest meshes it reuses."""
        V0, F0 = self.rest_low(s)
        Vh, _ = self.recalled(("rest_high", s))  # the build cached it for target_high
        hi, lo = change_pct(Vh, Vg, Fh), change_pct(V0, self.target_low(s, p), F0)
        return {"gt_volume_change_pct_high": hi["volume_change_pct"], "gt_area_change_pct_high": hi["area_change_pct"],
                "gt_volume_change_pct_low": lo["volume_change_pct"], "gt_area_change_pct_low": lo["area_change_pct"],
                "rest_high_offset_max_m": self.recalled(("surface_map", s)).offset_max}

    def rest_inputs(self, s):
        return {"rest_file_sha256": self.file_sha(s, 0)}

    def pose_inputs(self, s, p):
        return {"rest_file_sha256": self.file_sha(s, 0), "target_file_sha256": self.file_sha(s, p),
                "high_ground_truth": FAUST_HIGH_GT}

    def pose_name(self, s, p):
        return f"faust_pose_{p}"

    def subject_record(self, s, poses):
        return {"rest_file": str(self.files[(s, 0)]), "target_files": {str(p): str(self.files[(s, p)]) for p in poses}}


class ModelSource(Source):
    """A source whose subject is a posable body model (``model(s)`` with ``V``, ``F``,
    ``W``, ``landmarks`` and ``posed(p, V=None, W=None)``): the synthetic bodies and ANNY.

    Subclasses set ``names`` (pose ``p`` is ``names[p]``, ``names[0]`` the rest pose) and
    implement :meth:`make_model`, :meth:`high_weights` and :meth:`check_subjects`.
    """

    has_high_gt = True
    names: list

    def make_model(self, s):
        raise NotImplementedError

    def high_weights(self, s, m, Vh, ls3_iterations: int | None = None) -> np.ndarray:
        """Skinning weights of the rest vertices ``Vh`` of a remesh of model ``m`` (made
        after ``ls3_iterations`` LS3 Loop iterations; None: the high-res one's)."""
        raise NotImplementedError

    def check_subjects(self, want: list[int]) -> None:
        """Raise SShaDeError if a requested subject id does not exist."""
        raise NotImplementedError

    def plan(self):
        subs = list(range(int(self.cfg.n_subjects)))
        if self.cfg.subjects is not None:
            given = [int(s) for s in self.cfg.subjects]
            twice = sorted({s for s in given if given.count(s) > 1})
            if not given or twice:
                raise SShaDeError("subjects must name each subject to build once (or be null for the first "
                                  f"n_subjects), got {list(self.cfg.subjects)}"
                                  + (f": {', '.join(map(str, twice))} more than once" if twice else ": none"))
            subs = sorted(set(given))
            self.check_subjects(subs)
        return {s: list(range(1, len(self.names))) for s in subs}

    def model(self, s):
        return self.cached(("model", s), lambda: self.make_model(s))

    def rest_low(self, s):
        m = self.model(s)
        return m.V, m.F

    def landmarks(self, s):
        return dict(self.model(s).landmarks)

    def target_low(self, s, p):
        return self.model(s).posed(p)

    def target_high(self, s, p, Vh):
        """Target pose ``p`` of the high-res rest mesh ``Vh`` by the same skinning."""
        return self.target_at(s, p, Vh, "high")

    def target_at(self, s, p, V, tag: str, ls3_iterations: int | None = None):
        """Target pose ``p`` of rest mesh ``V`` of resolution ``tag`` (``high`` or ``rN``,
        a remesh after ``ls3_iterations`` LS3 Loop iterations; None: the high one's) by
        the same skinning, its weights made once per subject and resolution."""
        m = self.model(s)
        W = self.cached((f"W_{tag}", s), lambda: self.high_weights(s, m, V, ls3_iterations))
        return m.posed(p, V=V, W=W)

    def pose_name(self, s, p):
        return self.names[p]


class SyntheticSource(ModelSource):
    """The implicit bodies of :mod:`defaust.synthetic` (seeded by ``seed`` and the subject)."""

    def __init__(self, cfg):
        super().__init__(cfg)
        self.names = pose_names(cfg.n_poses)
        if int(cfg.n_subjects) < 1:
            raise SShaDeError(f"n_subjects must be >= 1, got {cfg.n_subjects}")

    def check_subjects(self, want):
        bad = [s for s in want if s < 0]
        if bad:
            raise SShaDeError(f"subject ids must be >= 0, got {bad}")

    def make_model(self, s):
        c = self.cfg
        return synthetic_subject(c.seed, s, n_poses=c.n_poses, voxel_size=c.synthetic_voxel,
                                 n_vertices=c.synthetic_vertices, blend=c.synthetic_blend,
                                 remesh_iterations=c.synthetic_remesh_iterations)

    def high_weights(self, s, m, Vh, ls3_iterations=None):
        return transfer_weights(m.V, m.F, m.W, Vh)

    def rest_inputs(self, s):
        return {}

    def pose_inputs(self, s, p):
        return {"pose_name": self.names[p]}

    def subject_record(self, s, poses):
        return {"body_seed": [int(self.cfg.seed), 0xB0D1, int(s)],
                "pose_seeds": {str(p): [int(self.cfg.seed), 0x905E, int(s), POSE_NAMES.index(self.names[p])]
                               for p in poses},
                "pose_names": {str(p): self.names[p] for p in [0] + list(poses)}}


class AnnySource(ModelSource):
    """ANNY bodies (:mod:`defaust.anny_source`); the model
    (:func:`defaust.anny_fixed.load_anny_fixed`) is loaded only when an item is built (a
    complete build is verified without it); ``anny.cache`` is not used. Fixed phenotypes and library
    poses by default; drawn per subject with ``anny.phenotypes=sampled`` and/or
    ``anny.poses=sampled`` (:mod:`defaust.anny_sampling`), the draws recorded with the
    rest item (``info.sampled``) and keyed by what makes them (seed, sampler, difficulty)."""

    def __init__(self, cfg):
        super().__init__(cfg)
        self.sampled_poses = cfg.anny_poses == "sampled"
        self.fixed = cfg.anny_phenotypes == "fixed"
        self.poses = None if self.sampled_poses else resolve_poses(cfg.anny_poses)
        self.names = (["rest"] + [f"sampled_{j}" for j in range(1, int(cfg.anny_n_targets) + 1)]
                      if self.sampled_poses else [p.name for p in self.poses])
        self.root = find_anny_assets(cfg.anny_root)
        self.fingerprint = assets_fingerprint(self.root)
        self.versions = versions()
        n = int(cfg.n_subjects)
        if self.fixed and not 1 <= n <= len(SUBJECTS):
            raise SShaDeError(f"n_subjects must be in [1, {len(SUBJECTS)}] for the anny source with its fixed "
                              f"phenotypes, got {n} (anny.phenotypes=sampled draws any number)")

    @property
    def sampling(self) -> bool:
        """Whether a phenotype or the poses are drawn."""
        return self.sampled_poses or not self.fixed

    def check_subjects(self, want):
        bad = [s for s in want if not 0 <= s < (len(SUBJECTS) if self.fixed else 2**31)]
        if bad:
            raise SShaDeError(f"anny subject ids must be in 0..{len(SUBJECTS) - 1}, got {bad}" if self.fixed
                              else f"anny subject ids must be >= 0, got {bad}")

    def make_model(self, s):
        if not self.sampling:
            return anny_subject(s, poses=self.poses[1:], root=self.root)
        c = self.cfg
        got = sampled_subject(s, seed=int(c.seed), model=load_anny_fixed(self.root),
                              phenotypes=c.anny_phenotypes, poses="sampled" if self.sampled_poses else self.poses[1:],
                              n_targets=int(c.anny_n_targets), difficulty=float(c.anny_difficulty))
        self.remember(("sampled", s), got.record)
        return got.subject

    def high_weights(self, s, m, Vh, ls3_iterations=None):
        k = self.ls3_iterations(s) if ls3_iterations is None else ls3_iterations
        return high_res_weights(m.V, m.F, m.W, Vh, k)

    def rest_info(self, s, Vh, Fh):
        m = self.model(s)
        out = {"stature_m": round(float(m.stature), 4),
               "n_self_intersecting_faces_low": int(self_intersections(m.V, m.F).size)}
        if Vh is not None:  # no high-res mesh: resolutions without high
            out["n_self_intersecting_faces_high"] = int(self_intersections(Vh, Fh).size)
        if self.sampling:
            out["sampled"] = {**self.recalled(("sampled", s)), "poses_drawn": [pose_to_spec(p) for p in m.poses]}
        return out

    def pose_info(self, s, p, Vg, Fh):
        n = int(self_intersections(Vg, Fh).size)
        n_rest = self.recalled(("rest_info", s), {}).get("n_self_intersecting_faces_high")
        if n_rest is not None and n > n_rest:
            log.warning("subject %d pose %d (%s): %d self-intersecting faces at high resolution, %d in the rest "
                        "pose's LS3 surface", s, p, self.names[p], n, n_rest)
        return {"n_self_intersecting_faces_high": n}

    def _sampling_key(self) -> dict:
        c = self.cfg
        return {"sampler": SAMPLER_VERSION, "seed": int(c.seed), "phenotypes": c.anny_phenotypes,
                "poses": ("sampled" if self.sampled_poses else [pose_to_spec(p) for p in self.poses[1:]]),
                **({"difficulty": float(c.anny_difficulty), "n_targets": int(c.anny_n_targets)}
                   if self.sampled_poses else {})}

    def rest_inputs(self, s):
        corrections = [[r.kind, r.joint, list(r.vector), r.degrees] for r in REST_CORRECTIONS]
        if self.sampling:  # the body and its poses are drawn together (a body is redrawn when a pose fails)
            return {"anny_sampling": self._sampling_key(), "anny_rest_corrections": corrections}
        return {"anny_phenotype": SUBJECTS[s].record(), "anny_rest_corrections": corrections}

    def pose_inputs(self, s, p):
        last = p == len(self.names) - 1
        pose = {"anny_pose_sampled": p} if self.sampled_poses else {"anny_pose": pose_to_spec(self.poses[p])}
        return {**pose, "last_target": last,
                "last_target_move": [LAST_TARGET_TURN_DEG, list(LAST_TARGET_SHIFT)] if last else None}

    def subject_record(self, s, poses):
        last = max(poses)
        drawn = self.recalled(("rest_info", s), {}).get("sampled") if self.sampling else None
        if self.sampling and drawn is None:
            raise SShaDeError(f"anny subject {s}: its rest item records no draws (info.sampled); rebuild it "
                              "(delete its rest_high.ply and rerun)")
        specs = drawn["poses_drawn"] if drawn else [pose_to_spec(p) for p in self.poses]
        rec = {"phenotype": drawn["phenotype"] if drawn else SUBJECTS[s].record(),
               "pose_names": {str(p): self.names[p] for p in [0] + list(poses)},
               "poses": {str(p): specs[p] for p in [0] + list(poses)},
               "last_target": {"pose": int(last), "turn_deg": float(LAST_TARGET_TURN_DEG),
                               "shift_m": [float(x) for x in LAST_TARGET_SHIFT],
                               "about": "the vertical axis through the rest pose's root (pelvis)"}}
        if drawn:
            rec["sampled"] = {k: v for k, v in drawn.items() if k != "poses_drawn"}
        return rec


#: ``source=`` name -> its :class:`Source`.
SOURCES: dict[str, type[Source]] = {"anny": AnnySource, "faust": FaustSource, "synthetic": SyntheticSource}

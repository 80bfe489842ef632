"""``python -m defaust [overrides]``: the DeFAUST builder's command line (Hydra).

Config: ``conf/defaust/config.yaml`` (+ ``conf/defaust/preset/{full,ci}.yaml``). Examples::

    python -m defaust out=/data/defaust                     # ANNY bodies (default source)
    python -m defaust source=faust faust.root=/data/MPI-FAUST out=/data/defaust_faust
    python -m defaust preset=ci out=/tmp/defaust_ci subjects=[0]
    python -m defaust out=DIR anny.poses=[arms_forward,knee_lift,side_bend,step]
    python -m defaust out=DIR anny.phenotypes=sampled anny.poses=sampled n_subjects=200

Hydra is used only here; :func:`config_from_omegaconf` maps its config onto
:class:`defaust.config.BuildConfig` for :func:`defaust.build.build_defaust`.
"""
from __future__ import annotations

import logging
import sys
from pathlib import Path

from harness.checks import check_int_list, check_number, config_value
from harness.command import hydra_main, run_command
from harness.confdir import config_dir
from harness.slurm_array import cluster_options
from sshade.errors import SShaDeError
from sshade.pipeline import MAX_SEED

from .build import build_defaust
from .config import BuildConfig

__all__ = ["CONF_DIR", "config_from_omegaconf", "compose_config", "run", "main"]

CONF_DIR = config_dir("defaust")  # conf/defaust of a source checkout, else the installed package data

log = logging.getLogger("defaust")


def _abs(path) -> str:
    """Resolve ``path`` against the directory the command was started from."""
    try:
        from hydra.core.hydra_config import HydraConfig
        from hydra.utils import to_absolute_path

        if HydraConfig.initialized():
            return to_absolute_path(str(Path(str(path)).expanduser()))
    except ImportError:  # pragma: no cover
        pass
    return str(Path(str(path)).expanduser().resolve())


def config_from_omegaconf(cfg) -> BuildConfig:
    """Map the Hydra/OmegaConf config onto a :class:`BuildConfig`.

    Raises
    ------
    SShaDeError if ``out`` is missing, the source unknown, a number is not a number
    (``seed=abc``, ``synthetic.voxel_size=inf``: the message names the key) or, for
    ``source=faust``, ``faust.root`` is missing. The ranges are checked by
    :meth:`BuildConfig.validate`.

    Examples
    --------
    Example::

        bc = config_from_omegaconf(compose_config(["preset=ci", "out=/tmp/x"]))
    """
    from omegaconf import OmegaConf

    c = OmegaConf.to_container(cfg, resolve=True)
    if c.get("out") in (None, ""):
        raise SShaDeError("no output folder: pass out=DIR (e.g. python -m defaust out=data/defaust)")
    src = c.get("source", "anny")
    if src not in ("anny", "faust", "synthetic"):
        raise SShaDeError(f"unknown source {src!r}; use source=anny, source=faust or source=synthetic")
    faust = c.get("faust") or {}
    if src == "faust" and faust.get("root") in (None, ""):
        raise SShaDeError("source=faust needs faust.root=DIR (a folder with tr_reg_XYZ.ply files or an "
                          "MPI-FAUST folder with training/registrations/)")
    an = c.get("anny") or {}
    d = BuildConfig(out="x")

    def num(key, default, kind=int):  # a number of the config, or SShaDeError naming its key
        seed = key == "seed"
        return check_number(config_value(cfg, key, default), key, kind=kind, min=0 if seed else None,
                            max=MAX_SEED if seed else None)

    def ints(key):
        return check_int_list(config_value(cfg, key, None), key, min=-2**31, allow_none=True)
    vertex_range = config_value(cfg, "high_res.vertex_range", None)
    progress = c.get("progress", True)
    if not isinstance(progress, bool):
        raise SShaDeError(f"progress must be true or false, got {progress!r}")
    return BuildConfig(
        out=_abs(c["out"]), source=src, seed=num("seed", 0),
        subjects=ints("subjects"), n_subjects=num("n_subjects", d.n_subjects), n_poses=num("n_poses", d.n_poses),
        vertex_range=d.vertex_range if vertex_range is None else tuple(
            check_int_list(vertex_range, "high_res.vertex_range", min=-2**31, allow_none=False)),
        remesh_iterations=num("high_res.remesh_iterations", d.remesh_iterations),
        remesh_check_distance=(c.get("high_res") or {}).get("check_distance", d.remesh_check_distance),
        n_per_landmark=num("handles.n_per_landmark", d.n_per_landmark),
        neighbourhood=num("handles.neighbourhood", d.neighbourhood),
        static_threshold=num("handles.static_threshold", d.static_threshold, float),
        faust_root=None if faust.get("root") in (None, "") else _abs(faust["root"]),
        faust_target_poses=ints("faust.target_poses"),
        synthetic_vertices=num("synthetic.n_vertices", d.synthetic_vertices),
        synthetic_voxel=num("synthetic.voxel_size", d.synthetic_voxel, float),
        synthetic_blend=num("synthetic.skin_blend", d.synthetic_blend, float),
        synthetic_remesh_iterations=num("synthetic.remesh_iterations", d.synthetic_remesh_iterations),
        anny_poses=None if an.get("poses") is None else an["poses"] if an["poses"] == "sampled"
        else _as_list(an["poses"]),
        anny_phenotypes=str(an.get("phenotypes", d.anny_phenotypes)),
        anny_difficulty=num("anny.difficulty", d.anny_difficulty, float),
        anny_n_targets=num("anny.n_targets", d.anny_n_targets),
        anny_root=None if an.get("root") in (None, "") else _abs(an["root"]),
        anny_cache=None if an.get("cache") in (None, "") else _abs(an["cache"]),
        resolutions=_resolutions(c.get("resolutions", list(d.resolutions))),
        cluster=cluster_options(c.get("cluster")),
        progress=progress, workers=check_number(config_value(cfg, "workers", None), "workers", min=1, max=4096,
                                                allow_none=True),
    )


def _resolutions(x) -> list:
    """``resolutions`` as given: a list of ``high`` and vertex counts (numbers as ints;
    the ranges are :meth:`BuildConfig.validate`'s)."""
    out = []
    for r in _as_list(x):
        if isinstance(r, str) and r.strip().isdigit():
            r = int(r)
        if not (r == "high" or isinstance(r, int) and not isinstance(r, bool)):
            raise SShaDeError(f"resolutions must list high and vertex counts, got {r!r}")
        out.append(r)
    return out


def _as_list(x):
    if isinstance(x, (list, tuple)):
        return list(x)
    return [x]


def compose_config(overrides=()):
    """The builder's config with command-line style overrides, without running Hydra's
    app (for tests and notebooks).

    Examples
    --------
    Example::

        cfg = compose_config(["preset=ci", "out=/tmp/x"]); cfg.high_res.vertex_range
        # -> [8000, 12000]
    """
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    if GlobalHydra.instance().is_initialized():
        GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONF_DIR, version_base=None):
        return compose(config_name="config", overrides=list(overrides))


def run(cfg):
    """Build from a Hydra config; log a summary. Returns the :class:`BuildReport`."""
    bc = config_from_omegaconf(cfg)
    log.info("DeFAUST %s -> %s", bc.source, bc.out)
    rep = build_defaust(bc)
    n_hi = [it["info"]["n_vertices_high"] for k, it in rep.manifest["items"].items()
            if k.endswith("/rest") and "n_vertices_high" in it.get("info", {})]
    log.info("done: %d item(s) built, %d skipped (already complete); %d subject(s); high-res vertices %s",
             len(rep.built), len(rep.skipped), len(rep.manifest["subjects"]),
             f"{min(n_hi)}-{max(n_hi)}" if n_hi else "-")
    for s, t in sorted(rep.subject_seconds.items()):
        if t > 0:
            log.info("subject %02d: %.1f s", s, t)
    log.info("manifest: %s", Path(bc.out) / "manifest.json")
    return rep


def _main(cfg) -> None:
    """Hydra task of ``python -m defaust``: build; a bad parameter, an OSError (one
    ``error: ...`` line, status 2) or Ctrl-C (``interrupted``, 130) ends the process
    through :func:`harness.command.run_command`."""
    logging.getLogger("defaust").setLevel(logging.INFO)
    def work():
        try:
            return run(cfg)
        except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the partial manifest keeps every finished item
            print("the build is partial (defaust.load and verify say so); run the same command again to finish "
                  "it: finished items are kept", file=sys.stderr)
            raise

    rc = run_command(work, where=cfg.get("out"))
    if rc:
        raise SystemExit(rc)


def main() -> None:
    """Console entry point: Hydra parses the overrides. The command line is composed
    and every builder parameter checked (:func:`config_from_omegaconf`,
    :meth:`BuildConfig.validate`) before anything is built or any folder made
    (:func:`harness.command.hydra_main`)."""
    def check(cfg):
        config_from_omegaconf(cfg).validate()
    hydra_main(_main, CONF_DIR, check=check)

"""The resolutions of a DeFAUST build, named once: ``low`` (the source's base mesh),
``high`` (LS3 Loop + isotropic remesh to ``vertex_range``, the paper's setting) and ``rN``
(``resolutions=[..., N]``: a remesh of the same surface with N vertices); which a build's
manifest has (:func:`build_resolutions`), a name checked (:func:`check_resolution`), and
what the builder makes of ``resolutions`` (:func:`extra_counts`, :func:`resolution_key`).
Files: ``rest_<name>.ply``, ``pose_YY_<name>.ply``; docs/defaust.md, "Resolutions"."""
from __future__ import annotations

import re

from sshade.errors import SShaDeError

__all__ = ["RESOLUTIONS", "check_resolution", "build_resolutions", "extra_counts", "resolution_key"]

#: The two meshes of a default build's subjects: ``high`` and ``low``.
RESOLUTIONS = ("high", "low")
_EXTRA_RESOLUTION = re.compile(r"r[1-9][0-9]*")


def check_resolution(resolution) -> str:
    """``resolution`` checked: ``"high"``, ``"low"`` or ``"rN"`` (N >= 1, a build's extra
    remesh); SShaDeError naming the parameter otherwise."""
    if isinstance(resolution, str) and (resolution in RESOLUTIONS or _EXTRA_RESOLUTION.fullmatch(resolution)):
        return resolution
    raise SShaDeError(f"resolution must be 'high', 'low' or 'rN' (an extra resolution of N vertices), "
                      f"got {resolution!r}")


def build_resolutions(manifest: dict) -> list[str]:
    """The resolutions a build's manifest says it has: ``low``, then its ``resolutions``
    parameter (``high`` and ``rN``; a default build: ``high``)."""
    params = manifest.get("parameters") if isinstance(manifest.get("parameters"), dict) else {}
    res = params.get("resolutions", ["high"])
    res = res if isinstance(res, list) else ["high"]
    return ["low"] + [r if r == "high" else f"r{r}" for r in res
                      if r == "high" or isinstance(r, int) and not isinstance(r, bool) and r > 0]


def extra_counts(resolutions) -> list[int]:
    """The vertex counts of a build's ``resolutions`` (its ``rN`` meshes), in the order given."""
    return [int(x) for x in resolutions if x != "high"]


def resolution_key(resolutions) -> dict:
    """What the builder's item keys hold of ``resolutions``: nothing for the default
    ``[high]`` (a default build's keys are what they were before resolutions)."""
    r = [x if x == "high" else int(x) for x in resolutions]
    return {} if r == ["high"] else {"resolutions": r}

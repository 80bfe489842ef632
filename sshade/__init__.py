"""SShaDe: scalable shape deformation via local representations (Maggioli, Baieri,
Lähner, Melzi): the package's public API. The pipeline (paper §3): remesh
(:mod:`sshade.remesh`), projection onto seed fans (:mod:`sshade.projection`), low-res
spokes-and-rims ARAP (:mod:`sshade.arap`), per-triangle LRF transfer (:mod:`sshade.lrf`),
averaged over k samplings (:mod:`sshade.deform`); parameters: :class:`SShaDeParams`.

Example::

    Vd = deform(V, F, handles, targets, n_low=6000, n_samplings=5, seed=0)
    frames = [p.solve(T) for T in frame_targets]  # p = prepare(V, F, handles, n_low=6000)
"""
from .deform import SShaDe, deform, deform_once
from .errors import SShaDeError
from .method import Deformer
from .params import SShaDeParams, check_params
from .prepared import Prepared, prepare
from .remesh import RemeshResult, remesh

__all__ = ["deform", "deform_once", "prepare", "Prepared", "SShaDe", "SShaDeParams", "check_params", "SShaDeError",
           "Deformer", "remesh", "RemeshResult"]
__version__ = "0.1.0"

"""SShaDe: scalable shape deformation via local representations.

Maggioli, Baieri, Lähner, Melzi. "SShaDe: scalable shape deformation via local
representations". The pipeline (paper §3): topology-preserving remesh
(:mod:`sshade.remesh`), projection onto seed fans (:mod:`sshade.projection`),
low-res spokes-and-rims ARAP (:mod:`sshade.arap`), per-triangle LRF transfer
(:mod:`sshade.lrf`), averaged over k samplings (:mod:`sshade.deform`).

Example::

    from sshade import deform, prepare
    Vd = deform(V, F, handles, targets, n_low=6000, n_samplings=5, seed=0)
    prepared = prepare(V, F, handles, n_low=6000)       # once per handle selection
    frames = [prepared.solve(T) for T in frame_targets]  # then per frame
"""
from .deform import SShaDe, deform, deform_once
from .errors import SShaDeError
from .method import Deformer
from .prepared import Prepared, prepare
from .remesh import RemeshResult, remesh

__all__ = ["deform", "deform_once", "prepare", "Prepared", "SShaDe", "SShaDeError", "Deformer", "remesh",
           "RemeshResult"]
__version__ = "0.1.0"

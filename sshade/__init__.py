"""SShaDe: scalable shape deformation via local representations (Maggioli, Baieri,
Lähner, Melzi): the package's public API. The pipeline (paper §3): remesh
(:mod:`sshade.remesh`), projection onto seed fans (:mod:`sshade.projection`), low-res
spokes-and-rims ARAP (:mod:`sshade.arap`), per-triangle LRF transfer (:mod:`sshade.lrf`),
averaged over k samplings (:mod:`sshade.pipeline`); parameters: :class:`SShaDeParams`.

Example::

    Vd = deform(V, F, handles, targets, n_low=6000, n_samplings=5, seed=0)
    frames = [p.solve(T) for T in frame_targets]  # p = prepare(V, F, handles, n_low=6000)
"""
from .errors import SShaDeError
from .method_interface import Deformer
from .params import SShaDeParams, check_params
from .pipeline import (
    MAX_SEED,
    LowResSkippedWarning,
    SamplingJob,
    SShaDe,
    auto_n_low,
    deform,
    deform_once,
    deform_with,
    effective_params,
    handle_pre_pct,
    low_res_size,
    prepare_sampling,
    prepare_samplings,
    warm_sshade,
)
from .prepared import Prepared, prepare
from .remesh import RemeshResult, remesh

# every public name of sshade.pipeline is also the package's (sshade.deform is the function)
__all__ = ["deform", "deform_once", "prepare", "Prepared", "SShaDe", "SShaDeParams", "check_params", "SShaDeError",
           "Deformer", "remesh", "RemeshResult", "deform_with", "SamplingJob", "auto_n_low", "effective_params",
           "MAX_SEED", "warm_sshade", "LowResSkippedWarning", "prepare_sampling", "prepare_samplings", "low_res_size",
           "handle_pre_pct"]
__version__ = "0.1.0"

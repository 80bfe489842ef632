"""SShaDe: scalable shape deformation via local representations (Maggioli, Baieri,
Lähner, Melzi): the package's public API. The pipeline (paper §3): remesh
(:mod:`sshade.remesh`), projection onto seed fans (:mod:`sshade.projection`), low-res
spokes-and-rims ARAP (:mod:`sshade.arap`), per-triangle LRF transfer (:mod:`sshade.lrf`),
averaged over k samplings (:mod:`sshade.pipeline`); parameters: :class:`SShaDeParams`.

Example::

    Vd = deform(V, F, handles, targets, n_low=6000, n_samplings=5, seed=0)
    frames = [p.solve(T) for T in frame_targets]  # p = prepare(V, F, handles, n_low=6000)
"""
import lazy_loader

# bound on first use (SPEC 1): importing one submodule (sshade.arap.solver, sshade.mesh.io)
# does not import the pipeline, so a row's code identity holds only what its code reaches
# (docs/implementation.md); ``sshade.remesh`` stays the function after ``import sshade.remesh``
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "errors": ["SShaDeError"],
    "method_interface": ["Deformer"],
    "params": ["SShaDeParams", "check_params"],
    "pipeline": ["MAX_SEED", "LowResSkippedWarning", "SamplingJob", "SShaDe", "auto_n_low", "deform", "deform_once",
                 "deform_with", "effective_params", "handle_pre_pct", "low_res_size", "prepare_sampling",
                 "prepare_samplings", "warm_sshade"],
    "prepared": ["Prepared", "prepare"],
    "remesh": ["RemeshResult", "remesh"],
})
__version__ = "0.1.0"

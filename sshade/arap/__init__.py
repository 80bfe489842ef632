"""As-rigid-as-possible deformation: SShaDe's low-resolution step (paper §3.3, §4.1) and
the full-resolution baselines (Sorkine & Alexa 2007; Chao et al. 2010; Levi & Gotsman 2015).

One concept per module, imports only downwards: threads, kernels, solver_kernels,
kernel_data, operators, linear, criterion, options, accelerate, rigid, result, solver,
sr_local, smooth_rotations, sr_solver, sr_paper_protocol, rigid_motion, paper_protocol,
local_global; :mod:`~sshade.arap.problems` (synthetic problems) is not imported here. What
each module holds: docs/layout.md (``sshade/arap/``).
"""
import lazy_loader

# bound on first use (SPEC 1): importing one submodule does not import the others, so a
# row's code identity holds only what its code reaches (docs/implementation.md)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "accelerate": ["LBFGS", "Anderson"],
    "criterion": ["DEEP_CRITERION", "DEFAULT_CRITERION", "Criterion", "gradient_norm", "make_criterion"],
    "kernel_data": ["REORDER_MIN_VERTICES", "KernelData", "rcm_order"],
    "linear": ["LINEAR_SOLVERS", "LaplacianSolver"],
    "local_global": ["ArapDeformer", "arap_deform", "deformer_reads"],
    "operators": ["ENERGIES", "ArapOperators", "bbox_diag", "build_operators", "fit_rotations"],
    "paper_protocol": ["PaperSolver", "iterate", "paper_deform"],
    "options": ["ACCELERATIONS", "ALPHA_SCALINGS", "DEFAULT_ALPHA", "DEFAULT_MAX_ITER", "DEFORM_ENERGIES",
                "PAPER_STOPS", "PROTOCOLS", "READS", "SR_ENERGY", "ArapOptions"],
    "result": ["ArapResult"],
    "rigid": ["rigid_fit"],
    "smooth_rotations": ["SRProblem"],
    "solver": ["ArapSolver", "solve_arap"],
    "solver_kernels": ["warmup_kernels"],
    "sr_paper_protocol": ["arap_sr_deform"],
    "sr_solver": ["SR_ACCELERATIONS", "solve_arap_sr"],
    "threads": ["PARALLEL_MIN_CELLS", "MAIN_MIN_CELLS", "max_threads", "resolve_threads", "beside_others"],
})

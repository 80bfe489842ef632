"""As-rigid-as-possible deformation: SShaDe's low-resolution step (paper §3.3, §4.1) and
the full-resolution baselines (Sorkine & Alexa 2007; Chao et al. 2010; Levi & Gotsman 2015).

One concept per module, imports only downwards: threads, kernels, solver_kernels,
kernel_data, operators, linear, criterion, accelerate, rigid, result, solver,
smooth_rotations, local_global; :mod:`~sshade.arap.problems` (synthetic problems) is not
imported here. What each module holds: docs/layout.md (``sshade/arap/``).
"""
from .accelerate import LBFGS, Anderson
from .criterion import DEEP_CRITERION, DEFAULT_CRITERION, Criterion, gradient_norm, make_criterion
from .kernel_data import KernelData, rcm_order
from .linear import LINEAR_SOLVERS, LaplacianSolver
from .local_global import DEFAULT_MAX_ITER, DEFORM_ENERGIES, PROTOCOLS, ArapDeformer, arap_deform, iterate
from .operators import ENERGIES, ArapOperators, bbox_diag, build_operators, fit_rotations
from .result import ArapResult
from .rigid import rigid_fit
from .smooth_rotations import ALPHA_SCALINGS, DEFAULT_ALPHA, SR_ENERGY, SRProblem, arap_sr_deform, solve_arap_sr
from .solver import ACCELERATIONS, REORDER_MIN_VERTICES, ArapSolver, solve_arap
from .solver_kernels import warmup_kernels
from .threads import PARALLEL_MIN_CELLS, max_threads, resolve_threads

__all__ = ["solve_arap", "ArapSolver", "arap_deform", "ArapDeformer", "iterate", "build_operators", "ArapOperators",
           "KernelData", "rcm_order",
           "fit_rotations", "bbox_diag", "ENERGIES", "PROTOCOLS", "DEFAULT_MAX_ITER", "ACCELERATIONS",
           "REORDER_MIN_VERTICES", "Criterion", "DEFAULT_CRITERION", "DEEP_CRITERION", "make_criterion",
           "gradient_norm", "LaplacianSolver", "LINEAR_SOLVERS", "LBFGS", "Anderson", "rigid_fit", "ArapResult",
           "warmup_kernels", "PARALLEL_MIN_CELLS", "max_threads", "resolve_threads", "DEFORM_ENERGIES",
           "SRProblem", "solve_arap_sr", "arap_sr_deform", "SR_ENERGY", "DEFAULT_ALPHA", "ALPHA_SCALINGS"]

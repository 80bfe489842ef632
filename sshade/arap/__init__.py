"""As-rigid-as-possible deformation: SShaDe's low-resolution step (paper §3.3, §4.1) and
the full-resolution baselines.

One concept per module (imports only downwards, in this order):

- :mod:`~sshade.arap.threads`: thread policy of the numba kernels (``resolve_threads``,
  ``max_threads``, fork safety, ``numba_threads``, ``ThreadPicker``);
- :mod:`~sshade.arap.kernels`: numba kernels of the energies (fused local step, ``K(R)``)
  and their lazy compilation; :mod:`~sshade.arap.solver_kernels`: those of the solver's
  loop and accelerators;
- :mod:`~sshade.arap.kernel_data`: the kernels' arrays in a vertex numbering
  (``KernelData``, ``rcm_order``);
- :mod:`~sshade.arap.operators`: the energies (``ENERGIES``), ``ArapOperators``,
  ``build_operators``, ``fit_rotations``, ``bbox_diag``;
- :mod:`~sshade.arap.linear`: ``LaplacianSolver`` (CHOLMOD, scipy, libigl);
- :mod:`~sshade.arap.criterion`: ``Criterion``, ``DEFAULT_CRITERION``,
  ``DEEP_CRITERION``, ``make_criterion``, ``gradient_norm``;
- :mod:`~sshade.arap.accelerate`: L-BFGS (Liu et al. 2017) and Anderson (Peng et al.
  2018);
- :mod:`~sshade.arap.rigid`: ``rigid_fit``; :mod:`~sshade.arap.result`: ``ArapResult``;
- :mod:`~sshade.arap.solver`: ``solve_arap``, the converged solver, and ``ArapSolver``, the
  same prepared once for a handle set and solved for any targets;
- :mod:`~sshade.arap.local_global`: ``arap_deform`` under the ``"converged"`` or
  ``"paper"`` protocol, ``iterate``, ``PROTOCOLS``, ``DEFAULT_MAX_ITER``;
- :mod:`~sshade.arap.cases`: synthetic calibration problems (twisted bar, bent cylinder,
  lifted plane); not imported here.
"""
from .accelerate import LBFGS, Anderson
from .criterion import DEEP_CRITERION, DEFAULT_CRITERION, Criterion, gradient_norm, make_criterion
from .kernel_data import KernelData, rcm_order
from .linear import LINEAR_SOLVERS, LaplacianSolver
from .local_global import DEFAULT_MAX_ITER, PROTOCOLS, ArapDeformer, arap_deform, iterate
from .operators import ENERGIES, ArapOperators, bbox_diag, build_operators, fit_rotations
from .result import ArapResult
from .rigid import rigid_fit
from .solver import ACCELERATIONS, REORDER_MIN_VERTICES, ArapSolver, solve_arap
from .solver_kernels import warmup_kernels
from .threads import PARALLEL_MIN_CELLS, max_threads, resolve_threads

__all__ = ["solve_arap", "ArapSolver", "arap_deform", "ArapDeformer", "iterate", "build_operators", "ArapOperators",
           "KernelData", "rcm_order",
           "fit_rotations", "bbox_diag", "ENERGIES", "PROTOCOLS", "DEFAULT_MAX_ITER", "ACCELERATIONS",
           "REORDER_MIN_VERTICES", "Criterion", "DEFAULT_CRITERION", "DEEP_CRITERION", "make_criterion",
           "gradient_norm", "LaplacianSolver", "LINEAR_SOLVERS", "LBFGS", "Anderson", "rigid_fit", "ArapResult",
           "warmup_kernels", "PARALLEL_MIN_CELLS", "max_threads", "resolve_threads"]

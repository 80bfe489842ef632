"""Converged ARAP: local/global with one prefactored Laplacian, accelerated (L-BFGS or
Anderson), stopped by an energy-and-gradient criterion (:func:`solve_arap`;
:class:`ArapSolver` keeps the set-up for one handle set across solves).

Options: :class:`sshade.arap.options.ArapOptions`; energy and operators:
:mod:`sshade.arap.operators`; accelerators: :mod:`sshade.arap.accelerate`; stopping rule:
:class:`sshade.arap.criterion.Criterion`.
The algorithm, its phases, the cost of one iteration and the result's ``info`` keys:
docs/implementation.md ("Implementation notes: sshade/arap/solver.py").
"""
from __future__ import annotations

import time

import numpy as np
from scipy.sparse.csgraph import connected_components

from ..errors import SShaDeError
from ..mesh.validate import validate_handle_indices, validate_handles
from .accelerate import LBFGS, Anderson
from .criterion import Criterion, gradient_norm
from .kernel_data import REORDER_MIN_VERTICES
from .kernels import fused
from .linear import LaplacianSolver
from .operators import ENERGIES, ArapOperators, build_operators
from .options import READS, SR_ENERGY, ArapOptions
from .result import ArapResult
from .rigid import rigid_fit
from .solver_kernels import loop_kernels
from .threads import ThreadPicker, numba_threads, resolve_threads

__all__ = ["solve_arap", "ArapSolver", "SOLVER_SETUP"]

#: the options an :class:`ArapSolver` is set up with: each solve's must be the same
SOLVER_SETUP = ("energy", "linear_solver", "threads", "reorder")

clock = time.perf_counter


def solve_arap(V: np.ndarray, F: np.ndarray, handles, targets, options: ArapOptions | None = None, *,
               U0: np.ndarray | None = None, R0: np.ndarray | None = None, callback=None,
               operators: ArapOperators | None = None) -> ArapResult:
    """Handle-driven ARAP deformation run to a certified convergence (the converged
    protocol; the algorithm: docs/implementation.md, "Implementation notes: sshade/arap/solver.py").

    Parameters
    ----------
    V : (n, 3) float64 rest positions (mesh units). F : (m, 3) int faces.
    handles : (h,) int unique vertex indices; targets : (h, 3) float64 their positions.
    options : :class:`sshade.arap.options.ArapOptions` or None (its defaults). Read:
        ``energy`` (``"spokes"`` or ``"spokes_and_rims"``, libigl's definitions,
        :mod:`sshade.arap.operators`), ``criterion``, ``max_iter`` (None: 10000),
        ``accelerate`` (``"auto"``/``"lbfgs"``: L-BFGS, Armijo backtracking, memory pairs
        with non-positive curvature skipped; ``"anderson"``: energy safeguard;
        ``"none"``: plain local/global, libigl's iteration in float64), ``history``,
        ``time_budget_s``, ``linear_solver`` (:class:`sshade.arap.linear.LaplacianSolver`),
        ``threads`` (the iterates do not depend on it), ``reorder`` (same iterates up to
        rounding: the renumbered Cholesky factor rounds differently). The others must keep
        their defaults.
    U0 : (n, 3) float64 or None, start; default the best rigid fit of the handles
        (:func:`sshade.arap.rigid.rigid_fit`) applied to ``V``. The handle rows are
        overwritten by ``targets``.
    R0 : (n, 3, 3) float64 or None, start rotations (one per vertex = rotation cell),
        e.g. those of a solve on a low-resolution remesh (the baselines' coarse start): the
        first iterate is their global step, the minimiser of ``E(U, R0)`` with the handles
        at ``targets``. Not together with ``U0``.
    callback : callable or None, ``callback(k, U, E, gnorm) -> bool`` after every accepted
        iterate ``k`` (``U`` (n, 3) must not be modified); a true return value stops
        (status ``"callback"``).
    operators : :class:`sshade.arap.operators.ArapOperators` or None, precomputed for
        ``(V, F, energy)`` to reuse across calls (then ``V``/``F`` are not re-read).

    Returns
    -------
    :class:`sshade.arap.result.ArapResult`: ``V`` (n, 3) the last accepted iterate (the
    one the reported energy and gradient belong to), ``iterations`` (accepted iterations
    = global solves), ``converged`` (the criterion was met), ``last_move`` (mesh units),
    ``precompute_s`` (operators + factorisation), ``solve_s``, ``info`` (its keys:
    docs/implementation.md, "Implementation notes: sshade/arap/solver.py").

    Raises
    ------
    SShaDeError
        ``options`` not an ArapOptions, an energy other than :data:`sshade.arap.ENERGIES`,
        an option this solver does not read set, bad mesh / handles / targets / ``U0`` /
        ``R0`` shapes or values, both ``U0`` and ``R0`` given, ``operators`` built for
        another energy, a connected component without a handle.

    Examples
    --------
    >>> from sshade.arap.options import ArapOptions
    >>> from sshade.arap.problems import twisted_bar
    >>> V, F, h, T = twisted_bar(90.0, h=0.25)
    >>> solve_arap(V, F, h, T, ArapOptions(energy="spokes")).converged
    True
    """
    t_start = clock()
    solver = ArapSolver(V, F, handles, options, operators=operators)
    return solver._solve(targets, U0, R0, solver.options, callback, t_start)


class ArapSolver:
    """ARAP for one mesh and one handle set, prepared once and solved for any targets:
    libigl's ``arap_precomputation`` / ``arap_solve`` split, with :func:`solve_arap`'s
    iteration and stopping rule. The operators, the vertex numbering and the Cholesky
    factorisation of ``L_ff`` depend on the handles, not on where they go, so a sequence
    of solves (an animation's frames, a dragged handle) pays them once.

    Parameters
    ----------
    V : (n, 3) float64 rest positions. F : (m, 3) int faces. handles : (h,) int unique
        vertex indices (their targets are given to :meth:`solve`).
    options : :class:`sshade.arap.options.ArapOptions` or None, as :func:`solve_arap`; its
        set-up fields (:data:`SOLVER_SETUP`: energy, linear solver, threads, numbering) hold for
        every solve. operators : as :func:`solve_arap`.

    Attributes
    ----------
    n : int, vertices. handles : (h,) int64. energy : str. options : ArapOptions (each
    solve's unless it gives its own). precompute_s : float, seconds of the set-up (reported
    in the first solve's ``precompute_s``).

    Raises
    ------
    SShaDeError as :func:`solve_arap` for the options, the mesh, the handle indices, the
    linear solver and a component without a handle.

    Examples
    --------
    >>> from sshade.arap.options import ArapOptions
    >>> from sshade.arap.problems import twisted_bar
    >>> V, F, h, T = twisted_bar(90.0, h=0.25)
    >>> solver = ArapSolver(V, F, h, ArapOptions(energy="spokes"))
    >>> r1 = solver.solve(T)                  # the first frame
    >>> r2 = solver.solve(T * 1.01, U0=r1.V)  # the next one, warm-started from the first
    >>> r1.converged and r2.converged
    True
    """

    def __init__(self, V, F, handles, options: ArapOptions | None = None, *,
                 operators: ArapOperators | None = None):
        t0 = clock()
        options = _checked(options, "solve_arap")
        energy = options.energy
        self.ops = operators if operators is not None else build_operators(V, F, energy)
        if self.ops.energy_type != energy:
            raise SShaDeError(f"operators were built for {self.ops.energy_type!r}, not {energy!r}")
        self.energy, self.n, self.options = energy, self.ops.n, options
        self.handles = validate_handle_indices(self.ops.V, handles)
        self._st = None
        if len(self.handles) < self.n:  # not every vertex a handle (handles are unique)
            _check_components(self.ops.L, self.handles)
            self._st = _Stepper(self.ops, self.handles, threads=options.threads, reorder=options.reorder,
                                linear_solver=options.linear_solver)
        self.precompute_s = clock() - t0
        self._first = True
        self._acc = None  # the last solve's accelerator and its history (carry_history)

    @property
    def factorisation(self) -> LaplacianSolver | None:
        """The factorised ``L_ff`` every solve uses (None when every vertex is a handle)."""
        return None if self._st is None else self._st.lin

    def solve(self, targets, *, options: ArapOptions | None = None, U0: np.ndarray | None = None,
              R0: np.ndarray | None = None, callback=None, carry_history: bool = False) -> ArapResult:
        """The converged deformation for ``targets`` ((h, 3) float64, one per handle, in
        :attr:`handles`' order); ``U0``, ``R0``, ``callback`` and the result as
        :func:`solve_arap` (``U0``: e.g. the previous frame's result). ``options``: None
        (the solver's) or another :class:`~sshade.arap.options.ArapOptions` with the same
        set-up fields (:data:`SOLVER_SETUP`). The result's ``precompute_s`` holds the set-up's
        seconds in the first solve only. ``carry_history``: the accelerator starts with the
        history the last solve of this solver ended with (when it ran the same accelerator
        with the same window), not with none: L-BFGS's curvature pairs, Anderson's
        differences of iterates and of their plain steps. The free vertices and ``L_ff``
        are the same, and each entry (a difference of positions, gradients or plain steps
        within one solve) does not depend on the targets, whose term cancels in the
        differences. The stopping rule is the same; only the path to it changes.

        Raises
        ------
        SShaDeError on bad targets, ``U0`` / ``R0`` or options (:func:`solve_arap`), a
        set-up field other than the solver's.
        """
        if options is None:
            options = self.options
        else:
            options = _checked(options, "ArapSolver.solve")
            options.refuse_other_setup(self.options, SOLVER_SETUP, "ArapSolver.solve")
        return self._solve(targets, U0, R0, options, callback, clock(), carry_history)

    def _solve(self, targets, U0, R0, options: ArapOptions, callback, t_start: float,
               carry_history: bool = False) -> ArapResult:
        """:meth:`solve` with checked ``options``, its set-up time counted from
        ``t_start`` (plus the preparation's on the first solve)."""
        crit, acc = options.criterion, options.acceleration()
        m, max_iter = options.window(acc), options.iteration_cap("converged")
        h, T = validate_handles(self.ops.V, self.handles, targets)
        U = _start_point(self.ops, h, T, U0)
        R0 = _start_rotations(self.n, U0, R0)
        extra = self.precompute_s if self._first else 0.0
        self._first = False
        info = {"energy_type": self.energy, "etol": crit.etol, "gtol": crit.gtol, "accelerate": acc,
                "history": m, "n_local": 0, "n_fallback": 0}
        if self._st is None:  # every vertex is a handle
            res = _all_handles(self.ops, U, info, t_start)
            res.precompute_s += extra
            return res
        self._st.start(U, T, info, crit.trace_energy)
        kind = {"lbfgs": LBFGS, "anderson": Anderson}.get(acc)
        kept = self._acc if carry_history and kind is not None and isinstance(self._acc, kind) \
            and self._acc.m == m else None
        loop = _Loop(self._st, crit, acc, m, max_iter=max_iter, time_budget_s=options.time_budget_s,
                     callback=callback, R0=R0, kept=kept)
        loop.run()
        self._acc = loop.lbfgs if loop.lbfgs is not None else loop.anderson
        return loop.result(precompute_s=loop.t_iter - t_start + extra)


def _checked(options, who: str) -> ArapOptions:
    """``options`` (None: the defaults) for this solver: an :class:`ArapOptions` of an ARAP
    energy that sets no field the solver does not read. Raises SShaDeError naming ``who``."""
    options = ArapOptions.of(options, who)
    options.refuse_unused(READS["solve_arap"], who)
    if options.energy not in ENERGIES:
        raise SShaDeError(f"unknown ARAP energy {options.energy!r}; use one of {ENERGIES} "
                          f"({SR_ENERGY!r}: solve_arap_sr or arap_deform)")
    return options


def _start_point(ops: ArapOperators, h: np.ndarray, T: np.ndarray, U0) -> np.ndarray:
    """The first iterate (n, 3): ``U0`` or the rigid fit of the handles applied to the rest
    mesh, handle rows at their targets (a new array)."""
    V, n = ops.V, ops.n
    if U0 is None:
        Rr, tr_ = rigid_fit(V[h], T)
        U = V @ Rr.T + tr_
    else:
        U = np.array(U0, dtype=np.float64)
        if U.shape != (n, 3) or not np.isfinite(U).all():
            raise SShaDeError(f"U0 must be a finite (n, 3) array with n={n}, got shape {U.shape}")
    U[h] = T
    return U


def _start_rotations(n: int, U0, R0) -> np.ndarray | None:
    """``R0`` of :func:`solve_arap` checked: None, or a finite (n, 3, 3) float64 array
    (``U0`` not given)."""
    if R0 is None:
        return None
    if U0 is not None:
        raise SShaDeError("give U0 (start positions) or R0 (start rotations), not both")
    R = np.asarray(R0, dtype=np.float64)
    if R.shape != (n, 3, 3) or not np.isfinite(R).all():
        raise SShaDeError(f"R0 must be a finite (n, 3, 3) array with n={n}, got shape {R.shape}")
    return R


def _all_handles(ops: ArapOperators, U: np.ndarray, info: dict, t_start: float) -> ArapResult:
    """The result when every vertex is a handle: ``U``, converged, no iteration."""
    info.update(status="converged", energy=ops.energy(U), gnorm=0.0, rel_decrease=0.0,
                energy_history=[], gnorm_history=[], linear_solver=None, factor_s=0.0)
    return ArapResult(V=U, iterations=0, converged=True, last_move=0.0,
                      precompute_s=clock() - t_start, solve_s=0.0, info=info)


def _check_components(L, h: np.ndarray) -> None:
    """Raise SShaDeError when a connected component of the mesh (the pattern of ``L``)
    holds no handle: its position would be undetermined (singular ``L_ff``)."""
    ncomp, label = connected_components(L, directed=False)
    if ncomp > 1:
        lacking = np.setdiff1d(np.arange(ncomp), label[h])
        if len(lacking):
            raise SShaDeError(f"{len(lacking)} of the mesh's {ncomp} connected components hold no handle "
                              f"(e.g. the one with vertex {int(np.flatnonzero(label == lacking[0])[0])}); "
                              "their position is undetermined")


class _Stepper:
    """The set-up of :func:`solve_arap` and the four operations of its iterations.

    Holds the iteration's vertex numbering (the mesh's, or a cache-friendly one: every
    array here lives in it; :meth:`to_mesh` maps back), the numba kernels and their
    threads (``cur``: threads of the next kernel calls; ``picker`` in the automatic
    mode), the factorised ``L_ff`` and the preallocated buffers. Operations on free
    positions ``x`` (n_f, 3): :meth:`local` (rotations into ``R``, energy),
    :meth:`glob` (the plain iterate ``G(x)`` from the rotations in ``R``),
    :meth:`gnorm`, :meth:`max_move`; ``tm`` accumulates their seconds per stage.
    """

    def __init__(self, ops: ArapOperators, h: np.ndarray, *, threads, reorder, linear_solver: str):
        self.ops = ops
        self.diag = ops.diag
        self.zero_E = 1e-12 * ops.rest_term
        self._pick_kernels(threads, ops.n)
        self._renumber(h, reorder)
        self.lin = LaplacianSolver(self.Lff, linear_solver)
        if self.kern:
            Lc = self.Lff.tocsr()
            Lc.sort_indices()
            self.L_csr = (Lc.indptr.astype(np.uint64), Lc.indices.astype(np.uint32),
                          np.ascontiguousarray(Lc.data, np.float64))
            self.free_u = self.free.astype(np.uint32)
        self.rows = self.free_u if self.kern else self.free

    def start(self, U: np.ndarray, T: np.ndarray, info: dict, trace: bool = False) -> None:
        """A solve's problem: start positions ``U`` (n, 3) (mesh numbering, handle rows at
        their targets), targets ``T`` (h, 3), its ``info`` (the set-up's facts added);
        ``trace``: the local steps take the energy's trace form
        (:meth:`sshade.arap.operators.ArapOperators.local_step`, with the kernels)."""
        self.info, self.trace = info, trace
        self.U = U if self.perm is None else np.ascontiguousarray(U[self.perm])
        self.c_f = np.ascontiguousarray(self.Lfb @ T)  # (n_f, 3)
        info.update(linear_solver=self.lin.backend, factor_s=self.lin.factor_s, threads=self.nthreads,
                    reordered=self.perm is not None)
        self.tm = dict.fromkeys(("local", "rhs", "solve", "gradient", "anderson"), 0.0)  # seconds per stage

    def _pick_kernels(self, threads, n: int) -> None:
        """The loop's kernels (False: numpy paths) and threads (:class:`ThreadPicker` in
        the automatic mode)."""
        nthreads = resolve_threads(threads, n)
        kern = loop_kernels(False) if fused(1) else False
        if not kern or (nthreads > 1 and not (fused(nthreads) and loop_kernels(True))):
            nthreads = 1  # numpy paths, or parallel kernels unusable
        self.kern = kern
        self.kerns = {1: kern, nthreads: loop_kernels(True)} if kern and nthreads > 1 else {1: kern}
        self.picker = ThreadPicker(nthreads) if threads is None and nthreads > 1 else None
        self.nthreads = self.cur = nthreads

    def _renumber(self, h: np.ndarray, reorder) -> None:
        """The iteration's numbering (cache-friendly from :data:`REORDER_MIN_VERTICES`
        vertices with numba), the free vertices and the blocks of ``L`` in it."""
        ops, n = self.ops, self.ops.n
        if reorder is None:
            reorder = n >= REORDER_MIN_VERTICES
        reorder = bool(reorder) and bool(self.kern)
        self.kdata = ops.kernel_data(reorder) if self.kern else None
        self.perm = perm = None if self.kdata is None else self.kdata.perm
        if perm is not None:
            Lp = ops.L[perm][:, perm].tocsr()
            hp = self.kdata.inv[h]
            mass = ops.mass[perm]
        else:
            Lp, hp, mass = ops.L, h, ops.mass
        is_free = np.ones(n, bool)
        is_free[hp] = False
        self.free = np.flatnonzero(is_free)
        Lf = Lp[self.free]
        self.Lff = Lf[:, self.free].tocsc()
        self.Lfb = Lf[:, hp]
        self.mass_f = mass[self.free]
        self.mass_sum = self.mass_f.sum()

    def allocate(self) -> None:
        """The buffers of the iterations: polar warm start, rotations ``R`` of the last
        local step, cell energies, right-hand side, gradient scratch, edge terms."""
        n, nf = self.ops.n, len(self.free)
        self.warm = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        self.R = np.empty((n, 3, 3))
        self.Ek = np.empty(n)
        self.B = np.empty((nf, 3))
        self.q = np.empty(nf)
        self.grad = np.empty((nf, 3))  # the last gnorm's gradient (kernels only)
        self.Et = np.empty(len(self.ops.edges)) if self.trace and self.kern else None  # the trace form's

    def run(self, name: str, *args):
        """Loop kernel ``name`` with ``cur`` threads."""
        t = self.cur
        if t > 1:
            with numba_threads(t):
                return self.kerns[t][name](*args)
        return self.kern[name](*args)

    def to_mesh(self, Ux: np.ndarray) -> np.ndarray:
        """Positions in the mesh's numbering."""
        return Ux if self.perm is None else Ux[self.kdata.inv]

    def local(self, x: np.ndarray) -> float:
        """Rotations (into ``R``) and energy at free positions ``x`` (n_f, 3)."""
        t0 = clock()
        if self.kern:
            self.kern["set_rows"](self.U, self.free_u, x)
        else:
            self.U[self.free] = x
        self.info["n_local"] += 1
        E = self.ops.local_step(self.U, self.R, self.Ek, self.warm, self.cur, self.kdata, self.Et)
        self.tm["local"] += clock() - t0
        return E

    def glob(self) -> np.ndarray:
        """Global step with the rotations in ``R``: the plain iterate ``G(x)`` (n_f, 3)."""
        t0 = clock()
        self.ops.rhs_rows(self.R, self.rows, self.c_f, self.B, self.cur, self.kdata)
        t1 = clock()
        X = np.ascontiguousarray(self.lin.solve(self.B))
        self.tm["rhs"] += t1 - t0
        self.tm["solve"] += clock() - t1
        return X

    def gnorm(self, x: np.ndarray, g: np.ndarray) -> float:
        """Scale-free gradient norm at ``x``, whose plain step is ``g`` (``grad = 2 L_ff
        (x - g)``, kept in ``grad`` with the kernels; :func:`sshade.arap.criterion.gradient_norm`)."""
        t0 = clock()
        if self.kern:
            self.run("grad", *self.L_csr, x, g, self.mass_f, self.q, self.grad)
            gn = float(self.diag * np.sqrt(self.q.sum() / self.mass_sum))
        else:
            gn = gradient_norm(2.0 * (self.Lff @ (x - g)), self.mass_f, self.diag)
        self.tm["gradient"] += clock() - t0
        return gn

    def max_move(self, a: np.ndarray, b: np.ndarray) -> float:
        """Largest vertex move between two (n_f, 3) iterates (mesh units)."""
        if self.kern:
            return float(np.sqrt(self.kern["max_move"](a, b)))
        return float(np.sqrt(((a - b) ** 2).sum(1).max()))


class _Loop:
    """The iterations of :func:`solve_arap` on a :class:`_Stepper`: from the start point,
    repeat the stopping test (:meth:`stop_test`), a step (:meth:`lbfgs_step` or
    :meth:`anderson_step`, the latter also for the plain iteration) and its acceptance
    (:meth:`accept`). State: the accepted iterate ``x`` (energy ``E``, plain step ``g =
    G(x)``), the energy and gradient-norm histories, ``status`` once stopped. With start
    rotations ``R0`` (mesh numbering) the start point is their global step."""

    def __init__(self, st: _Stepper, crit: Criterion, acc: str, m: int, *, max_iter, time_budget_s, callback,
                 R0=None, kept=None):
        self.st, self.crit = st, crit
        self.max_iter, self.time_budget_s, self.callback = max_iter, time_budget_s, callback
        self.t_iter = clock()
        st.allocate()
        if kept is not None:  # the last solve's accelerator, its history kept
            kept.restart()
        self.lbfgs = self.anderson = None
        if acc == "lbfgs":
            self.lbfgs = kept if kept is not None else LBFGS(m, st.Lff)
        elif acc == "anderson":
            self.anderson = kept if kept is not None else Anderson(m, 3 * len(st.free), st.kerns if st.kern else None,
                                                                    st.nthreads)
        self.x = st.U[st.free].copy()
        if R0 is not None:  # the global step of the start rotations
            st.R[:] = R0 if st.perm is None else R0[st.perm]
            self.x = st.glob()
        self.E = st.local(self.x)
        self.g = st.glob()
        self.E_hist, self.G_hist = [self.E], []
        self.E_prev, self.rel = np.inf, np.inf
        self.it, self.last_move, self.status = 0, 0.0, None

    def run(self) -> None:
        """Iterate until :attr:`status` is set."""
        t_pass = clock()
        while True:
            self.status = self.stop_test()
            if self.status is not None:
                break
            step = self.lbfgs_step() if self.lbfgs is not None else self.anderson_step()
            if self.status is not None:  # stalled
                break
            if step is None:  # L-BFGS history dropped: test again, then the plain direction
                continue
            self.accept(*step)
            t_pass = self.tick(t_pass)

    def stop_test(self) -> str | None:
        """Convergence test at the accepted iterate, then the callback, the iteration cap
        and the time budget: the status to stop with, or None."""
        st, crit, E = self.st, self.crit, self.E
        gn = st.gnorm(self.x, self.g)
        self.G_hist.append(gn)
        if abs(E) <= st.zero_E:
            self.rel = 0.0
        else:  # |E|: libigl's cotangent weights turn negative on obtuse triangles, and so can E
            self.rel = (self.E_prev - E) / abs(E) if np.isfinite(self.E_prev) else np.inf
        if self.rel < crit.etol and gn < crit.gtol:
            return "converged" if self.it > 0 or abs(E) > st.zero_E else "rigid"
        if self.callback is not None and self.it > 0:
            st.U[st.free] = self.x
            if self.callback(self.it, st.to_mesh(st.U), E, gn):
                return "callback"
        if self.it >= self.max_iter:
            return "max_iter"
        if self.time_budget_s is not None and clock() - self.t_iter > self.time_budget_s:
            return "time_budget"
        return None

    def lbfgs_step(self):
        """Quasi-Newton step with Armijo backtracking: ``(x_new, E_new)``; None with the
        history dropped (a bad direction: test again, then a plain one), or None with
        status ``"stalled"`` (no decrease even along the plain direction)."""
        st, x, E = self.st, self.x, self.E
        t0 = clock()
        d, slope = self.lbfgs.direction(x, self.g, st.grad if st.kern else None)
        st.tm["anderson"] += clock() - t0
        alpha, E_new = 1.0, None
        while True:
            x_new = x + alpha * d
            E_try = st.local(x_new)
            if E_try <= E + 1e-4 * alpha * slope:
                E_new = E_try
                break
            if alpha < 1e-6:
                break
            alpha *= 0.5
        if E_new is None:
            if self.lbfgs.n_hist:  # a bad quasi-Newton direction: forget it, plain step
                st.info["n_fallback"] += 1
                self.lbfgs.reset()
                return None
            self.status = "stalled"
            return None
        if alpha < 1.0:
            st.info["n_fallback"] += 1
        return x_new, E_new

    def anderson_step(self):
        """Anderson history update with the accepted ``(x, g)`` and its candidate, under
        the energy safeguard (plain step ``g`` when rejected; always without Anderson):
        ``(x_new, E_new)``, or None with status ``"stalled"`` (a plain step raised the
        energy: only rounding does)."""
        st, g, E = self.st, self.g, self.E
        t0 = clock()
        x_new = self.anderson.step(self.x, g) if self.anderson is not None else None
        st.tm["anderson"] += clock() - t0
        accelerated = x_new is not None
        if not accelerated:
            x_new = g
        # R is overwritten by every local step: it holds the rotations of the last
        # evaluated candidate, which is the accepted one when glob() runs in accept()
        E_new = st.local(x_new)
        if accelerated and not E_new < E:  # safeguard: plain step, reset the history
            st.info["n_fallback"] += 1
            self.anderson.reset()
            x_new = g
            E_new = st.local(x_new)
            accelerated = False
        if not accelerated and E_new > E:
            self.status = "stalled"
            return None
        return x_new, E_new

    def accept(self, x_new: np.ndarray, E_new: float) -> None:
        """Accept ``x_new`` (energy ``E_new``; ``R`` holds its rotations): its plain step."""
        st = self.st
        t0 = clock()
        self.last_move = st.max_move(x_new, self.x)
        st.tm["anderson"] += clock() - t0
        self.E_prev, self.E = self.E, E_new
        self.x = x_new
        self.g = st.glob()
        self.it += 1
        self.E_hist.append(self.E)

    def tick(self, t_pass: float) -> float:
        """Automatic threads: time the iteration just done, pick the next mode."""
        st = self.st
        if st.picker is None:
            return t_pass
        now = clock()
        st.picker.record(st.cur, now - t_pass)
        st.cur = st.picker.cur
        if self.anderson is not None:
            self.anderson.threads = st.cur
        return now

    def result(self, precompute_s: float) -> ArapResult:
        """The :class:`ArapResult` of the stopped iterations (:func:`solve_arap`)."""
        st, status = self.st, self.status
        st.U[st.free] = self.x
        if status == "stalled":
            converged = bool(self.G_hist[-1] < self.crit.gtol)
        else:
            converged = status in ("converged", "rigid")
        info = st.info
        if st.picker is not None:
            info["parallel_fraction"] = st.picker.n_par / max(st.picker.count, 1)
        info.update(status=status, energy=float(self.E), gnorm=float(self.G_hist[-1]),
                    rel_decrease=float(self.rel) if status != "stalled" else 0.0,
                    energy_history=[float(e) for e in self.E_hist], gnorm_history=[float(v) for v in self.G_hist],
                    stage_s=st.tm)
        return ArapResult(V=np.array(st.to_mesh(st.U)), iterations=self.it, converged=converged,
                          last_move=self.last_move, precompute_s=precompute_s, solve_s=clock() - self.t_iter, info=info)

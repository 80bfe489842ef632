"""Prepare once, solve every frame: SShaDe split by what depends on the handles' targets
(paper §3), for animations and handles dragged in a viewer.

What depends only on the mesh and on which vertices are handles is done once by
:func:`prepare`, per sampling (§3.3): the remesh and the projection onto the seed fans
(§3.1, :func:`sshade.deform.prepare_sampling`), the frames' function and the local
coordinates of every high-res vertex (§3.2, :func:`sshade.lrf.encode`), and the low-res
ARAP's operators and Cholesky factor (:class:`sshade.arap.ArapDeformer`). What depends on
the targets is :meth:`Prepared.solve`: per sampling the low-res spokes-and-rims ARAP run to
the converged criterion, the decoding on the deformed low-res mesh (Alg. 1), then the
average over the samplings and the handles set to their targets, as :func:`sshade.deform`.

The first solve is :func:`sshade.deform` of the same parameters, bit for bit: sampling 0
starts from the rigid fit of the handles, the others (``warm_start``) from sampling 0's
result. Every later solve starts each sampling from its previous result moved on as its last
two results moved (linear extrapolation of the frames; the previous result alone at the
second solve), and still runs to the same stopping rule.

The samplings run in this process, one after the other (``deform`` spreads them over
processes).

Example::

    from sshade.prepared import prepare
    prepared = prepare(V, F, handles, n_low=6000, n_samplings=5, seed=0)
    frames = [prepared.solve(T) for T in targets_per_frame]   # (n, 3) each
"""
from __future__ import annotations

import time

import numpy as np

from .arap import ArapDeformer
from .deform import arap_options, check_params, handle_pre_pct, low_res_size, prepare_sampling
from .errors import SShaDeError
from .lrf import decode, encode, frame_functions
from .mesh.halfedge import count_components
from .mesh.validate import validate_handle_indices, validate_handles, validate_mesh
from .remesh import mesh_topology
from .sampling import average, sampling_seeds, warm_kernels

__all__ = ["prepare", "Prepared"]


class _Sampling:
    """One sampling's prepared state: its low-res mesh and projection (``prep``), the
    frames' axis and local coordinates, its ARAP deformer, its last low-res result."""

    def __init__(self, V, prep: dict, info: dict, gradient: str, anchor: str, protocol: str):
        self.prep, self.info = prep, info
        self.VN = V[prep["seeds"]]
        self.bary = prep["bary"] if anchor == "projection" else None
        self.axis = frame_functions(self.VN, prep["F"])
        self.C = encode(V, prep["tri"], self.VN, prep["F"], self.axis, gradient, self.bary)
        self.arap = ArapDeformer(self.VN, prep["F"], prep["low_handles"], energy="spokes_and_rims",
                                 protocol=protocol)
        self.last = self.before = None  # (k, 3) low-res results of the previous two solves

    def solve(self, targets, V0, arap: dict, gradient: str) -> tuple[np.ndarray, dict]:
        """The low-res ARAP from ``V0`` ((k, 3) or None: the rigid fit) and the decoding:
        ``(Vd (n, 3), info)`` with the handle residual before any overwrite."""
        t0 = time.perf_counter()
        res = self.arap.deform(targets, V0=V0, **arap)
        t1 = time.perf_counter()
        Vd = decode(self.C, self.prep["tri"], self.VN, res.V, self.prep["F"], self.axis, gradient, self.bary)
        self.last, self.before = res.V, self.last
        t2 = time.perf_counter()
        return Vd, {"arap_s": t1 - t0, "transfer_s": t2 - t1, "iterations": res.iterations,
                    "converged": res.converged, "status": res.info.get("status"), "warm_start": V0 is not None}


class Prepared:
    """SShaDe prepared for one mesh and one handle set (:func:`prepare`).

    Attributes
    ----------
    V : (n, 3) float64; F : (m, 3) int64; handles : (h,) int64 (the validated inputs).
    params : dict, the checked parameters (:func:`sshade.deform.check_params`).
    prepare_s : float, seconds :func:`prepare` took. n_solves : int, solves so far.
    """

    def __init__(self, V, F, handles, params: dict, samplings: list, prepare_s: float):
        self.V, self.F, self.handles, self.params = V, F, handles, params
        self._samplings, self.prepare_s = samplings, prepare_s
        self._arap = arap_options(params["tol"], params["max_iter"], params["protocol"], params["etol"],
                                  params["gtol"])
        self._arap.pop("protocol")  # the deformers were made for it
        self.n_solves = 0

    @property
    def factorisations(self) -> list:
        """Each sampling's factorised low-res ``L_ff`` (None before its first solve that
        needs one, and under the paper protocol): the same objects for every solve."""
        return [s.arap.factorisation for s in self._samplings]

    def solve(self, targets, *, return_info: bool = False):
        """Deform for ``targets`` ((h, 3) float, one per handle, in :attr:`handles`' order).

        Returns
        -------
        (n, 3) float64 deformed positions (handles at their targets); with ``return_info``
        ``(Vd, info)``: ``total_s`` (wall seconds of this solve), ``arap_s`` /
        ``transfer_s`` / ``iterations`` summed over the samplings, ``converged`` (every
        sampling's low-res ARAP met its stopping rule), ``status``, ``handle_pre_pct``,
        ``solve`` (0 for the first), per-sampling details in ``samplings``.

        Raises
        ------
        SShaDeError on targets of the wrong shape or with NaN/inf
        (:func:`sshade.mesh.validate.validate_handles`).
        """
        t0 = time.perf_counter()
        _, T = validate_handles(self.V, self.handles, targets)
        first, k = self.n_solves == 0, len(self._samplings)
        results, infos = [None] * k, [None] * k
        for i, s in enumerate(self._samplings):
            if not first:  # the previous frame, moved on as the last two frames moved
                V0 = s.last if s.before is None else 2.0 * s.last - s.before
            elif i > 0 and self.params["warm_start"]:
                V0 = results[0][s.prep["seeds"]]  # as deform: sampling 0's result
            else:
                V0 = None  # the rigid fit of the handles
            results[i], infos[i] = s.solve(T, V0, self._arap, self.params["gradient"])
            infos[i]["handle_resid"] = results[i][self.handles] - T
        Vd = average(results)
        Vd[self.handles] = T
        pre = average([d.pop("handle_resid") for d in infos])
        self.n_solves += 1
        if not return_info:
            return Vd
        others = [str(d["status"]) for d in infos if not d["converged"]]
        info = {"total_s": time.perf_counter() - t0, "solve": self.n_solves - 1, "samplings": infos,
                "arap_s": float(sum(d["arap_s"] for d in infos)),
                "transfer_s": float(sum(d["transfer_s"] for d in infos)),
                "iterations": int(sum(d["iterations"] for d in infos)),
                "converged": not others, "status": others[0] if others else "converged",
                "handles": "overwritten", "handle_pre_pct": handle_pre_pct(pre, self.V)}
        return Vd, info


def prepare(V, F, handles, *, n_low: int = 6000, n_samplings: int = 5, seed: int = 0, tol: float = 1e-4,
            max_iter: int | None = None, gradient: str = "normalized", warm_start: bool = True,
            protocol: str = "converged", etol: float | None = None, gtol: float | None = None,
            anchor: str = "projection") -> Prepared:
    """Everything of SShaDe that does not depend on the handles' targets (module docstring).

    Parameters
    ----------
    V : (n, 3) float64 rest positions; F : (m, 3) int faces of a connected manifold
        triangle mesh; handles : (h,) int vertex indices (a new selection needs a new
        :func:`prepare`). The other parameters as :func:`sshade.deform.deform` (no
        ``workers``: the samplings run in this process).

    Returns
    -------
    :class:`Prepared`; ``prepared.solve(targets)`` deforms.

    Raises
    ------
    SShaDeError on an invalid mesh or handle indices, a bad parameter
    (:func:`sshade.deform.check_params`), or a mesh of several connected components
    (:func:`sshade.deform.deform` handles those).

    Warns
    -----
    :class:`sshade.deform.LowResSkippedWarning` when ``n_low`` is not below the vertex count.

    Examples
    --------
    >>> from sshade.arap.cases import twisted_bar
    >>> V, F, h, T = twisted_bar(45.0, h=0.25)
    >>> p = prepare(V, F, h, n_low=100, n_samplings=2)
    >>> bool(np.allclose(p.solve(T)[h], T))
    True
    """
    t0 = time.perf_counter()
    p = check_params(n_low=n_low, n_samplings=n_samplings, seed=seed, tol=tol, max_iter=max_iter,
                     gradient=gradient, warm_start=warm_start, protocol=protocol, etol=etol, gtol=gtol, anchor=anchor)
    warm_kernels()
    V, F, he = validate_mesh(V, F, return_halfedges=True, allow_components=True)
    h = validate_handle_indices(V, handles)
    if count_components(he.E, len(V)) > 1:
        raise SShaDeError("prepare: the mesh has several connected components; deform it with sshade.deform")
    _, n_low_used = low_res_size(len(V), p["n_low"])  # warns when there is no low-res step
    topology = mesh_topology(V, F, he)
    samplings = []
    for s in sampling_seeds(p["seed"], p["n_samplings"]):
        prep, info = prepare_sampling(V, F, h, n_low_used, s, topology)
        samplings.append(_Sampling(V, prep, info, p["gradient"], p["anchor"], p["protocol"]))
    return Prepared(V, F, h, p, samplings, time.perf_counter() - t0)

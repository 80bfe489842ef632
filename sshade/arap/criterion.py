"""Stopping criterion of the converged ARAP solver (:func:`sshade.arap.solver.solve_arap`):
the relative energy decrease AND a scale-free gradient norm below their thresholds.

* :class:`Criterion`, :data:`DEFAULT_CRITERION`, :data:`DEEP_CRITERION` (for references);
* :func:`make_criterion`: a criterion from optional thresholds (None: the default's), the
  one builder of the callers' ``etol`` / ``gtol`` options;
* :func:`gradient_norm`: the scale-free gradient norm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SShaDeError

__all__ = ["TRACE_ETOL", "Criterion", "DEFAULT_CRITERION", "DEEP_CRITERION", "make_criterion", "gradient_norm"]


#: The least ``etol`` under which the solver's local step sums the energy in the trace form
#: (:data:`sshade.arap.operators.TRACE_MIN_ENERGY`); below it, e.g. :data:`DEEP_CRITERION`,
#: the cells' energies are summed term by term.
TRACE_ETOL = 1e-9


@dataclass(frozen=True)
class Criterion:
    """Convergence criterion of :func:`sshade.arap.solver.solve_arap`: stop when BOTH hold
    at an accepted iterate ``U_k``.

    * energy: ``(E_{k-1} - E_k) / |E_k| < etol`` (relative decrease over the last accepted
      iteration; an energy within ``1e-12 * sum_e w_e ||e_e||^2`` of 0, i.e. a rigid motion
      up to rounding, satisfies it). ``|E_k|``: with libigl's cotangent weights, negative
      on obtuse triangles, the spokes energy can be negative;
    * gradient: ``gnorm(U_k) < gtol`` with the scale-free norm of :func:`gradient_norm`.

    Attributes
    ----------
    etol : float >= 0, relative energy decrease threshold (dimensionless).
    gtol : float >= 0, scale-free gradient threshold (dimensionless).

    The defaults (:data:`DEFAULT_CRITERION`: ``etol = 1e-7``, ``gtol = 1e-3``), their
    calibration and what a stop certifies: docs/implementation.md ("Implementation notes:
    sshade/arap/criterion.py").
    """

    etol: float = 1e-7
    gtol: float = 1e-3

    def __post_init__(self):
        if not (self.etol >= 0 and self.gtol >= 0):
            raise SShaDeError(f"criterion thresholds must be >= 0, got etol={self.etol}, gtol={self.gtol}")

    @property
    def trace_energy(self) -> bool:
        """Whether the solver may take the energy's trace form (``etol >= TRACE_ETOL``):
        its noise, about 1e-12 relative at most where it is kept, stays far below ``etol``."""
        return self.etol >= TRACE_ETOL


DEFAULT_CRITERION = Criterion()
#: for references: stop only when the energy stops changing in float64
DEEP_CRITERION = Criterion(etol=1e-15, gtol=1e-10)


def make_criterion(etol: float | None = None, gtol: float | None = None, *,
                   base: Criterion = DEFAULT_CRITERION) -> Criterion:
    """The criterion with thresholds ``etol`` / ``gtol``, each None taking ``base``'s.

    Parameters
    ----------
    etol, gtol : float >= 0 or None (dimensionless, :class:`Criterion`).
    base : :class:`Criterion`, the thresholds of None (default :data:`DEFAULT_CRITERION`).

    Returns
    -------
    :class:`Criterion` (``base`` itself when both are None).

    Raises
    ------
    SShaDeError on a negative threshold (ValueError / TypeError on a non-number).
    """
    if etol is None and gtol is None:
        return base
    return Criterion(etol=base.etol if etol is None else float(etol),
                     gtol=base.gtol if gtol is None else float(gtol))


def gradient_norm(grad_f: np.ndarray, mass_f: np.ndarray, diag: float) -> float:
    """Scale-free norm of the ARAP gradient on the free vertices.

    ``gnorm = diag * sqrt( sum_i ||g_i||^2 / (4 m_i) / sum_i m_i )``, i.e. the area-weighted
    RMS over the free vertices of the force density ``g_i / (2 m_i)`` (``g = dE/dU``,
    ``m_i`` the Voronoi area of vertex ``i``), times the bounding-box diagonal.

    Why: the cotangent weights are dimensionless, so ``g / 2 = L U - K(R)`` is a length,
    and ``(L u)_i ~ -m_i (Laplace u)(x_i)``; ``g_i / (2 m_i)`` is thus a discrete
    ``Laplace(delta)`` of the residual displacement ``delta``, independent of the mesh
    resolution for a smooth residual, with units 1/length. Multiplying by ``diag`` makes
    it invariant to the scale of the shape: a smooth residual of amplitude ``a`` varying
    over the size of the shape gives ``gnorm ~ a / diag`` (times a shape factor).

    Parameters
    ----------
    grad_f : (n_f, 3) float64 gradient rows of the free vertices (mesh units).
    mass_f : (n_f,) float64 > 0 Voronoi areas of those vertices (mesh units^2).
    diag : float > 0, bounding-box diagonal of the rest mesh (mesh units).

    Returns
    -------
    float, dimensionless (0 when there is no free vertex).
    """
    if len(grad_f) == 0:
        return 0.0
    return float(diag * np.sqrt((np.einsum("ij,ij->i", grad_f, grad_f) / (4.0 * mass_f)).sum() / mass_f.sum()))

"""Full-resolution baselines behind the :class:`sshade.method_interface.Deformer` interface.

- :class:`ARAP`: libigl ARAP with the spokes energy (Sorkine & Alexa 2007).
- :class:`Elastic`: libigl ARAP with the spokes-and-rims energy (Chao et al. 2010).
- :class:`ARAPSR`: ARAP with smooth rotations (Levi & Gotsman 2015).

Each runs under the ``protocol`` it is given (``arap.protocol``): ``converged`` (the
default: :func:`sshade.arap.solve_arap` until the energy-verified criterion holds) or
``paper`` (the paper's §4.1 rule: rigid-fit start, libigl's local/global until the
largest move is below ``tol * bbox_diag``, at most 1000 iterations); docs/protocols.md.
"""
from .arap_sr import ARAPSR
from .fullres_arap import ARAP, Elastic, FullResArap

__all__ = ["ARAP", "Elastic", "ARAPSR", "FullResArap"]

"""Full-resolution baselines behind the :class:`sshade.method.Deformer` interface.

- :class:`ARAP`: libigl ARAP with the spokes energy (Sorkine & Alexa 2007).
- :class:`Elastic`: libigl ARAP with the spokes-and-rims energy (Chao et al. 2010).
- :class:`ARAPSR`: ARAP with smooth rotations (Levi & Gotsman 2015).

Both use the paper's protocol (§4.1): rigid-fit start, iterate to convergence
(largest move below ``tol * bbox_diag``), at most 1000 iterations.
"""
from .arap import ARAP, Elastic, FullResArap
from .arap_sr import ARAPSR

__all__ = ["ARAP", "Elastic", "ARAPSR", "FullResArap"]

"""Full-resolution baselines behind the :class:`sshade.method_interface.Deformer` interface.

- :class:`ARAP`: libigl ARAP with the spokes energy (Sorkine & Alexa 2007).
- :class:`Elastic`: libigl ARAP with the spokes-and-rims energy (Chao et al. 2010).
- :class:`ARAPSR`: ARAP with smooth rotations (Levi & Gotsman 2015).

Each runs under the ``protocol`` it is given (``arap.protocol``): ``converged`` (the
default: :func:`sshade.arap.solve_arap` until the energy-verified criterion holds) or
``paper`` (the paper's §4.1 rule: rigid-fit start, libigl's local/global until the
largest move is below ``tol * bbox_diag``, at most 1000 iterations); docs/protocols.md.
"""
import lazy_loader

# bound on first use (SPEC 1): importing one submodule does not import the others, so a
# row's code identity holds only what its code reaches (docs/implementation.md)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "arap_sr": ["ARAPSR"],
    "fullres_arap": ["ARAP", "Elastic", "FullResArap"],
})

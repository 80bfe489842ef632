"""Implicit-ARAP (Baieri, Maggioli, Lähner, Melzi, Rodolà 2024; reference code
github.com/dbaieri/implicit-arap, MIT licence), ported: a neural SDF of the mesh
(:mod:`.sdf`), a neural deformation field (:mod:`.field`) trained with the ARAP energy
of small patches meshed on the SDF's level sets (:mod:`.patches`), applied to the
mesh's vertices (:mod:`.method`), its parameters one checked object (:mod:`.params`).
Needs PyTorch (extra ``[neural]``); importing this package does not (:mod:`.backend`).
"""
import lazy_loader

# bound on first use (SPEC 1): importing one submodule does not import the others, so a
# row's code identity holds only what its code reaches (docs/implementation.md)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "method": ["ImplicitARAP"],
    "params": ["PRESETS", "ImplicitARAPParams", "implicit_arap_params"],
})

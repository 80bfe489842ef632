"""Implicit-ARAP (Baieri, Maggioli, Lähner, Melzi, Rodolà 2024; reference code
github.com/dbaieri/implicit-arap, MIT licence), ported: a neural SDF of the mesh
(:mod:`.sdf`), a neural deformation field (:mod:`.field`) trained with the ARAP energy
of small patches meshed on the SDF's level sets (:mod:`.patches`), applied to the
mesh's vertices (:mod:`.method`). Needs PyTorch (extra ``[neural]``); importing this
package does not (:mod:`.backend`).
"""
from .method import PRESETS, ImplicitARAP

__all__ = ["PRESETS", "ImplicitARAP"]

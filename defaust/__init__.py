"""DeFAUST: datasets for handle-guided deformation (paper appendix) and mesh file IO."""
from .meshio import read_mesh, write_mesh, atomic_write

__all__ = ["read_mesh", "write_mesh", "atomic_write"]

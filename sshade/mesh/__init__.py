"""Triangle meshes: file I/O, validation and the mesh structures the method builds on.

One concept per module (imports only downwards, in this order):

- :mod:`~sshade.mesh.halfedge`: half-edges (``HalfEdges``, ``halfedges``), vertex fans,
  pinched vertices, connected components, boundary loops, vertex normals (numba);
- :mod:`~sshade.mesh.geodesic`: edge graphs, Dijkstra/Voronoi regions and farthest-point
  sampling (``VoronoiState``, ``locality_order``; numba);
- :mod:`~sshade.mesh.validate`: THE input checks of every layer: ``validate_mesh``
  (single-component 2-manifold), ``validate_handles``, ``validate_deformed`` (a method's
  output) and ``check_points`` / ``check_faces`` / ``check_arrays`` (shapes, dtypes,
  finite values, index range only, for callers that need no manifold mesh);
- :mod:`~sshade.mesh.repair`: pymeshlab's vertex-preserving repair filters
  (``repair_mesh``; pymeshlab imported on use);
- :mod:`~sshade.mesh.io`: ``read_mesh`` / ``write_mesh`` (OBJ, OFF, PLY; STL read only),
  ``atomic_write``, ``written_by_sshade``;
- :mod:`~sshade.mesh.gltf`: glTF 2.0 binary (``.glb``) animations, one morph target per
  frame (pygltflib); not imported here;
- :mod:`~sshade.mesh.handle_files`: the handle files of ``python -m sshade deform``
  (``.sel`` + ``.def``, ``.dmat``, ``.json``, ``.csv``); not imported here.

Example::

    from sshade.mesh import read_mesh, write_mesh
    V, F = read_mesh("bunny.off")
"""
from .halfedge import HalfEdges, halfedges
from .io import SIGNATURE, atomic_write, read_mesh, write_mesh, written_by_sshade
from .repair import repair_mesh
from .validate import (
    COORD_MAX,
    DIAG_MIN,
    MAX_DIAGONALS,
    check_arrays,
    check_faces,
    check_points,
    validate_deformed,
    validate_handles,
    validate_mesh,
)

__all__ = ["read_mesh", "write_mesh", "atomic_write", "written_by_sshade", "SIGNATURE", "validate_mesh",
           "validate_handles", "validate_deformed", "check_arrays", "check_points", "check_faces", "COORD_MAX",
           "DIAG_MIN", "MAX_DIAGONALS", "HalfEdges", "halfedges", "repair_mesh"]

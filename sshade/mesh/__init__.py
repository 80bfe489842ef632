"""Triangle meshes: file I/O, validation and the mesh structures the method builds on.

One concept per module, imports only downwards: halfedge, geodesic, validate, repair, io;
gltf and handle_files are not imported here. What each module holds: docs/layout.md
(``sshade/mesh/``).

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

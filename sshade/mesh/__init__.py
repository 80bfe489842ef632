"""Triangle meshes: file I/O, validation and the mesh structures the method builds on.

One concept per module, imports only downwards: halfedge, geodesic, validate, repair, io
(its formats: text_rows, then obj, off, ply, stl); gltf and handle_files are not imported
here. What each module holds: docs/layout.md (``sshade/mesh/``).

Example::

    from sshade.mesh import read_mesh, write_mesh
    V, F = read_mesh("bunny.off")
"""
import lazy_loader

# bound on first use (SPEC 1): importing one submodule does not import the others, so a
# row's code identity holds only what its code reaches (docs/implementation.md)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "halfedge": ["HalfEdges", "halfedges"],
    "io": ["SIGNATURE", "read_mesh", "write_mesh", "written_by_sshade"],
    "repair": ["repair_mesh"],
    "validate": ["COORD_MAX", "DIAG_MIN", "MAX_DIAGONALS", "check_arrays", "check_faces", "check_points",
                 "validate_deformed", "validate_handles", "validate_mesh"],
})

"""The project's one exception type.

Every bad input (unreadable file, non-triangle faces, NaN coordinates, non-manifold
edge, handle off the mesh, ...) raises :class:`SShaDeError` with a message naming the
problem and where it is, before any work is done.
"""


class SShaDeError(ValueError):
    """Raised for invalid input to any SShaDe function.

    Subclasses ``ValueError`` so generic callers that catch ``ValueError`` still work.

    Examples
    --------
    >>> from sshade.errors import SShaDeError
    >>> try:
    ...     raise SShaDeError("face 12 is degenerate (zero area)")
    ... except ValueError as e:
    ...     print(e)
    face 12 is degenerate (zero area)
    """

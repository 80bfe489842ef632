"""PyTorch, the optional dependency of Implicit-ARAP (extra ``[neural]``): the package's
one guarded import, and the check that turns its absence into one line.

``torch`` is the module, or None when PyTorch is not installed; the other modules of
:mod:`baselines.implicit_arap` use it only in function bodies, reached after
:func:`require_torch` (called by :class:`baselines.implicit_arap.ImplicitARAP` when it
is built), so importing :mod:`baselines` never needs PyTorch.
"""
from __future__ import annotations

from sshade.errors import SShaDeError

try:  # optional dependency: pip install -e .[neural]
    import torch
except ImportError:
    torch = None

__all__ = ["NO_TORCH", "require_torch", "torch"]

#: The one line a build without PyTorch fails with.
NO_TORCH = "Implicit-ARAP needs PyTorch: pip install -e .[neural]"


def require_torch():
    """The ``torch`` module.

    Raises
    ------
    SShaDeError with :data:`NO_TORCH` (one line) when PyTorch cannot be imported.
    """
    if torch is None:
        raise SShaDeError(NO_TORCH)
    return torch

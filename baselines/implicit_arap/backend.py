"""PyTorch, the optional dependency of Implicit-ARAP (extra ``[neural]``): the package's
one guarded import, and the check that turns its absence into one line.

``torch`` is the module, or None when PyTorch cannot be imported (not installed, or
installed with a library that does not load: an ImportError or OSError); the other modules of
:mod:`baselines.implicit_arap` use it only in function bodies, reached after
:func:`require_torch` (called by :class:`baselines.implicit_arap.ImplicitARAP` when it
is built), so importing :mod:`baselines` never needs PyTorch.
"""
from __future__ import annotations

from sshade.errors import SShaDeError

try:  # optional dependency: pip install -e .[neural]
    import torch
    _IMPORT_ERROR: BaseException | None = None
except (ImportError, OSError) as e:
    torch = None
    _IMPORT_ERROR = e

__all__ = ["NO_TORCH", "require_torch", "resolve_device", "torch"]

#: The one line a build without PyTorch fails with (a PyTorch that is installed but does
#: not load adds the first line of its error).
NO_TORCH = "Implicit-ARAP needs PyTorch: pip install -e .[neural]"


def require_torch():
    """The ``torch`` module.

    Raises
    ------
    SShaDeError with :data:`NO_TORCH` (one line) when PyTorch cannot be imported.
    """
    if torch is None:
        e = _IMPORT_ERROR
        if isinstance(e, ModuleNotFoundError) and e.name == "torch":
            raise SShaDeError(NO_TORCH)
        first = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), "")
        raise SShaDeError(f"{NO_TORCH} (import torch failed: {type(e).__name__}: {first})")
    return torch


def resolve_device(device: str) -> str:
    """The torch device ``device`` (one of
    :data:`baselines.implicit_arap.params.DEVICES`) names: ``auto`` is ``cuda`` when
    PyTorch sees a CUDA device, else ``cpu``; ``cpu`` and ``cuda`` are themselves."""
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    return device

"""Paths of the evaluator's config, resolved against the launch directory."""
from __future__ import annotations

from pathlib import Path

from hydra.utils import to_absolute_path

__all__ = ["abs_path"]


def abs_path(path) -> Path:
    """``path`` (str or Path; ``~`` expanded) resolved against the directory the command
    was started from (Hydra's original working directory when a Hydra run is active,
    else the current one); an absolute path is only normalised."""
    return Path(to_absolute_path(str(Path(str(path)).expanduser()))).resolve()

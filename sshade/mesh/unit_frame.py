"""The unit frame: a mesh centred at the origin and scaled by a power of two near its
bounding-box diagonal, where every solve of SShaDe and the baselines runs
(:func:`unit_frame`; :class:`UnitFrame`'s ``to_unit`` and ``from_unit``).

A power-of-two scale is exact: a mesh scaled by ``2**k`` gives the same result scaled,
bit for bit; a translation is undone up to the precision of the moved input. Why:
docs/implementation.md ("Implementation notes: sshade/mesh/unit_frame.py").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .bounds import bounding_box

__all__ = ["UnitFrame", "unit_frame"]


@dataclass(frozen=True)
class UnitFrame:
    """Centre and power-of-two scale of a mesh's unit frame (:func:`unit_frame`).

    Attributes
    ----------
    centre : (3,) float64, the bounding box's midpoint, mesh units.
    scale : float, a power of two, ``diag < scale <= 2 * diag`` for the box's diagonal
        ``diag`` (mesh units); unit positions are ``(X - centre) / scale``.
    """

    centre: np.ndarray
    scale: float

    def to_unit(self, X: np.ndarray) -> np.ndarray:
        """Positions ``X`` ((k, 3) float, mesh units) in the unit frame, a new (k, 3)
        float64 array."""
        return (np.asarray(X, np.float64) - self.centre) / self.scale

    def from_unit(self, U: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Unit-frame positions ``U`` ((k, 3) float64) back in mesh units; into ``out``
        ((k, 3) float64, may be ``U`` itself) when given, else a new array."""
        out = np.multiply(U, self.scale, out=out)
        out += self.centre
        return out

    def energy(self, e: float | None) -> float | None:
        """An ARAP-type energy measured in the unit frame, in mesh units (squared lengths:
        times ``scale ** 2``); None stays None."""
        return None if e is None else float(e) * self.scale * self.scale

    def as_dict(self) -> dict:
        """The frame as JSON-ready numbers (``centre`` a list of 3 floats, ``scale``)."""
        return {"centre": [float(c) for c in self.centre], "scale": float(self.scale)}


def unit_frame(V: np.ndarray) -> UnitFrame:
    """The unit frame of positions ``V``.

    Parameters
    ----------
    V : (n, 3) float64 finite positions (validated: :func:`sshade.mesh.validate.validate_mesh`),
        of positive extent.

    Returns
    -------
    :class:`UnitFrame` with ``centre`` the midpoint of ``V``'s bounding box and ``scale``
    ``2 ** e`` where ``diag = m * 2 ** e``, ``0.5 <= m < 1`` (``math.frexp``), so the
    unit-frame box has a diagonal in [0.5, 1).

    Raises
    ------
    ValueError if ``V`` is empty or its bounding box has a zero or non-finite diagonal
    (validated meshes have neither).
    """
    V = np.asarray(V, np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or not len(V):
        raise ValueError(f"unit_frame: V must be (n, 3) with n >= 1, got shape {V.shape}")
    lo, hi = bounding_box(V)
    diag = float(np.linalg.norm(hi - lo))
    if not (math.isfinite(diag) and diag > 0):
        raise ValueError(f"unit_frame: the bounding box's diagonal is {diag}")
    return UnitFrame(centre=0.5 * lo + 0.5 * hi, scale=math.ldexp(1.0, math.frexp(diag)[1]))

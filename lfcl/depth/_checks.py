"""Argument checks shared by the depth modules (one-line ``ValueError`` naming the problem)."""

from __future__ import annotations

import numpy as np


def grid(sensor_shape, pitch) -> tuple[int, int, int, int]:
    """``(U, V, S, T)`` of a mosaic of whole ``pitch`` lenses; ``ValueError`` otherwise."""
    if np.isscalar(pitch):
        pitch = (pitch, pitch)
    try:
        U, V = (int(p) for p in pitch)
    except (TypeError, ValueError):
        raise ValueError(f"pitch must be an integer or (U, V), got {pitch!r}") from None
    if U < 1 or V < 1:
        raise ValueError(f"pitch must be positive, got {U}x{V}")
    if len(sensor_shape) != 2:
        raise ValueError(f"mosaic must have shape [H, W], got {tuple(sensor_shape)}")
    H, W = (int(n) for n in sensor_shape)
    if H < U or W < V or H % U or W % V:
        raise ValueError(f"mosaic {H}x{W} is not a whole number (>= 1) of {U}x{V} lenses")
    return U, V, H // U, W // V

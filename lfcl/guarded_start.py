"""The ``guarded`` ADMM start: linear4d, with Malvar in the lenses where linear4d fails.

linear4d (docs/linear4d.md) reads the neighbouring lenses at the same (u, v). Where the scene
changes sharply from lens to lens (high-contrast edges, clipped highlights) those taps see other
content and its estimate breaks; on the full frames of the two real light fields 1 % of the lenses
carried all of the centre-view PSNR that the Malvar start gains over it (docs/auto.md). Such lenses
stand out in how far the two starts disagree:

    D = sqrt(mean over the lens's samples and colours of (linear4d - malvar)^2 / var(level))

with var the raw's noise model at the lens's mean level. Everywhere else D is set by the noise both
filters smooth differently and by ordinary texture, so a lens takes the Malvar start where D exceeds
``GUARD_FACTOR`` times the frame's median D (and at least ``GUARD_FACTOR`` noise sigmas), and so do its
8 neighbours: an outlier test on the frame's own scale, which does not move with the light level as
a fixed threshold would (one did, measured: docs/auto.md).

The test and the mix run on the host (numpy), on the two starts copied back from the device.
"""

from __future__ import annotations

import numpy as np

from .noise import NoiseEstimate

#: How many times the frame's median disagreement a lens's must exceed to take the Malvar start.
GUARD_FACTOR = 3.0


def disagreement(linear4d_planes: np.ndarray, malvar_planes: np.ndarray, mosaic: np.ndarray, pitch,
                 noise: NoiseEstimate) -> np.ndarray:
    """D per lens [S, T]: the rms difference of the two starts [3, H, W] over the lens, in units of
    the noise sigma at the lens's mean raw level."""
    U, V = pitch
    H, W = mosaic.shape
    S, T = H // U, W // V
    squared = ((linear4d_planes.astype(np.float64) - malvar_planes) ** 2).reshape(3, S, U, T, V).mean(axis=(0, 2, 4))
    level = np.clip(mosaic.reshape(S, U, T, V).mean(axis=(1, 3), dtype=np.float64), 0.0, None)
    variance = np.maximum(noise.gain * level + noise.floor, np.finfo(np.float32).tiny)
    return np.sqrt(squared / variance)


def malvar_lenses(d: np.ndarray, factor: float = GUARD_FACTOR) -> np.ndarray:
    """The lenses [S, T] that take the Malvar start: D above ``factor`` times max(median D, 1), and
    their 8 neighbours (linear4d at a neighbour reads the same lens-to-lens break)."""
    outliers = np.pad(d > factor * max(float(np.median(d)), 1.0), 1)
    S, T = d.shape
    return np.logical_or.reduce([outliers[i:i + S, j:j + T] for i in range(3) for j in range(3)])


def guarded_planes(linear4d_planes: np.ndarray, malvar_planes: np.ndarray, mosaic: np.ndarray, pitch,
                   noise: NoiseEstimate, factor: float = GUARD_FACTOR) -> tuple[np.ndarray, dict]:
    """The guarded start [3, H, W] and what it did (``lenses_from_malvar``, ``factor``, the median D)."""
    U, V = pitch
    d = disagreement(linear4d_planes, malvar_planes, mosaic, pitch, noise)
    chosen = malvar_lenses(d, factor)
    per_pixel = np.repeat(np.repeat(chosen, U, axis=0), V, axis=1)[None]
    planes = np.where(per_pixel, malvar_planes, linear4d_planes).astype(np.float32)
    return planes, {"factor": factor, "median_disagreement": float(np.median(d)),
                    "lenses_from_malvar": int(chosen.sum()), "lenses": int(chosen.size)}

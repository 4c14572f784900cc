"""The ``guarded`` ADMM start: linear4d, with Malvar in the lenses where linear4d fails.

linear4d (docs/linear4d.md) reads the neighbouring lenses at the same (u, v). Where the scene
changes sharply from lens to lens (high-contrast edges, clipped highlights) those taps see other
content and its estimate breaks; on the full frames of the two real light fields 1 % of the lenses
carried all of the centre-view PSNR that the Malvar start gains over it (docs/auto.md). Such lenses
stand out in how far the two starts disagree, D per lens in noise sigmas at the lens's level
(lfcl/ops/lensguard.py). Everywhere else D is set by the noise both filters smooth differently and
by ordinary texture, so a lens takes the Malvar start where D exceeds ``GUARD_FACTOR`` times the
frame's median D (and at least ``GUARD_FACTOR`` noise sigmas), and so do its 8 neighbours: an
outlier test on the frame's own scale, which does not move with the light level as a fixed
threshold would (one did, measured: docs/auto.md).

D is computed and the lenses are swapped on the device; only the [S, T] array of D visits the host.
"""

from __future__ import annotations

import numpy as np

from ..noise.model import NoiseEstimate
from ..ops.lensguard import LensGuard

#: How many times the frame's median disagreement a lens's must exceed to take the Malvar start.
GUARD_FACTOR = 2.5


def malvar_lenses(d: np.ndarray, factor: float = GUARD_FACTOR) -> np.ndarray:
    """The lenses [S, T] that take the Malvar start: D above ``factor`` times max(median D, 1), and
    their 8 neighbours (linear4d at a neighbour reads the same lens-to-lens break)."""
    outliers = np.pad(d > factor * max(float(np.median(d)), 1.0), 1)
    S, T = d.shape
    return np.logical_or.reduce([outliers[i:i + S, j:j + T] for i in range(3) for j in range(3)])


def guarded_start(runtime, linear4d_start, malvar_start, mosaic, pitch, noise: NoiseEstimate,
                  factor: float = GUARD_FACTOR):
    """The guarded start, written into the device ``linear4d_start`` [3, H, W] (which is returned),
    and what it did (``factor``, the median D, ``lenses_from_malvar`` of ``lenses``)."""
    guard = LensGuard(runtime, mosaic.shape, pitch)
    d = guard.disagreement(linear4d_start, malvar_start, mosaic, noise.gain, noise.floor)
    chosen = malvar_lenses(d, factor)
    if chosen.any():
        guard.take(linear4d_start, malvar_start, chosen)
    return linear4d_start, {"factor": factor, "median_disagreement": float(np.median(d)),
                            "lenses_from_malvar": int(chosen.sum()), "lenses": int(chosen.size)}

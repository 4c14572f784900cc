"""The ``guarded`` ADMM start: linear4d, with Malvar in the lenses where linear4d fails or the data cannot tell.

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

With admm-epi's disparity it also takes the Malvar start in the lenses whose epipolar lines carry one
colour (:func:`one_colour_lenses`): with an odd pitch and an odd integer disparity every sample along a
line has the same CFA colour, so neither the data term nor the prior along the lines says anything about
the line's two other colours, and admm-epi keeps whatever the start put there. linear4d's guess breaks on
lens-scale gratings (docs/auto.md, "Periodic content"); Malvar's is Malvar's own.

D is computed and the lenses are swapped on the device; only the [S, T] array of D visits the host.
"""

from __future__ import annotations

import numpy as np

from ..noise.model import NoiseEstimate
from ..ops.lensguard import LensGuard

#: How many times the frame's median disagreement a lens's must exceed to take the Malvar start.
GUARD_FACTOR = 2.5
#: Lenses whose disparity lies within this many lenses per view step of a one-colour disparity
#: (:func:`one_colour_lenses`) take the Malvar start. research/fit_one_colour_start.py on the training captures
#: (admm-epi, 0.5-50 lux, with ONE_COLOUR_CONFIDENCE): every margin from 0.05 to 0.3 left every cell at or above
#: no such rule (4 of 40 cells moved, all finetexture seed 1's: +0.10..+0.17 dB of centre view) and 0.05 is the
#: smallest of them (docs/auto.md, "Periodic content").
ONE_COLOUR_WITHIN = 0.05
#: ... and whose disparity is confident: at least this (lfcl.depth's confidence; the share of lenses at 0.5 or more
#: is what admm-epi's parameters call confident). Without it, at 0.5 lux, the noise gave 36 lenses of a training
#: photograph (Kodak DC120 at 48x48 lenses) an odd disparity and the start's noise in them cost 0.36 dB of centre view.
ONE_COLOUR_CONFIDENCE = 0.5


def with_neighbours(lenses: np.ndarray) -> np.ndarray:
    """``lenses`` [S, T] (bool) and their 8 neighbours: linear4d at a neighbour reads the same lenses."""
    padded = np.pad(lenses, 1)
    S, T = lenses.shape
    return np.logical_or.reduce([padded[i:i + S, j:j + T] for i in range(3) for j in range(3)])


def disagreement_outliers(d: np.ndarray, factor: float = GUARD_FACTOR) -> np.ndarray:
    """The lenses [S, T] whose D is above ``factor`` times max(median D, 1)."""
    return d > factor * max(float(np.median(d)), 1.0)


def malvar_lenses(d: np.ndarray, factor: float = GUARD_FACTOR) -> np.ndarray:
    """The lenses [S, T] that take the Malvar start without a disparity: the outliers of D and their 8
    neighbours (linear4d at a neighbour reads the same lens-to-lens break)."""
    return with_neighbours(disagreement_outliers(d, factor))


def one_colour_lenses(disparity: np.ndarray, pitch, within: float = ONE_COLOUR_WITHIN) -> np.ndarray:
    """The lenses [S, T] whose epipolar lines carry one CFA colour, to ``within`` lenses per view step.

    One step along a line (lfcl/ops/epi.py) moves the sample by ``1 - U k`` sensor rows (and ``1 - V k``
    columns) at an integer disparity k: both even, so the same Bayer colour all along, when the pitch is
    odd and k is odd. Near such a k the line's interpolation between lenses mixes in the other colours
    only weakly. An even pitch has no such disparity."""
    U, V = (int(p) for p in pitch)
    d = np.asarray(disparity, dtype=np.float64)
    k = np.round(d)
    odd = np.mod(1 - U * k, 2) == 0
    odd &= np.mod(1 - V * k, 2) == 0
    return odd & (np.abs(d - k) < within)


def guarded_start(runtime, linear4d_start, malvar_start, mosaic, pitch, noise: NoiseEstimate,
                  factor: float = GUARD_FACTOR, depth=None, one_colour_within: float | None = None):
    """The guarded start, written into the device ``linear4d_start`` [3, H, W] (which is returned),
    and what it did (``factor``, the median D, ``lenses_from_malvar`` of ``lenses``). With ``depth``, admm-epi's
    ``lfcl.depth.DisparityMap``, the lenses of one-colour lines (:func:`one_colour_lenses`, ``one_colour_within``;
    None: :data:`ONE_COLOUR_WITHIN`) whose confidence is at least :data:`ONE_COLOUR_CONFIDENCE` and their neighbours
    take Malvar's too (``one_colour_lenses``, ``one_colour_within``, ``one_colour_confidence``)."""
    guard = LensGuard(runtime, mosaic.shape, pitch)
    d = guard.disagreement(linear4d_start, malvar_start, mosaic, noise.gain, noise.floor)
    outliers = disagreement_outliers(d, factor)
    report = {"factor": factor, "median_disagreement": float(np.median(d))}
    if depth is not None:
        one_colour_within = ONE_COLOUR_WITHIN if one_colour_within is None else float(one_colour_within)
        one_colour = one_colour_lenses(depth.disparity, pitch, one_colour_within)
        one_colour &= depth.confidence >= ONE_COLOUR_CONFIDENCE
        outliers |= one_colour
        report.update(one_colour_within=one_colour_within, one_colour_confidence=ONE_COLOUR_CONFIDENCE,
                      one_colour_lenses=int(one_colour.sum()))
    chosen = with_neighbours(outliers)
    if chosen.any():
        guard.take(linear4d_start, malvar_start, chosen)
    return linear4d_start, {**report, "lenses_from_malvar": int(chosen.sum()), "lenses": int(chosen.size)}

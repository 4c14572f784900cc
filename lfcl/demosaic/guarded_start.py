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

With admm-epi's disparity it also takes the Malvar start where the lines it will follow cannot correct the
start (docs/auto.md, "Periodic content"):

* in the lenses whose epipolar lines carry one colour (:func:`one_colour_lenses`): with an odd pitch and an
  odd integer disparity every sample along a line has the same CFA colour, so neither the data term nor the
  prior along the lines says anything about the line's two other colours: the start fills them, and admm-epi's
  in-lens cross block (lfcl/solvers/epi.py ``InLensCrossGradient``) ties them to the neighbouring lines'.
  linear4d's guess breaks on lens-scale gratings; Malvar's is Malvar's own. The disparity must
  be known there (:func:`known_one_colour_lenses`): confident, or shared by most of the neighbourhood;
* in regions whose disparity is an end of the search range and not confident, and whose micro-images are not
  flat within the noise (:func:`range_edge_lenses`): content beyond the range, or a repeating pattern the cost
  cannot tell from a coloured one, so the lines followed are not the scene's. (A texture-less lens has no line
  to get wrong; its estimate drifts to the range's ends too, where nothing tells the candidates apart.)

D is computed and the lenses are swapped on the device; only the [S, T] array of D visits the host.
"""

from __future__ import annotations

import numpy as np

from ..noise.model import NoiseEstimate
from ..ops.lensguard import LensGuard

#: How many times the frame's median disagreement a lens's must exceed to take the Malvar start.
GUARD_FACTOR = 2.5
#: Lenses whose disparity lies within this many lenses per view step of a one-colour disparity
#: (:func:`one_colour_lenses`) take the Malvar start. research/epi_start_guard.py within, on the training captures
#: (admm-epi, 0.5-50 lux, with CONFIDENT): every margin from 0.05 to 0.3 left every cell at or above
#: no such rule (4 of 40 cells moved, all finetexture seed 1's: +0.10..+0.17 dB of centre view) and 0.05 is the
#: smallest of them (docs/auto.md, "Periodic content").
ONE_COLOUR_WITHIN = 0.05
#: The disparity confidence (lfcl.depth) from which a lens's disparity counts as known, as admm-epi's parameters
#: count it (``confident_share``): one-colour lenses must reach it, range-edge ones must not. Without it, at 0.5 lux,
#: the noise gave 36 lenses of a training photograph (Kodak DC120 at 48x48 lenses) an odd disparity and the start's
#: noise in them cost 0.36 dB of centre view.
CONFIDENT = 0.5
#: A one-colour lens whose confidence is below :data:`CONFIDENT` still counts where at least this many of its 3x3
#: neighbourhood (itself included) are one-colour lenses too. Clipping lowers a right disparity's confidence (a clipped
#: sample only bounds the cost, docs/depth.md): on the periodic scene's grating at 100 lux (54 % of its samples clip)
#: the disparity was 1.01 but its median confidence 0.36, 96 lenses counted instead of ~450, and admm-epi fell to
#: 0.72 dB below Malvar's centre view (+0.28 with this rule). The noise's odd disparities are lone ones.
#: research/epi_start_guard.py majority on the training captures at 0.5-100 lux: 5 cost a training photograph
#: 0.08 dB at 0.5 lux, 7 and 9 no cell more than 0.005 dB, and 7 gained more (docs/auto.md, "Periodic content").
ONE_COLOUR_MAJORITY = 7
#: A range-edge lens counts where at least this many of its 3x3 neighbourhood (itself included) are range-edge
#: lenses: a majority. Lone ones are the noise's (at 0.5 lux 13-14 lenses of two training photographs, which cost
#: them up to 0.26 dB of centre view; docs/auto.md, "Periodic content").
RANGE_EDGE_MAJORITY = 5


def neighbourhood_count(lenses: np.ndarray) -> np.ndarray:
    """Per lens [S, T], how many of its 3x3 neighbourhood (itself included) are in ``lenses`` (bool)."""
    padded = np.pad(lenses, 1).astype(np.int32)
    S, T = lenses.shape
    return sum(padded[i:i + S, j:j + T] for i in range(3) for j in range(3))


def with_neighbours(lenses: np.ndarray) -> np.ndarray:
    """``lenses`` [S, T] (bool) and their 8 neighbours: linear4d at a neighbour reads the same lenses."""
    return neighbourhood_count(lenses) > 0


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


def known_one_colour_lenses(depth, pitch, within: float = ONE_COLOUR_WITHIN, majority: int | None = None) -> np.ndarray:
    """The lenses [S, T] of :func:`one_colour_lenses` whose disparity is known: confident (at least :data:`CONFIDENT`)
    or in a neighbourhood where ``majority`` (None: :data:`ONE_COLOUR_MAJORITY`) of the 3x3 lenses are one-colour
    lenses too. ``depth``: an ``lfcl.depth.DisparityMap`` (its ``disparity`` and ``confidence``)."""
    one_colour = one_colour_lenses(depth.disparity, pitch, within)
    majority = ONE_COLOUR_MAJORITY if majority is None else int(majority)
    return one_colour & ((np.asarray(depth.confidence) >= CONFIDENT) | (neighbourhood_count(one_colour) >= majority))


def range_edge_lenses(depth, flat: np.ndarray | None = None, majority: int | None = None) -> np.ndarray:
    """The lenses [S, T] whose disparity is an end of the search range (the best candidate is the last one), not
    confident (below :data:`CONFIDENT`) and not ``flat`` ([S, T] bool: flat within the noise,
    lfcl/demosaic/flat_lenses.py; None: none is), in a neighbourhood where ``majority`` (None:
    :data:`RANGE_EDGE_MAJORITY`) of the 3x3 lenses are so too.

    ``depth``: an ``lfcl.depth.DisparityMap`` (its ``disparity``, ``confidence``, ``dmax`` and ``step``)."""
    at_end = np.abs(np.asarray(depth.disparity, np.float64)) >= float(depth.dmax) - 0.25 * float(depth.step)
    edge = at_end & (np.asarray(depth.confidence) < CONFIDENT)
    if flat is not None:
        edge &= ~np.asarray(flat, bool)
    return edge & (neighbourhood_count(edge) >= (RANGE_EDGE_MAJORITY if majority is None else int(majority)))


def guarded_start(runtime, linear4d_start, malvar_start, mosaic, pitch, noise: NoiseEstimate,
                  factor: float = GUARD_FACTOR, depth=None, one_colour_within: float | None = None,
                  flat: np.ndarray | None = None, malvar_colour: float = 0.0):
    """The guarded start, written into the device ``linear4d_start`` [3, H, W] (which is returned),
    and what it did (``factor``, the median D, ``lenses_from_malvar`` of ``lenses``). With ``depth``, admm-epi's
    ``lfcl.depth.DisparityMap``, the lenses of one-colour lines whose disparity is known
    (:func:`known_one_colour_lenses`, ``one_colour_within``; None: :data:`ONE_COLOUR_WITHIN`) and their neighbours
    take Malvar's too, and so do the lenses of :func:`range_edge_lenses` (with ``flat``, the lenses flat within the
    noise) and theirs (``one_colour_lenses``, ``one_colour_within``, ``confident``, ``one_colour_majority``,
    ``range_edge_lenses``). ``malvar_colour`` w in [0, 1]: afterwards every pixel keeps the start's level (the mean
    of its three colours) and moves its colour differences by the share w towards Malvar's (0: none, 1: Malvar's;
    admm-epi's schedule sets it by light level, lfcl/solvers/epi.py ``EpiSetting.malvar_colour``): linear4d reads the
    neighbouring lenses at the same (u, v), and on lens-scale texture off the focal plane it misreads colour over the
    whole frame, where the outlier test finds no lens and admm-epi corrects it only slowly (docs/admm.md, "The start's
    colour differences")."""
    if not (isinstance(malvar_colour, (int, float)) and 0.0 <= malvar_colour <= 1.0):
        raise ValueError(f"malvar_colour must be a number in [0, 1], got {malvar_colour!r}")
    guard = LensGuard(runtime, mosaic.shape, pitch)
    d = guard.disagreement(linear4d_start, malvar_start, mosaic, noise.gain, noise.floor)
    outliers = disagreement_outliers(d, factor)
    report = {"factor": factor, "median_disagreement": float(np.median(d))}
    if depth is not None:
        one_colour_within = ONE_COLOUR_WITHIN if one_colour_within is None else float(one_colour_within)
        one_colour = known_one_colour_lenses(depth, pitch, one_colour_within)
        range_edge = range_edge_lenses(depth, flat)
        outliers |= one_colour | range_edge
        report.update(one_colour_within=one_colour_within, confident=CONFIDENT, one_colour_majority=ONE_COLOUR_MAJORITY,
                      one_colour_lenses=int(one_colour.sum()), range_edge_lenses=int(range_edge.sum()))
    chosen = with_neighbours(outliers)
    if chosen.any():
        guard.take(linear4d_start, malvar_start, chosen)
    if malvar_colour > 0:
        guard.colour_differences_from(linear4d_start, malvar_start, malvar_colour)
    return linear4d_start, {**report, "lenses_from_malvar": int(chosen.sum()), "lenses": int(chosen.size),
                            "malvar_colour": float(malvar_colour)}

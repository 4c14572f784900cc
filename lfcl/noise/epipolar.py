"""Noise variances from pairs of raw samples that see the same scene point (along the epipolar lines).

The plane fit of :mod:`lfcl.noise.model` reads the noise inside one micro-image; wherever the scene lies
off the focal plane a micro-image holds a shrunken copy of the scene's texture, and fine texture reads as
noise (up to 15-40x the true sigma on the ``finetexture`` scenes, 6-11x on the Lytro frame at 12-50 lux:
docs/noise.md). The light field itself offers a cleaner measurement: a point seen at lens ``(s, t)`` by
view ``(u, v)`` is seen by view ``(u + du, v + dv)`` at lens ``(s - d du, t - d dv)`` (``d`` the disparity,
HCI's sign). Where ``d du`` and ``d dv`` are whole numbers of lenses, the two raw samples measure the same
radiance with independent noise, so half the mean square of their difference is the noise variance, with
no interpolation and no texture left in it.

Per lens, :func:`pair_variances` takes every view offset ``(du, dv)`` whose lens shift lies within
``tolerance`` lenses of whole numbers and that pairs samples of one CFA colour, and pools their pairs. The
disparity comes from :func:`lfcl.depth.estimate_disparity` on tiles of the raw (:func:`tile_disparities`).
"""

from __future__ import annotations

import numpy as np

#: Largest residual lens shift (lenses) of a kept pair offset (fitted on training captures: research/fit_noise.py).
TOLERANCE = 0.08
#: Pairs of one colour a lens needs to count.
MIN_PAIRS = 6
#: Samples at or above this (normalised raw) are clipped: their differences would read as no noise.
SATURATION = 0.99
#: The disparity is estimated on at most TILES x TILES tiles of TILE x TILE lenses spread over the raw (9216
#: lenses: four times the 48x48-lens captures the estimate was fitted on).
TILE = 32
TILES = 3


def view_offsets(pitch) -> np.ndarray:
    """The view offsets ``(du, dv)`` of a half plane (each pair of views once): [n, 2] int."""
    U, V = pitch
    return np.array([(du, dv) for du in range(U) for dv in range(-(V - 1), V) if (du, dv) > (0, 0)], np.int64)


def offset_shifts(disparity, pitch):
    """Per lens and view offset: the whole-lens shift ``(ns, nt)`` [S, T, n, 2] int and how far the true
    shift ``(d du, d dv)`` lies from it [S, T, n] (inf where the offset pairs no samples of one colour).

    Samples ``(s, u)`` and ``(s - ns, u + du)`` lie ``du - U ns`` sensor rows apart (and ``dv - V nt``
    columns): a Bayer colour pairs with itself when both are even (red, blue, green) or their sum is (green).
    """
    U, V = pitch
    offsets = view_offsets(pitch)
    d = np.asarray(disparity, np.float64)[..., None]
    shift_s, shift_t = d * offsets[:, 0], d * offsets[:, 1]
    ns, nt = np.rint(shift_s), np.rint(shift_t)
    error = np.maximum(np.abs(shift_s - ns), np.abs(shift_t - nt))
    rows, cols = offsets[:, 0] - U * ns, offsets[:, 1] - V * nt
    error = np.where((rows + cols) % 2 == 0, error, np.inf)
    return np.stack([ns, nt], -1).astype(np.int64), error


def pair_variances(mosaic, channels, pitch, disparity, tolerance: float = TOLERANCE):
    """Per lens with at least ``MIN_PAIRS`` pairs: (mean level, noise variance, degrees of freedom).

    ``mosaic`` [S*U, T*V] normalised raw of whole lenses, ``channels`` its CFA colour per pixel (same
    shape), ``disparity`` [S, T]. Every view offset whose lens shift lies within ``tolerance`` of whole
    lenses contributes its pairs of one colour whose partner lies on the raw; clipped samples
    (``SATURATION``) are left out. The pooled pairs share samples, so the degrees of freedom of a lens's
    variance are its pairs or its own samples in them, whichever is fewer.
    """
    U, V = pitch
    S, T = np.shape(disparity)
    m4 = np.asarray(mosaic, np.float64).reshape(S, U, T, V)
    c4 = np.asarray(channels).reshape(S, U, T, V)
    offsets = view_offsets(pitch)
    shift, error = offset_shifts(disparity, pitch)
    s_all, t_all = np.meshgrid(np.arange(S), np.arange(T), indexing="ij")
    diff2, level, count = np.zeros((S, T)), np.zeros((S, T)), np.zeros((S, T), np.int64)
    used = np.zeros((S, U, T, V), bool)  # a lens's own samples that are in some pair
    for k, (du, dv) in enumerate(offsets):
        partner_s, partner_t = s_all - shift[..., k, 0], t_all - shift[..., k, 1]
        lens = (error[..., k] < tolerance) & (partner_s >= 0) & (partner_s < S) & (partner_t >= 0) & (partner_t < T)
        if not lens.any():
            continue
        s, t, s2, t2 = s_all[lens], t_all[lens], partner_s[lens], partner_t[lens]
        u = np.arange(U - du)[None, :, None]  # du >= 0 on the half plane
        v = np.arange(max(0, -dv), V - max(0, dv))[None, None, :]
        s, t, s2, t2 = (a[:, None, None] for a in (s, t, s2, t2))
        a, b = m4[s, u, t, v], m4[s2, u + du, t2, v + dv]
        same = (c4[s, u, t, v] == c4[s2, u + du, t2, v + dv]) & (a < SATURATION) & (b < SATURATION)
        diff2[lens] += np.where(same, (a - b) ** 2, 0.0).sum(axis=(1, 2))
        level[lens] += np.where(same, a + b, 0.0).sum(axis=(1, 2))
        count[lens] += same.sum(axis=(1, 2))
        used[s, u, t, v] |= same
    ok = count >= MIN_PAIRS
    dof = np.minimum(count, used.sum(axis=(1, 3)))
    return level[ok] / (2.0 * count[ok]), diff2[ok] / (2.0 * count[ok]), dof[ok]


def tiles(S: int, T: int, tile: int = TILE, count: int = TILES) -> list[tuple[int, int, int, int]]:
    """Lens blocks ``(s0, s1, t0, t1)`` for the disparity: the whole raw if it is at most ``count`` tiles
    across, else ``count`` x ``count`` tiles of ``tile`` lenses spread evenly over it."""
    def spans(n):
        if n <= tile * count:
            return [(0, n)]
        starts = np.linspace(0, n - tile, count).round().astype(int)
        return [(int(a), int(a) + tile) for a in starts]
    return [(s0, s1, t0, t1) for s0, s1 in spans(S) for t0, t1 in spans(T)]


def tile_pair_variances(mosaic, pattern, pitch, origin, first_guess, device=None):
    """(levels, variances, pairs) over the tiles of :func:`tiles`: each tile's disparity is estimated with
    the ``first_guess`` noise model (its choice of ``d`` barely depends on the model's scale), without the colour
    penalty and the clipped samples' bound (lfcl.depth.cost), as fitted: with either, the training captures' worst
    estimate went from 2.73x the truth to 3.37x and 3.38x (finetexture seed 2 at 50 lux; docs/noise.md)."""
    from ..depth import estimate_disparity
    from ..layout import channel_map

    U, V = pitch
    S, T = mosaic.shape[0] // U, mosaic.shape[1] // V
    out = [], [], []
    for s0, s1, t0, t1 in tiles(S, T):
        block = np.ascontiguousarray(mosaic[s0 * U:s1 * U, t0 * V:t1 * V])
        phase = (origin[0] + s0 * U, origin[1] + t0 * V)
        depth = estimate_disparity(block, pattern, (U, V), origin=phase, noise=first_guess, device=device,
                                   occlusion=False, colour=0.0, clipped=False)
        found = pair_variances(block, channel_map(block.shape, pattern, phase), (U, V), depth.disparity, TOLERANCE)
        for acc, part in zip(out, found):
            acc.append(part)
    return tuple(np.concatenate(acc) for acc in out)

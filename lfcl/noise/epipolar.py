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
``tolerance`` lenses of whole numbers and that pairs samples of one CFA colour, and pools their pairs.

Where ``d du`` stays away from whole lenses (``d`` = 0.3: no offset comes within 0.1 lens) there are no
pairs. :func:`fit_variances` reads the same structure without them: per lens, each view's sample nearest to
the lens's scene point (from the lens ``d (u - uc)`` away) sees the scene within half a lens of it, so the
lens's ~81 samples of one colour are that small scene patch sampled densely; a quadratic surface in the
scene's coordinates takes its texture out, and the residual is the noise.

The disparity comes from :func:`lfcl.depth.estimate_disparity` on tiles of the raw (:func:`tile_variances`).
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
#: Per tile, the fit also tries the disparity map shifted by these (lenses) and keeps the shift with the lowest
#: median variance (texture can only raise it): the estimate's bias on smooth texture (1.45 for a period-8 grating
#: at d = 1.5) left 2.7x the noise, the shifted map 1.03x (docs/noise.md).
FIT_SHIFTS = (-0.1, -0.05, 0.0, 0.05, 0.1)
#: Lens rows :func:`pair_variances` pairs at a time (bounds its memory: every pair's two sample keys).
PAIR_ROWS = 16
#: Degrees of freedom a lens's colour needs in the fit.
MIN_FIT_DOF = 4


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
    """Per lens and colour with at least ``MIN_PAIRS`` pairs: (mean level, noise variance, degrees of freedom).

    ``mosaic`` [S*U, T*V] normalised raw of whole lenses, ``channels`` its CFA colour per pixel (same
    shape), ``disparity`` [S, T]. Every view offset whose lens shift lies within ``tolerance`` of whole
    lenses contributes its pairs of one colour whose partner lies on the raw; clipped samples
    (``SATURATION``) are left out. The pooled pairs share samples; the degrees of freedom of a lens colour's
    variance count that (Satterthwaite's; they were the pairs or the lens's own samples in them, whichever was
    fewer, which undercounted them 2.7x at d = 1: tests/test_noise.py). Each colour is kept apart: pooled, a
    pure-colour lens's lit and unlit samples gave one middling level, no bin of dark samples, and a noise floor of 0
    (docs/noise.md).
    """
    U, V = pitch
    S, T = np.shape(disparity)
    m4 = np.asarray(mosaic, np.float64).reshape(S, U, T, V)
    c4 = np.asarray(channels).reshape(S, U, T, V)
    offsets = view_offsets(pitch)
    shift, error = offset_shifts(disparity, pitch)
    s_all, t_all = np.meshgrid(np.arange(S), np.arange(T), indexing="ij")
    # per lens colour, index (s T + t) 3 + colour: sum of squared differences, of levels, pairs, and sum k_i (k_i - 1)
    # with sample i in k_i of its pairs
    diff2, level, count, shared = (np.zeros(3 * S * T) for _ in range(4))
    for first in range(0, S, PAIR_ROWS):  # lens rows a slab at a time: the sample keys of a slab fit in memory
        keys = []  # (lens colour, sample) of both samples of every pair
        for k, (du, dv) in enumerate(offsets):
            partner_s, partner_t = s_all - shift[..., k, 0], t_all - shift[..., k, 1]
            lens = (error[..., k] < tolerance) & (partner_s >= 0) & (partner_s < S) & (partner_t >= 0) \
                & (partner_t < T) & (s_all >= first) & (s_all < first + PAIR_ROWS)
            if not lens.any():
                continue
            s, t, s2, t2 = s_all[lens], t_all[lens], partner_s[lens], partner_t[lens]
            u = np.arange(U - du)[None, :, None]  # du >= 0 on the half plane
            v = np.arange(max(0, -dv), V - max(0, dv))[None, None, :]
            s, t, s2, t2 = (a[:, None, None] for a in (s, t, s2, t2))
            a, b, colour = m4[s, u, t, v], m4[s2, u + du, t2, v + dv], c4[s, u, t, v]
            same = (colour == c4[s2, u + du, t2, v + dv]) & (a < SATURATION) & (b < SATURATION)
            entry = ((s * T + t) * 3 + colour)[same]
            diff2 += np.bincount(entry, weights=((a - b) ** 2)[same], minlength=3 * S * T)
            level += np.bincount(entry, weights=(a + b)[same], minlength=3 * S * T)
            count += np.bincount(entry, minlength=3 * S * T)
            for ps, pu, pt, pv in ((s, u, t, v), (s2, u + du, t2, v + dv)):
                sample = np.broadcast_to(((ps * U + pu) * T + pt) * V + pv, same.shape)[same]
                keys.append(entry * (S * U * T * V) + sample)
        if keys:
            found, k = np.unique(np.concatenate(keys), return_counts=True)
            shared += np.bincount(found // (S * U * T * V), weights=k * (k - 1.0), minlength=3 * S * T)
    ok = count >= MIN_PAIRS
    # Satterthwaite: pairs that share a sample are correlated; with sample i in k_i of a lens colour's n pairs, their
    # mean square has 4 n^2 / (4 n + sum k_i (k_i - 1)) degrees of freedom.
    dof = 4.0 * count**2 / np.maximum(4.0 * count + shared, 1)
    return level[ok] / (2.0 * count[ok]), diff2[ok] / (2.0 * count[ok]), dof[ok]


def fit_variances(mosaic, channels, pitch, disparity):
    """Per lens and colour with at least ``MIN_FIT_DOF`` degrees of freedom: (mean level, noise variance, degrees
    of freedom) of a quadratic surface fitted to the samples that see the lens's scene patch.

    ``mosaic`` [S*U, T*V] normalised raw of whole lenses, ``channels`` its CFA colour per pixel, ``disparity``
    [S, T]. View ``(u, v)`` sees lens ``(s, t)``'s scene point from lens ``(s - d (u - uc), t - d (v - vc))``;
    its sample on the nearest lens lies ``delta`` (within half a lens) from that point in the scene's
    coordinates. Per colour the samples (clipped ones, ``SATURATION``, and those beyond the raw left out) get a
    least-squares quadratic in ``delta``; at d = 0 every ``delta`` is 0 and the surface is a constant, so the
    degrees of freedom are the samples less the fit's effective parameters (the trace of its hat matrix).
    """
    U, V = pitch
    S, T = np.shape(disparity)
    m4 = np.asarray(mosaic, np.float64).reshape(S, U, T, V)
    c4 = np.asarray(channels).reshape(S, U, T, V)
    d = np.asarray(disparity, np.float64)[:, :, None, None]
    u = (np.arange(U) - (U - 1) / 2)[None, None, :, None]
    v = (np.arange(V) - (V - 1) / 2)[None, None, None, :]
    s, t = np.arange(S)[:, None, None, None], np.arange(T)[None, :, None, None]
    lens_s, lens_t = s + np.rint(-d * u).astype(np.int64), t + np.rint(-d * v).astype(np.int64)
    delta_s = np.broadcast_to(lens_s + d * u - s, (S, T, U, V))
    delta_t = np.broadcast_to(lens_t + d * v - t, (S, T, U, V))
    inside = (lens_s >= 0) & (lens_s < S) & (lens_t >= 0) & (lens_t < T)
    views_u, views_v = np.arange(U)[None, None, :, None], np.arange(V)[None, None, None, :]
    lens_s, lens_t = np.clip(lens_s, 0, S - 1), np.clip(lens_t, 0, T - 1)
    values = m4[lens_s, views_u, lens_t, views_v].reshape(S, T, U * V)
    colours = c4[lens_s, views_u, lens_t, views_v].reshape(S, T, U * V)
    usable = (np.broadcast_to(inside, (S, T, U, V)).reshape(S, T, U * V)) & (values < SATURATION)
    ds, dt = delta_s.reshape(S, T, U * V), delta_t.reshape(S, T, U * V)
    design = np.stack([np.ones_like(ds), ds, dt, ds * ds, ds * dt, dt * dt], axis=-1)
    terms = design.shape[-1]
    out = [], [], []
    for colour in range(3):
        weight = (usable & (colours == colour)).astype(np.float64)
        count = weight.sum(axis=-1)
        mean = (weight * values).sum(axis=-1) / np.maximum(count, 1)
        centred = (values - mean[..., None]) * weight
        normal = np.einsum("stkp,stk,stkq->stpq", design, weight, design)
        inverse = np.linalg.inv(normal + 1e-9 * np.eye(terms))  # the ridge only steadies the terms d = 0 leaves empty
        moments = np.einsum("stkp,stk->stp", design, centred)
        explained = np.einsum("stp,stpq,stq->st", moments, inverse, moments)
        dof = count - np.trace(inverse @ normal, axis1=-2, axis2=-1)
        ok = dof >= MIN_FIT_DOF
        out[0].append(mean[ok])
        out[1].append(np.maximum((centred[ok] ** 2).sum(axis=-1) - explained[ok], 0.0) / dof[ok])
        out[2].append(dof[ok])
    return tuple(np.concatenate(part) for part in out)


def tiles(S: int, T: int, tile: int = TILE, count: int = TILES) -> list[tuple[int, int, int, int]]:
    """Lens blocks ``(s0, s1, t0, t1)`` for the disparity: the whole raw if it is at most ``count`` tiles
    across, else ``count`` x ``count`` tiles of ``tile`` lenses spread evenly over it."""
    def spans(n):
        if n <= tile * count:
            return [(0, n)]
        starts = np.linspace(0, n - tile, count).round().astype(int)
        return [(int(a), int(a) + tile) for a in starts]
    return [(s0, s1, t0, t1) for s0, s1 in spans(S) for t0, t1 in spans(T)]


def tile_variances(mosaic, pattern, pitch, origin, first_guess, device=None):
    """The pairs' and the fit's ``(levels, variances, degrees of freedom)`` over the tiles of :func:`tiles`.

    Each tile's disparity is estimated with the ``first_guess`` noise model (its choice of ``d`` barely depends on
    the model's scale), without the colour penalty and the clipped samples' bound (lfcl.depth.cost), as fitted: with
    either, the training captures' worst pair estimate went from 2.73x the truth to 3.37x and 3.38x (finetexture
    seed 2 at 50 lux; docs/noise.md). The fit takes the map shifted by the one of ``FIT_SHIFTS`` that leaves the
    lowest median variance.
    """
    from ..depth import estimate_disparity
    from ..layout import channel_map

    U, V = pitch
    S, T = mosaic.shape[0] // U, mosaic.shape[1] // V
    pairs, fits = ([], [], []), ([], [], [])
    for s0, s1, t0, t1 in tiles(S, T):
        block = np.ascontiguousarray(mosaic[s0 * U:s1 * U, t0 * V:t1 * V])
        phase = (origin[0] + s0 * U, origin[1] + t0 * V)
        channels = channel_map(block.shape, pattern, phase)
        disparity = estimate_disparity(block, pattern, (U, V), origin=phase, noise=first_guess, device=device,
                                       occlusion=False, colour=0.0, clipped=False).disparity
        found = [pair_variances(block, channels, (U, V), disparity, TOLERANCE)]
        shifted = [fit_variances(block, channels, (U, V), disparity + shift) for shift in FIT_SHIFTS]
        found.append(min(shifted, key=lambda fit: np.median(fit[1]) if fit[1].size else np.inf))
        for into, part in zip((pairs, fits), found):
            for acc, values in zip(into, part):
                acc.append(values)
    return tuple(tuple(np.concatenate(acc) for acc in into) for into in (pairs, fits))

"""Per-lens flatness statistics: the float64 reference against a plain loop and against the
noise model it encodes, and the device op (LensFlatness) against the reference.

Tolerances (device float32 vs reference float64): means rtol 1e-6 (plus 1e-6 of the data's
largest magnitude, for means near zero); chi2 rtol 1e-4 (atol 1e-9).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lfcl.ops.flatlens import VARIANCE_FLOOR, LensFlatness, colour_counts, lens_flatness_np

PATTERNS = ("RGGB", "GRBG", "BGGR")
ORIGINS = ((0, 0), (1, 0), (1, 1))
PITCHES = ((2, 2), (3, 3), (9, 9), (5, 7))


def vignette(pitch) -> np.ndarray:
    """A lens response^2 falling off to the rim: values in (0, 1], dark corners (0)."""
    U, V = pitch
    u = (np.arange(U) - (U - 1) / 2) / (U / 2)
    v = (np.arange(V) - (V - 1) / 2) / (V / 2)
    w = np.clip(1 - 0.8 * (u[:, None] ** 2 + v[None, :] ** 2), 0, None)
    w[w < 0.3] = 0
    w[0, 0] = 0  # every pitch gets a dark pixel (at pitch 2x2 a whole colour of each lens is dark)
    return w


def sensor_colour(pattern: str, row: int, col: int) -> int:
    """0/1/2 for R/G/B at sensor pixel (row, col), straight from the pattern letters."""
    return "RGB".index(pattern[2 * (row % 2) + col % 2])


def noisy_lenses(rng, lenses, pitch, levels=(0.01, 1.0), gain=1e-3, floor=1e-5, weights=None,
                 pattern="RGGB", origin=(0, 0)):
    """Each lens flat per colour at a random level, plus Poisson-Gaussian noise through the
    flat field: var(x) = (gain sqrt(w) level + floor) / w (dark pixels get level-sized junk)."""
    (S, T), (U, V) = lenses, pitch
    w = np.ones(pitch) if weights is None else np.asarray(weights, float)
    cells = np.array([[sensor_colour(pattern, r, c) for c in (0, 1)] for r in (0, 1)])
    rows, cols = np.arange(origin[0], origin[0] + S * U) % 2, np.arange(origin[1], origin[1] + T * V) % 2
    colour = cells[rows[:, None], cols[None, :]]  # [H, W]
    level = rng.uniform(*levels, size=(S, T, 3))
    mu = np.take_along_axis(np.repeat(np.repeat(level, U, axis=0), V, axis=1), colour[..., None], axis=2)[..., 0]
    ww = np.tile(np.where(w > 0, w, 1.0), (S, T))
    sigma = np.sqrt((gain * np.sqrt(ww) * np.maximum(mu, 0) + floor) / ww)
    return mu + sigma * rng.standard_normal(mu.shape)


def device_stats(runtime, mosaic, pattern, pitch, origin, weights, gain, floor):
    op = LensFlatness(runtime, mosaic.shape, pattern, pitch, origin)
    return op(runtime.to_device(mosaic.astype(np.float32)), weights, gain, floor)


def assert_matches(device, reference, mosaic):
    assert np.isfinite(device).all()
    np.testing.assert_allclose(device[..., :3], reference[..., :3], rtol=1e-6, atol=1e-6 * np.abs(mosaic).max())
    # atol: a lens with one pixel per colour has chi2 0, up to the reference's rounding (1e-30)
    np.testing.assert_allclose(device[..., 3], reference[..., 3], rtol=1e-4, atol=1e-9)


# ----------------------------------------------------------------------------- the reference


def loop_flatness(mosaic, pattern, pitch, origin, weights, gain, floor):
    """lens_flatness_np written as the formula reads, one lens and pixel at a time."""
    U, V = pitch
    S, T = mosaic.shape[0] // U, mosaic.shape[1] // V
    w = np.ones(pitch) if weights is None else weights
    out = np.zeros((S, T, 4))
    for s, t in itertools.product(range(S), range(T)):
        pixels = [(float(mosaic[s * U + u, t * V + v]), float(w[u, v]),
                   sensor_colour(pattern, origin[0] + s * U + u, origin[1] + t * V + v))
                  for u in range(U) for v in range(V) if w[u, v] > 0]
        for c in range(3):
            mine = [(x, wi) for x, wi, ci in pixels if ci == c]
            if not mine:
                continue
            mean = sum(wi * x for x, wi in mine) / sum(wi for _, wi in mine)
            out[s, t, c] = mean
            for x, wi in mine:
                var = (gain * np.sqrt(wi) * max(mean, 0.0) + floor) / wi
                out[s, t, 3] += (x - mean) ** 2 / max(var, VARIANCE_FLOOR)
    return out


@pytest.mark.parametrize("origin", [(0, 0), (1, 1)])
def test_reference_matches_plain_loop(rng, origin):
    pitch, weights = (5, 7), vignette((5, 7))
    mosaic = noisy_lenses(rng, (3, 4), pitch, levels=(-0.05, 1.0), weights=weights)
    mosaic[:5, :7] = rng.standard_normal((5, 7))  # one lens of zero-mean data: negative means
    args = ("GRBG", pitch, origin, weights)
    np.testing.assert_allclose(lens_flatness_np(mosaic, *args, gain=1e-3, floor=1e-5),
                               loop_flatness(mosaic, *args, 1e-3, 1e-5), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("origin", [(0, 0), (1, 1)])
@pytest.mark.parametrize("weights", [None, "vignette"])
def test_colour_counts_match_loop(origin, weights):
    pitch = (9, 9)
    w = vignette(pitch) if weights else np.ones(pitch)
    counts = colour_counts((27, 36), "RGGB", pitch, origin, None if weights is None else w)
    expected = np.zeros((3, 4, 3), int)
    for s, t, u, v in itertools.product(range(3), range(4), range(9), range(9)):
        if w[u, v] > 0:
            expected[s, t, sensor_colour("RGGB", origin[0] + s * 9 + u, origin[1] + t * 9 + v)] += 1
    np.testing.assert_array_equal(counts, expected)
    assert counts.sum(axis=2).max() == (w > 0).sum()


@pytest.mark.parametrize("gain,floor", [(1e-3, 1e-5), (1e-5, 1e-3)])  # shot noise / read noise dominated
@pytest.mark.parametrize("weights", [None, "vignette"])
def test_flat_lenses_give_chi2_near_dof_and_edges_far_above(rng, weights, gain, floor):
    # 4000 flat 9x9 lenses of the Poisson-Gaussian model: the mean of chi2 / dof has a spread
    # of sqrt(2 / (dof * 4000)) < 0.3 %; the weighted mean is not quite the best estimate when
    # shot noise dominates under a vignette (that would weigh by 1 / var), which adds a little.
    pitch, lenses = (9, 9), (40, 100)
    w = vignette(pitch) if weights else None
    mosaic = noisy_lenses(rng, lenses, pitch, levels=(0.02, 1.0), gain=gain, floor=floor, weights=w)
    stats = lens_flatness_np(mosaic, "RGGB", pitch, (0, 0), w, gain=gain, floor=floor)
    dof = (colour_counts(mosaic.shape, "RGGB", pitch, (0, 0), w) - 1).sum(axis=2)
    ratio = stats[..., 3].sum() / dof.sum()
    assert abs(ratio - 1) < 0.02, ratio

    # an edge of 10 sigma across one lens: chi2 ~ 25 per pixel
    lens = mosaic[:9, :9]
    mu, sigma = 0.5, np.sqrt(gain * 0.5 + floor)
    lens[:] = mu + sigma * rng.standard_normal((9, 9))
    lens[:, 5:] += 10 * sigma
    edged = lens_flatness_np(mosaic, "RGGB", pitch, (0, 0), w, gain=gain, floor=floor)[0, 0, 3]
    assert edged > 10 * dof[0, 0], (edged, dof[0, 0])


# ----------------------------------------------------------------------------- the device op


@pytest.mark.parametrize("weights", [None, "vignette"])
@pytest.mark.parametrize("pitch", PITCHES)
@pytest.mark.parametrize("pattern,origin", list(itertools.product(PATTERNS, ORIGINS)))
def test_device_matches_reference(runtime, rng, pattern, origin, pitch, weights):
    w = vignette(pitch) if weights else None
    mosaic = noisy_lenses(rng, (4, 5), pitch, levels=(-0.05, 1.0), weights=w).astype(np.float32)
    reference = lens_flatness_np(mosaic, pattern, pitch, origin, w, gain=1e-3, floor=1e-5)
    assert_matches(device_stats(runtime, mosaic, pattern, pitch, origin, w, 1e-3, 1e-5), reference, mosaic)


@pytest.mark.parametrize("level,noise", [(0.0, 1.0), (-3.0, 0.5), (100.0, 1e-3), (1e-3, 1e-4)])
def test_device_matches_reference_at_other_levels(runtime, rng, level, noise):
    # zero-mean and negative data (clipped var), a level far above the noise (float sums)
    pitch, w = (9, 9), vignette((9, 9))
    mosaic = (level + noise * rng.standard_normal((27, 45))).astype(np.float32)
    for gain, floor in [(1e-3, 1e-5), (1e-2, 0.0), (0.0, noise**2)]:
        reference = lens_flatness_np(mosaic, "GRBG", pitch, (1, 0), w, gain=gain, floor=floor)
        assert_matches(device_stats(runtime, mosaic, "GRBG", pitch, (1, 0), w, gain, floor), reference, mosaic)


@pytest.mark.parametrize("weights", [None, "vignette"])
def test_all_zero_mosaic_gives_zero_means_and_chi2(runtime, weights):
    pitch = (2, 2)  # vignetted: one colour per lens has no lit pixel
    w = vignette(pitch) if weights else None
    stats = device_stats(runtime, np.zeros((6, 8), np.float32), "BGGR", pitch, (0, 1), w, 1e-3, 0.0)
    np.testing.assert_array_equal(stats, 0.0)


def test_floor_zero_gain_positive(runtime, rng):
    # var = gain sqrt(w) mu / w: zero for mu <= 0, then VARIANCE_FLOOR
    pitch, w = (9, 9), vignette((9, 9))
    mosaic = noisy_lenses(rng, (3, 3), pitch, levels=(0.05, 1.0), gain=1e-3, floor=0.0, weights=w)
    mosaic[:9, :9] = -0.01  # a lens with negative means, flat: var at the floor, residuals 0
    mosaic[9:18, 9:18] = -0.01 + 1e-3 * rng.standard_normal((9, 9))  # not flat: a huge chi2
    mosaic = mosaic.astype(np.float32)
    reference = lens_flatness_np(mosaic, "RGGB", pitch, (0, 0), w, gain=1e-3, floor=0.0)
    assert reference[0, 0, 3] < 1e-3 and reference[1, 1, 3] > 1e6
    assert_matches(device_stats(runtime, mosaic, "RGGB", pitch, (0, 0), w, 1e-3, 0.0), reference, mosaic)


def test_weights_change_between_calls(runtime, rng):
    pitch = (9, 9)
    mosaic = noisy_lenses(rng, (2, 3), pitch).astype(np.float32)
    op = LensFlatness(runtime, mosaic.shape, "RGGB", pitch)
    device = runtime.to_device(mosaic)
    for w in [vignette(pitch), None, 0.5 * vignette(pitch), vignette(pitch)]:
        reference = lens_flatness_np(mosaic, "RGGB", pitch, (0, 0), w, gain=1e-3, floor=1e-5)
        assert_matches(op(device, w, 1e-3, 1e-5), reference, mosaic)


def test_bad_input_raises(runtime):
    with pytest.raises(ValueError, match="not a whole number of 9x9 lenses"):
        LensFlatness(runtime, (18, 20), "RGGB", (9, 9))
    op = LensFlatness(runtime, (18, 18), "RGGB", (9, 9))
    with pytest.raises(ValueError, match="mosaic must be float32 of shape"):
        op(runtime.to_device(np.zeros((18, 27), np.float32)), None, 1e-3, 1e-5)
    good = runtime.to_device(np.zeros((18, 18), np.float32))
    with pytest.raises(ValueError, match="lens weights must be"):
        op(good, np.ones((3, 3)), 1e-3, 1e-5)
    with pytest.raises(ValueError, match="noise gain must be"):
        op(good, None, -1.0, 1e-5)
    with pytest.raises(ValueError, match="noise floor must be"):
        op(good, None, 1e-3, float("nan"))

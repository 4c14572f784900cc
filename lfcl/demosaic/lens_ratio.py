"""How much a raw changes from lens to lens against within a lens: the content ``auto`` was fitted on.

``--method auto`` (lfcl/demosaic/auto.py) was fitted on synthetic scenes. On raws simulated from
real light fields it lost more (docs/auto.md), and one number separated the two kinds of
content: the *cross-lens ratio*

    ratio = E[(x(s+2, t, u, v) - x(s, t, u, v))^2 - var - var']     (and along t)
            / E[(x(s, t, u+2, v) - x(s, t, u, v))^2 - var - var']   (and along v)

the mean squared difference of samples at the same (u, v) two lenses apart over that of
samples two pixels apart in the same lens (same colour in both pairs, for any pitch),
each less the noise model's variance of the difference (var = gain * x + floor per
sample), so that the ratio does not depend on the exposure. It was 1.1-2.2 on the two real
light fields and 3.0 or more on every synthetic training scene: in the real ones
neighbouring views differ about as much as neighbouring lenses.

With a white image's lens response, the samples are flat-fielded and dark pixels are left
out, as the demosaic does (lfcl/grid/vignetting.py). The ratio is None where either difference is not significantly above the noise
(3 standard errors), e.g. a raw of pure noise or of flat lenses. Large raws are sampled:
bands of 3 lens rows, evenly spaced, about ``max_lenses`` lenses in all.

Example::

    >>> import numpy as np
    >>> from lfcl.noise.model import NoiseEstimate
    >>> rng = np.random.default_rng(0)
    >>> lenses = rng.random((12, 12, 1, 1)) * np.ones((1, 1, 5, 5))  # flat lenses, random from lens to lens
    >>> lenses[:, :, 2, :] += 0.1  # and a little structure inside each
    >>> mosaic = lenses.transpose(0, 2, 1, 3).reshape(60, 60)
    >>> ratio = cross_lens_ratio(mosaic, (5, 5), NoiseEstimate(0.0, 1e-8, 1e-4, "raw"))
    >>> ratio > 10
    True
"""

from __future__ import annotations

import math

import numpy as np

from ..grid.vignetting import flat_field_gain
from ..noise.model import NoiseEstimate

#: Lens rows per sampled band: a lens and the one two rows on.
BAND_ROWS = 3
#: How many standard errors above zero each noise-corrected difference must be.
SIGNIFICANCE = 3.0


def _sampled_lens_rows(S: int, T: int, max_lenses: int) -> list[slice]:
    if max_lenses >= S * T:
        return [slice(0, S)]
    step = BAND_ROWS * math.ceil(S * T / max_lenses)
    return [slice(s0, s0 + BAND_ROWS) for s0 in range(0, S - BAND_ROWS + 1, step)]


def _excess(a, b, var_a, var_b, valid) -> tuple[float, float, int]:
    """Sum and sum of squares of (a - b)^2 - var_a - var_b over ``valid``, and the count."""
    term = np.where(valid, (a - b) ** 2 - var_a - var_b, 0.0)
    return float(term.sum(dtype=np.float64)), float((term * term).sum(dtype=np.float64)), int(valid.sum())


def cross_lens_ratio(mosaic: np.ndarray, pitch, noise: NoiseEstimate, lens_response=None,
                     max_lenses: int = 60_000) -> float | None:
    """The cross-lens ratio of ``mosaic`` [S*U, T*V] (module docstring), or None if not significant.

    ``mosaic``: the normalised raw (not flat-fielded); ``lens_response`` [U, V]: the white
    image's (None: every pixel lit, response 1). ``noise``: the raw's Poisson-Gaussian model.
    """
    U, V = (int(p) for p in pitch)
    H, W = mosaic.shape
    S, T = H // U, W // V
    if S < BAND_ROWS or T < BAND_ROWS or U < 3 or V < 3:
        return None
    gain, weights = ((np.ones((U, V), np.float32),) * 2 if lens_response is None
                     else flat_field_gain(lens_response))
    lit = weights > 0
    lens_grid = np.asarray(mosaic[:S * U, :T * V], dtype=np.float32).reshape(S, U, T, V).transpose(0, 2, 1, 3)
    sums = {"across": [0.0, 0.0, 0], "within": [0.0, 0.0, 0]}
    for rows in _sampled_lens_rows(S, T, max_lenses):
        raw = lens_grid[rows].astype(np.float64)  # [s, T, U, V]; float64: squares of huge values stay finite
        x = raw * gain  # flat-fielded; its variance is the raw's times gain^2
        var = (noise.gain * np.maximum(raw, 0) + noise.floor) * gain * gain
        pairs = {
            "within": [(np.s_[:, :, 2:, :], np.s_[:, :, :-2, :]), (np.s_[:, :, :, 2:], np.s_[:, :, :, :-2])],
            "across": [(np.s_[2:], np.s_[:-2]), (np.s_[:, 2:], np.s_[:, :-2])],
        }
        mask = np.broadcast_to(lit, x.shape)
        for kind, offsets in pairs.items():
            for first, second in offsets:
                total, squares, count = _excess(x[first], x[second], var[first], var[second],
                                                mask[first] & mask[second])
                sums[kind][0] += total
                sums[kind][1] += squares
                sums[kind][2] += count
    means = {}
    for kind, (total, squares, count) in sums.items():
        if count < 2 or not (math.isfinite(total) and math.isfinite(squares)):
            return None
        mean = total / count
        spread = math.sqrt(max(squares / count - mean * mean, 0.0) / count)
        if not mean > SIGNIFICANCE * spread or mean <= 0:
            return None
        means[kind] = mean
    return means["across"] / means["within"]

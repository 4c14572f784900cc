"""Noise level of a lenslet raw of any lens grid, estimated from the raw itself.

The estimator of lfcl/noise/model.py, generalised from aligned lens blocks to the
micro-images of a :class:`lfcl.grid.resampling.SamplingModel`: per lens and colour,
the well-lit pixels (white response >= ``min_response``) of that colour are
fitted by ``response * (a + b u + c v)`` (the scene is nearly flat over one
micro-image; the response carries the vignetting) and the residual variance is
kept. Binned by brightness, a low quantile of those variances (rescaled by the
same quantile of sigma^2 chi^2_dof / dof, see lfcl/noise/model.py) follows
``var = gain * mean + floor``, fitted by least squares. ``sigma`` is the rms
noise per raw pixel at the mean level of the measured pixels, normalised units.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.special

from ..layout import channel_map
from .model import QUANTILE, NoiseEstimate, fit_noise_model

MIN_RESPONSE = 0.8
MIN_SAMPLES = 6  # per lens and colour: 3 parameters and at least 3 degrees of freedom


def estimate_grid_noise(mosaic: np.ndarray, sampling, bins: int = 16, min_response: float = MIN_RESPONSE) -> NoiseEstimate:
    """Poisson-Gaussian noise model of a normalised raw [H, W] of ``sampling``'s lens grid."""
    mosaic = np.asarray(mosaic, np.float64)
    pixels = sampling.measured_pixels()
    rows, cols = np.divmod(pixels, sampling.sensor_shape[1])
    response = sampling.response.ravel()[pixels].astype(np.float64)
    lit = response >= min_response
    pixels, rows, cols, response = pixels[lit], rows[lit], cols[lit], response[lit]
    s, t, u, v = sampling.pixel_coordinates(rows.astype(np.float64), cols.astype(np.float64))
    colour = channel_map((2, 2), sampling.pattern)[rows % 2, cols % 2]
    group = (s * sampling.lenses[1] + t) * 3 + colour
    groups, group = np.unique(group, return_inverse=True)
    y = mosaic.ravel()[pixels]
    design = response[:, None] * np.stack([np.ones_like(u), u - u.mean(), v - v.mean()], axis=1)
    # per group: the 3x3 normal equations from bincounts, solved in one batch
    G = groups.size
    gram = np.stack([np.bincount(group, design[:, a] * design[:, b], G) for a in range(3) for b in range(3)],
                    axis=1).reshape(G, 3, 3)
    moment = np.stack([np.bincount(group, design[:, a] * y, G) for a in range(3)], axis=1)
    count = np.bincount(group, minlength=G)
    enough = count >= MIN_SAMPLES
    coef = np.zeros((G, 3))
    coef[enough] = np.einsum("gij,gj->gi", np.linalg.pinv(gram[enough], hermitian=True), moment[enough])
    residual = y - np.einsum("ki,ki->k", design, coef[group])
    dof = count - 3
    rss = np.bincount(group, residual**2, G)
    mean = np.bincount(group, y, G) / np.maximum(count, 1)
    keep = enough & (dof > 0)
    to_sigma2 = dof[keep] / scipy.special.chdtri(dof[keep], 1 - QUANTILE)  # the chi-square QUANTILE-quantile
    means, variances = mean[keep], rss[keep] / dof[keep] * to_sigma2
    if means.size < 8:
        raise ValueError(f"too few well-lit micro-images ({means.size} lens colours with >= {MIN_SAMPLES} pixels "
                         f"of response >= {min_response}) to estimate the noise")
    gain, floor = fit_noise_model(means, variances, bins)
    level = float(np.mean(mosaic.ravel()[sampling.measured_pixels()]))
    return NoiseEstimate(gain, floor, math.sqrt(max(gain * level + floor, 0.0)), "raw", "plane fit")

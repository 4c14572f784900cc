"""Microlens vignetting: flat-field the raw and weight the data term by the white image.

A lenslet raw is the scene times each pixel's white response ``r`` (the microlens
and main-lens vignetting a white image shows): ``b = r (A x) + noise``. Solving
``min sum w (r (A x) - b)^2`` is the same as ``min sum w r^2 (A x - b / r)^2``, so
the pipeline divides the mosaic by ``r`` (flat-field) and weights the data term by
``r^2`` (the flat-fielded corners are noisier). Pixels whose response is below a
threshold (the dark corners between micro-images) get weight 0: they are left out
of the data term and of the prior (no difference that touches them is penalised),
and after the solve each gets the harmonic fill of its lens's lit pixels
(lfcl/ops/lensfill.py, docs/admm.md).

For an aligned grid the response repeats from lens to lens, so it is one ``U x V``
array (``lens_response``); the slow main-lens falloff that a calibration also
models is left to later stages.
"""

from __future__ import annotations

import numpy as np

DEFAULT_THRESHOLD = 0.2


def lens_response_from_white(white: np.ndarray, pitch) -> np.ndarray:
    """The mean white response of each of the U x V lens pixels, max 1.

    ``white``: a normalised white mosaic [H, W] of the same aligned grid. Averaging
    over all lenses (and so over the Bayer colours, whose phase alternates with an
    odd pitch) gives the geometric vignetting; each colour is first divided by its own
    median so the colour filters do not count as vignetting.
    """
    U, V = pitch
    H, W = (white.shape[0] // U) * U, (white.shape[1] // V) * V
    white = np.asarray(white[:H, :W], dtype=np.float64)
    if H == 0 or W == 0:
        raise ValueError(f"white image {white.shape} is smaller than one {U}x{V} lens")
    balanced = white.copy()
    for r in range(2):
        for c in range(2):
            cell = balanced[r::2, c::2]
            median = float(np.median(cell))
            if not median > 0:
                raise ValueError("the white image is black: it gives no vignetting response")
            balanced[r::2, c::2] = cell / median
    response = balanced.reshape(H // U, U, W // V, V).mean(axis=(0, 2))
    return (response / response.max()).astype(np.float32)


def lens_response_from_calibration(calibration, pitch) -> np.ndarray:
    """The U x V response of an aligned-grid calibration's weight model (colour mean)."""
    U, V = pitch
    if calibration.weight is None:
        return np.ones((U, V), np.float32)
    dr = (np.arange(U) - (U - 1) / 2)[:, None] * np.ones((1, V))
    dc = np.ones((U, 1)) * (np.arange(V) - (V - 1) / 2)[None, :]
    colours = len(calibration.weight.colours)
    response = np.mean([calibration.weight.local_at(np.full(dr.shape, c), dr, dc) for c in range(colours)], axis=0)
    return (response / response.max()).astype(np.float32)


def flat_field(mosaic: np.ndarray, lens_response: np.ndarray, threshold: float = DEFAULT_THRESHOLD):
    """(flat-fielded mosaic, data-term weights [U, V]) for a lens-periodic response.

    Pixels with response < threshold keep their raw value (they get weight 0).
    """
    gain, weights = flat_field_gain(lens_response, threshold)
    U, V = gain.shape
    if mosaic.shape[0] % U or mosaic.shape[1] % V:
        raise ValueError(f"mosaic {mosaic.shape} is not a whole number of {U}x{V} lenses")
    tiled = np.tile(gain, (mosaic.shape[0] // U, mosaic.shape[1] // V))
    return (mosaic * tiled).astype(np.float32), weights


def flat_field_gain(lens_response: np.ndarray, threshold: float = DEFAULT_THRESHOLD):
    """(gain [U, V] that flat-fields a lens, data-term weights [U, V]): 1 / response and response^2
    where the response reaches ``threshold``, 1 and 0 on the dark pixels."""
    response = np.asarray(lens_response, dtype=np.float32)
    if response.ndim != 2 or not np.all(np.isfinite(response)) or response.min() < 0:
        raise ValueError(f"lens response must be a finite, non-negative 2-D array, got shape {response.shape}")
    usable = response >= threshold
    if not usable.any():
        raise ValueError(f"no lens pixel has a white response >= {threshold}: is the white image too dark?")
    gain = np.where(usable, 1.0 / np.maximum(response, 1e-6), 1.0).astype(np.float32)
    return gain, np.where(usable, response**2, 0.0).astype(np.float32)

"""Per-lens colour means and the chi-square of "this lens is flat", for skipping flat lenses.

A lens whose scene patch is one colour (an in-focus flat patch, a sky, a backdrop,
a dark or saturated area) samples a constant per colour plus noise. For each lens and
colour c, over its lit pixels P_c (lens weight w > 0)::

    mu_c  = sum_{P_c} w x / sum_{P_c} w                     weighted mean (w = response^2)
    chi2  = sum_c sum_{P_c} (x - mu_c)^2 / var(mu_c)         var = (gain sqrt(w) mu_c+ + floor) / w

with the raw's Poisson-Gaussian noise model (gain, floor; lfcl/noise/model.py) carried through
the flat field (x = raw / response, so var(x) = var(raw) / response^2). For a flat lens
chi2 follows chi-square with sum_c (|P_c| - 1) degrees of freedom; lfcl/demosaic/flat_lenses.py
turns it into a p-value and decides.

``lens_flatness_np`` is the float64 reference; ``LensFlatness`` runs it on the device.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.flatlens import lens_flatness_np
    >>> stats = lens_flatness_np(np.full((9, 18), 0.25, np.float32), "GRBG", (9, 9), gain=1e-4, floor=1e-6)
    >>> stats.shape, stats[0, 0].tolist()
    ((1, 2, 4), [0.25, 0.25, 0.25, 0.0])
"""

from __future__ import annotations

import numpy as np

from ..device import grid_defines
from ..layout import channel_map, packed_pattern
from . import check_device_array, lens_grid

# var(x) is never below this: a noise model without read noise, a zero mean
VARIANCE_FLOOR = 1e-12


def _lens_weights(lens_weights, pitch) -> np.ndarray:
    U, V = pitch
    if lens_weights is None:
        return np.ones((U, V))
    weights = np.asarray(lens_weights, dtype=np.float64)
    if weights.shape != (U, V) or not np.all(np.isfinite(weights)) or np.any(weights < 0):
        raise ValueError(f"lens weights must be a finite, non-negative {U}x{V} array, got shape {weights.shape}")
    return weights


def colour_counts(sensor_shape, pattern: str, pitch, origin=(0, 0), lens_weights=None) -> np.ndarray:
    """Lit pixels of each colour per lens, int [S, T, 3] (odd pitches: it depends on the lens's Bayer phase)."""
    U, V = pitch
    S, T = sensor_shape[0] // U, sensor_shape[1] // V
    # the Bayer phase of a lens repeats every 2 lens rows and columns: count a 2 x 2 block of lenses
    lit = np.tile(_lens_weights(lens_weights, pitch) > 0, (2, 2))
    channels = channel_map((2 * U, 2 * V), pattern, origin)
    block = np.stack([((channels == c) & lit).reshape(2, U, 2, V).sum(axis=(1, 3)) for c in range(3)], axis=-1)
    return np.tile(block, (-(-S // 2), -(-T // 2), 1))[:S, :T]


def lens_flatness_np(mosaic: np.ndarray, pattern: str, pitch, origin=(0, 0), lens_weights=None, *,
                     gain: float, floor: float) -> np.ndarray:
    """[S, T, 4] float64: the lens's weighted colour means (R, G, B) and its chi2 (module docstring).

    A colour without a lit pixel in the lens gets mean 0 and adds nothing to chi2.
    """
    U, V = pitch
    H, W = mosaic.shape
    if H % U or W % V:
        raise ValueError(f"mosaic {H}x{W} is not a whole number of {U}x{V} lenses")
    S, T = H // U, W // V
    w = np.tile(_lens_weights(lens_weights, pitch), (S, T))
    x = np.asarray(mosaic, dtype=np.float64)
    channels = channel_map((H, W), pattern, origin)

    def per_lens(a):
        return a.reshape(S, U, T, V).sum(axis=(1, 3))

    def spread(a):  # [S, T] -> [H, W], each lens's value over its pixels
        return np.repeat(np.repeat(a, U, axis=0), V, axis=1)

    out = np.zeros((S, T, 4))
    for c in range(3):
        wc = np.where(channels == c, w, 0.0)
        total = per_lens(wc)
        mean = np.divide(per_lens(wc * x), total, out=np.zeros((S, T)), where=total > 0)
        mu = spread(mean)
        var = (gain * np.sqrt(wc) * np.maximum(mu, 0.0) + floor) / np.where(wc > 0, wc, 1.0)
        out[..., c] = mean
        out[..., 3] += per_lens(np.where(wc > 0, (x - mu) ** 2 / np.maximum(var, VARIANCE_FLOOR), 0.0))
    return out


class LensFlatness:
    """lens_flatness_np on the device: float32 mosaic [H, W] in, host float64 [S, T, 4] out."""

    def __init__(self, runtime, sensor_shape, pattern: str, pitch, origin=(0, 0)):
        self.runtime = runtime
        self.height, self.width, self.pitch, self.lenses = lens_grid(sensor_shape, pitch)
        self.pattern = packed_pattern(pattern, origin)
        self._weights = None  # (weights key, device U*V weights): uploaded once per distinct weights
        self._out = runtime.empty((*self.lenses, 4))

    def __call__(self, mosaic, lens_weights, gain: float, floor: float) -> np.ndarray:
        """Stats of the device ``mosaic``; ``lens_weights`` [U, V] on the host, or None for all ones."""
        check_device_array(mosaic, (self.height, self.width), "mosaic")
        for name, value in (("gain", gain), ("floor", floor)):
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"noise {name} must be a finite number >= 0, got {value}")
        weights = _lens_weights(lens_weights, self.pitch)
        key = tuple(weights.ravel().tolist())
        if self._weights is None or self._weights[0] != key:
            self._weights = (key, self.runtime.to_device(weights.astype(np.float32).ravel()))
        S, T = self.lenses
        self.runtime.launch(
            "flatlens", "lens_flatness", (T, S),
            mosaic.data, self._weights[1].data, self._out.data, np.int32(self.height), np.int32(self.width),
            self.pattern, np.float32(gain), np.float32(floor), defines=grid_defines(self.pitch, 0),
        )
        return self._out.get().astype(np.float64)

"""Per-lens disagreement of two ADMM starts, and taking chosen lenses from one: the device half of
the ``guarded`` start (lfcl/demosaic/guarded_start.py has the rule that decides).

For lens (s, t), two starts a, b [3, H, W] and the raw mosaic x::

    D[s, t] = sqrt( mean over its 3 U V samples of (a - b)^2 / var(level) ),
    level   = max(mean of x over the lens, 0),   var = gain level + floor   (lfcl/noise/model.py's model)

``lens_disagreement_np`` and ``take_lenses_np`` are the float64 references; ``LensGuard`` runs
both on the device (lfcl/kernels/lensguard.cl), so only the [S, T] array of D comes back to the host.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.lensguard import lens_disagreement_np
    >>> a, b = np.zeros((3, 9, 18)), np.zeros((3, 9, 18))
    >>> a[:, :, 9:] = 0.03  # the second lens differs by 0.03 in every sample
    >>> lens_disagreement_np(a, b, np.full((9, 18), 0.25), (9, 9), gain=0.0, floor=0.01**2).round(6).tolist()
    [[0.0, 3.0]]
"""

from __future__ import annotations

import numpy as np

from ..device import grid_defines
from . import check_device_array, lens_grid

#: var is never below this (float32's smallest normal): a noise model without read noise, zero level
VARIANCE_FLOOR = float(np.finfo(np.float32).tiny)


def lens_disagreement_np(a: np.ndarray, b: np.ndarray, mosaic: np.ndarray, pitch, *, gain: float,
                         floor: float) -> np.ndarray:
    """D [S, T] float64 (module docstring)."""
    U, V = pitch
    H, W = mosaic.shape
    if H % U or W % V:
        raise ValueError(f"mosaic {H}x{W} is not a whole number of {U}x{V} lenses")
    S, T = H // U, W // V
    squared = ((np.asarray(a, np.float64) - b) ** 2).reshape(3, S, U, T, V).mean(axis=(0, 2, 4))
    level = np.clip(np.asarray(mosaic, np.float64).reshape(S, U, T, V).mean(axis=(1, 3)), 0.0, None)
    return np.sqrt(squared / np.maximum(gain * level + floor, VARIANCE_FLOOR))


def take_lenses_np(x: np.ndarray, source: np.ndarray, chosen: np.ndarray, pitch) -> np.ndarray:
    """``x`` [3, H, W] with the lenses ``chosen`` [S, T] (bool) taken from ``source``."""
    U, V = pitch
    per_pixel = np.repeat(np.repeat(np.asarray(chosen, bool), U, axis=0), V, axis=1)[None]
    return np.where(per_pixel, source, x)


def guard_lens_means_np(x: np.ndarray, malvar: np.ndarray, mosaic: np.ndarray, pitch, *, gain: float,
                        floor: float, k: float) -> tuple[np.ndarray, np.ndarray]:
    """The safety net's lens-mean guard (lfcl/kernels/lensguard.cl ``guard_lens_means``), float64.

    Returns (x with each lens's colour means soft-thresholded towards Malvar's at ``k`` sd, sd the
    noise of a mean of a quarter of the lens's samples at its level; the number of colours [S, T]
    moved all the way to Malvar's mean).
    """
    U, V = pitch
    H, W = mosaic.shape
    if H % U or W % V:
        raise ValueError(f"mosaic {H}x{W} is not a whole number of {U}x{V} lenses")
    S, T = H // U, W // V
    x5 = np.asarray(x, np.float64).reshape(3, S, U, T, V)
    m5 = np.asarray(malvar, np.float64).reshape(3, S, U, T, V)
    level = np.clip(np.asarray(mosaic, np.float64).reshape(S, U, T, V).mean(axis=(1, 3)), 0.0, None)
    limit = k * np.sqrt(np.maximum(gain * level + floor, VARIANCE_FLOOR) / (0.25 * U * V))
    dx = (x5 - m5).mean(axis=(2, 4))  # [3, S, T]
    kept = np.sign(dx) * np.maximum(np.abs(dx) - limit, 0.0)
    out = x5 + (kept - dx)[:, :, None, :, None]
    return out.reshape(np.shape(x)), (np.abs(dx) <= limit).sum(axis=0).astype(np.float64)


class LensGuard:
    """The two references on the device, for [3, H, W] float32 starts of an H x W mosaic."""

    def __init__(self, runtime, sensor_shape, pitch):
        self.runtime = runtime
        self.height, self.width, self.pitch, self.lenses = lens_grid(sensor_shape, pitch)
        self._out = runtime.empty(self.lenses)

    def disagreement(self, a, b, mosaic, gain: float, floor: float) -> np.ndarray:
        """D [S, T] (float64 on the host) of the device starts ``a``, ``b`` over the device ``mosaic``."""
        planes = (3, self.height, self.width)
        check_device_array(a, planes, "a")
        check_device_array(b, planes, "b")
        check_device_array(mosaic, (self.height, self.width), "mosaic")
        S, T = self.lenses
        self.runtime.launch("lensguard", "lens_disagreement", (T, S), a.data, b.data, mosaic.data, self._out.data,
                            np.int32(self.height), np.int32(self.width), np.float32(gain), np.float32(floor),
                            defines=grid_defines(self.pitch, 0))
        return self._out.get().astype(np.float64)

    def guard_means(self, x, malvar, mosaic, gain: float, floor: float, k: float) -> np.ndarray:
        """:func:`guard_lens_means_np` in place on the device ``x``; the [S, T] replaced-colour counts."""
        planes = (3, self.height, self.width)
        check_device_array(x, planes, "x")
        check_device_array(malvar, planes, "malvar")
        check_device_array(mosaic, (self.height, self.width), "mosaic")
        S, T = self.lenses
        self.runtime.launch("lensguard", "guard_lens_means", (T, S), x.data, malvar.data, mosaic.data,
                            self._out.data, np.int32(self.height), np.int32(self.width), np.float32(gain),
                            np.float32(floor), np.float32(k), defines=grid_defines(self.pitch, 0))
        return self._out.get().astype(np.float64)

    def take(self, x, source, chosen: np.ndarray):
        """Overwrite the lenses ``chosen`` [S, T] (host bool) of the device ``x`` with ``source``'s; returns x."""
        planes = (3, self.height, self.width)
        check_device_array(x, planes, "x")
        check_device_array(source, planes, "source")
        if np.shape(chosen) != self.lenses:
            raise ValueError(f"chosen must be a {self.lenses[0]}x{self.lenses[1]} lens mask, got {np.shape(chosen)}")
        marks = self.runtime.to_device(np.ascontiguousarray(chosen, dtype=np.uint8))
        self.runtime.launch("lensguard", "take_lenses", (self.width, self.height), x.data, source.data, marks.data,
                            np.int32(self.height), np.int32(self.width), defines=grid_defines(self.pitch, 0))
        return x

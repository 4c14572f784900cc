"""Per-lens disagreement of two ADMM starts, and taking chosen lenses from one: the device half of
the ``guarded`` start (lfcl/demosaic/guarded_start.py has the rule that decides).

For lens (s, t), two starts a, b [3, H, W] and the raw mosaic x::

    D[s, t] = sqrt( mean over its 3 U V samples of (a - b)^2 / var(level) ),
    level   = max(mean of x over the lens, 0),   var = gain level + floor   (lfcl/noise/model.py's model)

``lens_disagreement_np`` and ``take_lenses_np`` are the float64 references; ``LensGuard`` runs
both on the device (lfcl/kernels/lensguard.cl), so only the [S, T] array of D comes back to the host.
``colour_differences_from_np`` (the start's colour differences taken from another, its level kept) too.

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


def colour_differences_from_np(x: np.ndarray, m: np.ndarray, weight: float = 1.0) -> np.ndarray:
    """``x`` [3, H, W] with its level (the mean of its three colours) kept and its colour differences moved by the
    share ``weight`` towards those of ``m``: ``x_c + weight (m_c + mean_c(x - m) - x_c)`` (lfcl/kernels/lensguard.cl
    ``colour_differences_from``), float64. ``weight`` 1: m's colour differences."""
    x, m = np.asarray(x, np.float64), np.asarray(m, np.float64)
    return x + float(weight) * (m + (x - m).mean(axis=0)[None] - x)


def guard_lens_means_np(x: np.ndarray, malvar: np.ndarray, mosaic: np.ndarray, pitch, *, gain: float,
                        floor: float, k: float, flat: np.ndarray | None = None, flat_means: np.ndarray | None = None,
                        j: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """The safety net's lens-mean guard (lfcl/kernels/lensguard.cl ``guard_lens_means``), float64.

    Returns (x with each lens's colour means soft-thresholded towards Malvar's at ``k`` sd, sd the
    noise of a mean of a quarter of the lens's samples at its level; per lens [S, T], the number of
    colours moved all the way to Malvar's mean, or -1 for a lens filled with its own means). ``k`` inf:
    no soft threshold, every lens keeps its means (the net of a method that has none: admm-epi's).

    ``flat`` [S, T] (bool) and ``flat_means`` [S, T, 3]: the lenses flat within the noise and the
    colour means of their own samples (lfcl/demosaic/flat_lenses.py). A flat lens any of whose
    Malvar colour means lies more than ``j`` sd from its own is filled with its own means instead:
    Malvar's filters read a different micro-image across its border (lfcl/demosaic/safety_net.py).
    """
    U, V = pitch
    H, W = mosaic.shape
    if H % U or W % V:
        raise ValueError(f"mosaic {H}x{W} is not a whole number of {U}x{V} lenses")
    S, T = H // U, W // V
    x5 = np.asarray(x, np.float64).reshape(3, S, U, T, V)
    m5 = np.asarray(malvar, np.float64).reshape(3, S, U, T, V)
    level = np.clip(np.asarray(mosaic, np.float64).reshape(S, U, T, V).mean(axis=(1, 3)), 0.0, None)
    sd = np.sqrt(np.maximum(gain * level + floor, VARIANCE_FLOOR) / (0.25 * U * V))
    limit = k * sd
    malvar_means = m5.mean(axis=(2, 4))  # [3, S, T]
    dx = x5.mean(axis=(2, 4)) - malvar_means
    if np.isinf(k):  # no soft threshold: every lens keeps its own means (only flat lenses may be filled)
        out, replaced = x5, np.zeros(dx.shape[1:])
    else:
        kept = np.sign(dx) * np.maximum(np.abs(dx) - limit, 0.0)
        out = x5 + (kept - dx)[:, :, None, :, None]
        replaced = (np.abs(dx) <= limit).sum(axis=0).astype(np.float64)
    if flat is not None:
        own = np.moveaxis(np.asarray(flat_means, np.float64).reshape(S, T, 3), -1, 0)  # [3, S, T]
        fill = np.asarray(flat, bool).reshape(S, T) & (np.abs(malvar_means - own) > j * sd).any(axis=0)
        out = np.where(fill[None, :, None, :, None], own[:, :, None, :, None], out)
        replaced[fill] = -1.0
    return out.reshape(np.shape(x)), replaced


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

    def guard_means(self, x, malvar, mosaic, gain: float, floor: float, k: float, flat=None, flat_means=None,
                    j: float = np.inf) -> np.ndarray:
        """:func:`guard_lens_means_np` in place on the device ``x``; the [S, T] counts (-1: filled flat).

        ``flat`` [S, T] and ``flat_means`` [S, T, 3] on the host, or None: no lens is filled.
        """
        planes = (3, self.height, self.width)
        check_device_array(x, planes, "x")
        check_device_array(malvar, planes, "malvar")
        check_device_array(mosaic, (self.height, self.width), "mosaic")
        S, T = self.lenses
        if flat is None:
            flat, flat_means = np.zeros((S, T), bool), np.zeros((S, T, 3))
        if np.shape(flat) != (S, T) or np.shape(flat_means) != (S, T, 3):
            raise ValueError(f"flat and flat_means must be [{S}, {T}] and [{S}, {T}, 3], got {np.shape(flat)} and "
                             f"{np.shape(flat_means)}")
        marks = self.runtime.to_device(np.ascontiguousarray(flat, dtype=np.uint8))
        means = self.runtime.to_device(np.ascontiguousarray(flat_means, dtype=np.float32))
        # an infinite j (no lens filled) as the largest float: the comparison stays exact without inf arithmetic
        j32 = np.float32(min(float(j), float(np.finfo(np.float32).max)))
        self.runtime.launch("lensguard", "guard_lens_means", (T, S), x.data, malvar.data, mosaic.data,
                            marks.data, means.data, self._out.data, np.int32(self.height), np.int32(self.width),
                            np.float32(gain), np.float32(floor), np.float32(k), j32,
                            defines=grid_defines(self.pitch, 0))
        return self._out.get().astype(np.float64)

    def colour_differences_from(self, x, source, weight: float = 1.0):
        """:func:`colour_differences_from_np` in place on the device ``x`` [3, H, W]; returns x."""
        planes = (3, self.height, self.width)
        check_device_array(x, planes, "x")
        check_device_array(source, planes, "source")
        self.runtime.launch("lensguard", "colour_differences_from", (self.width, self.height), x.data, source.data,
                            np.int32(self.height), np.int32(self.width), np.float32(weight),
                            defines=grid_defines(self.pitch, 0))
        return x

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

"""Microlens-array geometry of the simulated camera: where each light-field sample lands.

Only the aligned square grid exists so far (``grid="aligned-square"``): lens
``(s, t)`` covers the ``U x V`` sensor pixels whose top-left pixel is
``(offset_row + s*U, offset_col + t*V)``, and sample ``(s, t, u, v)`` of the
exchange layout ``[S, T, U, V, 3]`` (docs/layout.md) is sensor pixel
``(s*U + u, t*V + v)``. Rotated and hexagonal grids will be further ``grid``
values of :class:`LensletGeometry`; everything that maps samples to pixels goes
through this module.

Microlens vignetting (optional) is the natural ``cos^4`` falloff of the chief ray
under each lens: a pixel ``r`` pixels from the lens axis sees the lens pupil at
``tan(theta) = r * pixel_size / f_micro`` with ``f_micro = f_number * pitch *
pixel_size`` (the microlens f-number matches the main lens, paper section 2.2),
so ``factor = cos(theta)^4 = (1 + (r / (f_number * pitch))^2)^-2``. At f/2.8 and
a 9-pixel pitch the centre pixel gets 1.0 and the corner pixels about 0.91.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..layout import LightFieldShape, channel_map, parse_pattern

GRIDS = ("aligned-square",)


@dataclasses.dataclass(frozen=True)
class LensletGeometry:
    """An ``S x T`` array of microlenses, ``U x V`` sensor pixels each."""

    lenses: tuple[int, int]
    pitch: tuple[int, int] = (9, 9)
    grid: str = "aligned-square"
    offset: tuple[int, int] = (0, 0)

    def __post_init__(self):
        lenses = tuple(int(n) for n in self.lenses)
        pitch = tuple(int(n) for n in self.pitch)
        if len(lenses) != 2 or min(lenses) < 1:
            raise ValueError(f"the lens array must be at least 1x1 lenses, got {self.lenses!r}")
        if len(pitch) != 2 or min(pitch) < 2:
            raise ValueError(f"the pitch must be at least 2 pixels per microlens, got {self.pitch!r}")
        if self.grid not in GRIDS:
            raise ValueError(f"unknown lenslet grid {self.grid!r}: expected one of {', '.join(GRIDS)}")
        if tuple(self.offset) != (0, 0):
            raise ValueError(f"only offset (0, 0) is supported so far, got {self.offset!r}")
        object.__setattr__(self, "lenses", lenses)
        object.__setattr__(self, "pitch", pitch)
        object.__setattr__(self, "offset", (0, 0))

    @property
    def shape(self) -> LightFieldShape:
        return LightFieldShape(self.lenses[0], self.lenses[1], self.pitch[0], self.pitch[1])

    @property
    def sensor_shape(self) -> tuple[int, int]:
        return self.shape.sensor_shape

    @property
    def centre(self) -> tuple[float, float]:
        """``(u0, v0) = ((U - 1) / 2, (V - 1) / 2)``: the centre view's (u, v)."""
        return ((self.pitch[0] - 1) / 2.0, (self.pitch[1] - 1) / 2.0)

    def view_offsets(self) -> tuple[np.ndarray, np.ndarray]:
        """``u - u0`` (length U) and ``v - v0`` (length V)."""
        u0, v0 = self.centre
        return np.arange(self.pitch[0]) - u0, np.arange(self.pitch[1]) - v0

    def to_sensor(self, lightfield: np.ndarray) -> np.ndarray:
        """``[S, T, U, V, C]`` -> sensor image ``[S*U, T*V, C]`` (a copy)."""
        S, T = self.lenses
        U, V = self.pitch
        if lightfield.shape[:4] != (S, T, U, V):
            raise ValueError(f"light field shape {lightfield.shape} does not match the {S}x{T} lenses of {U}x{V} pixels")
        channels = lightfield.shape[4:]
        return np.ascontiguousarray(lightfield.transpose(0, 2, 1, 3, *range(4, lightfield.ndim))).reshape(
            S * U, T * V, *channels)

    def mosaic(self, lightfield: np.ndarray, pattern: str) -> np.ndarray:
        """CFA-sample a ``[S, T, U, V, 3]`` light field: the ``[H, W]`` value each pixel's filter passes."""
        channels = channel_map(self.sensor_shape, parse_pattern(pattern), self.offset)
        sensor = self.to_sensor(lightfield)
        return np.take_along_axis(sensor, channels[:, :, None], axis=2)[:, :, 0]

    def vignetting(self, f_number: float = 2.8) -> np.ndarray:
        """Per-(u, v) microlens falloff ``[U, V]`` (1 on the lens axis), see the module docstring."""
        du, dv = self.view_offsets()
        r2 = du[:, None] ** 2 + dv[None, :] ** 2
        focal_px = float(f_number) * float(np.mean(self.pitch))
        return ((1.0 + r2 / focal_px**2) ** -2).astype(np.float32)

    def vignetting_sensor(self, f_number: float = 2.8) -> np.ndarray:
        """The falloff tiled over the sensor ``[H, W]``."""
        return np.tile(self.vignetting(f_number), self.lenses)

    def as_meta(self) -> dict:
        return {
            "grid": self.grid,
            "lenses": list(self.lenses),
            "pitch": list(self.pitch),
            "offset": list(self.offset),
            "sensor_shape": list(self.sensor_shape),
            "sample_to_pixel": "(row, col) = (offset_row + s*U + u, offset_col + t*V + v)",
        }

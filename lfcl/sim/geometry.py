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

:class:`GridGeometry` is a square or hexagonal grid of any pitch, rotation and
offset (lens centres as :class:`lfcl.grid.lattice.LensGrid`): its white image
(:meth:`GridGeometry.white_expected`, :func:`render_white`; docs/calibration.md)
and, with :func:`lfcl.sim.capture.simulate_grid`, raws rendered at every pixel's
true continuous light-field position (:func:`scene_position`; docs/geometry.md).
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


# --------------------------------------------------------------------------- general grids (white images)

WHITE_GRIDS = ("square", "hex")


@dataclasses.dataclass(frozen=True)
class GridGeometry:
    """A square or hexagonal microlens grid of any pitch, rotation and offset over a sensor.

    White images (:func:`white_expected`, :func:`render_white`) and raws
    (:func:`lfcl.sim.capture.simulate_grid`) are simulated for these grids. The
    lens centres follow :class:`lfcl.grid.lattice.LensGrid` (``centre(i, j)``;
    ``offset`` (0, 0), pitch 9, square, no rotation puts lens (0, 0) at pixel
    (4, 4) as in the aligned camera). Each lens forms a micro-image of the main
    lens aperture: a disc of diameter ``fill * pitch`` with a soft edge (Gaussian
    blur of ``edge_px`` px, rms), dark between the discs.
    """

    sensor_shape: tuple[int, int]
    grid: str = "square"
    pitch: float = 9.0
    rotation_deg: float = 0.0
    offset: tuple[float, float] = (0.0, 0.0)
    fill: float = 0.9
    edge_px: float = 0.45

    def __post_init__(self):
        shape = tuple(int(v) for v in self.sensor_shape)
        if len(shape) != 2 or min(shape) < 1:
            raise ValueError(f"the sensor must be at least 1x1 pixels, got {self.sensor_shape!r}")
        if self.grid not in WHITE_GRIDS:
            raise ValueError(f"unknown lenslet grid {self.grid!r}: expected square or hex")
        pitch = float(self.pitch)
        if not np.isfinite(pitch) or pitch < 2:
            raise ValueError(f"the pitch must be at least 2 pixels per microlens, got {self.pitch!r}")
        rotation = float(self.rotation_deg)
        if not np.isfinite(rotation) or abs(rotation) > 45:
            raise ValueError(f"the rotation must be within +-45 degrees, got {self.rotation_deg!r}")
        try:
            offset = tuple(float(v) for v in self.offset)
        except (TypeError, ValueError):
            raise ValueError(f"the offset must be two numbers (rows, cols), got {self.offset!r}") from None
        if len(offset) != 2 or not all(np.isfinite(offset)):
            raise ValueError(f"the offset must be two finite numbers (rows, cols), got {self.offset!r}")
        if not 0.1 <= float(self.fill) <= 1.2:
            raise ValueError(f"fill must be in 0.1..1.2, got {self.fill!r}")
        if not 0 <= float(self.edge_px) <= 10:
            raise ValueError(f"edge_px must be in 0..10, got {self.edge_px!r}")
        for name, value in (("sensor_shape", shape), ("pitch", pitch), ("rotation_deg", rotation),
                            ("offset", offset), ("fill", float(self.fill)), ("edge_px", float(self.edge_px))):
            object.__setattr__(self, name, value)

    @classmethod
    def from_lenses(cls, lenses, grid: str = "square", pitch: float = 9.0, **kwargs) -> GridGeometry:
        """A sensor just large enough for ``lenses = (S, T)`` lens rows and columns (before rotation)."""
        S, T = (int(n) for n in lenses)
        row = float(pitch) * (np.sqrt(3.0) / 2 if grid == "hex" else 1.0)
        return cls((max(1, round(S * row)), max(1, round(T * float(pitch)))), grid, pitch, **kwargs)

    def lens_grid(self):
        from ..grid.lattice import LensGrid

        return LensGrid.from_params(self.grid, self.pitch, self.rotation_deg, self.offset)

    def centres(self):
        """``(i, j, rows, cols)`` of every lens whose centre lies on the sensor."""
        return self.lens_grid().centres(self.sensor_shape)

    def white_expected(self, pattern: str | None = "GRBG", level: float = 0.8, *, vignetting: bool = False,
                       f_number: float = 2.8, main_vignetting: float = 0.0, colour_gains=None,
                       block_rows: int = 512) -> np.ndarray:
        """Noise-free white response ``[H, W]`` float64 in normalised units (expected e- / full well).

        ``level`` at the centre of a micro-image; ``vignetting``: the microlens
        cos^4 falloff ``(1 + r^2 / (f_number * pitch)^2)^-2`` (module docstring);
        ``main_vignetting``: the relative loss in the sensor corners of a smooth
        main-lens falloff of the same form over the sensor; ``colour_gains``:
        ``(R, G, B)`` factors of the white per CFA colour (needs ``pattern``).
        """
        from scipy.special import erfc

        H, W = self.sensor_shape
        grid = self.lens_grid()
        radius = 0.5 * self.fill * self.pitch
        gains = None
        if colour_gains is not None:
            if pattern is None:
                raise ValueError("colour gains need a CFA pattern")
            gains = np.asarray(colour_gains, np.float64)
            if gains.shape != (3,) or not np.all(np.isfinite(gains)) or gains.min() <= 0:
                raise ValueError(f"colour gains must be three positive numbers, got {colour_gains!r}")
            cells = channel_map((2, 2), parse_pattern(pattern))
        if not 0 <= main_vignetting < 1:
            raise ValueError(f"main_vignetting must be in [0, 1), got {main_vignetting!r}")
        out = np.empty((H, W), np.float64)
        cols = np.arange(W, dtype=np.float64)[None, :]
        half_diag2 = ((H - 1) / 2) ** 2 + ((W - 1) / 2) ** 2
        for r0 in range(0, H, block_rows):
            rows = np.arange(r0, min(H, r0 + block_rows), dtype=np.float64)[:, None]
            rr, cc = np.broadcast_arrays(rows, cols)
            _, _, dr, dc = grid.nearest(rr, cc)
            r = np.hypot(dr, dc)
            if self.edge_px > 0:
                value = 0.5 * erfc((r - radius) / (np.sqrt(2.0) * self.edge_px))
            else:
                value = (r <= radius).astype(np.float64)
            if vignetting:
                value *= (1.0 + (r / (float(f_number) * self.pitch)) ** 2) ** -2
            if main_vignetting > 0:
                # (1 + q^2 rho^2)^-2 with q chosen so that the corners lose main_vignetting
                q2 = ((1.0 - main_vignetting) ** -0.5 - 1.0) / max(half_diag2, 1e-12)
                rho2 = (rr - (H - 1) / 2) ** 2 + (cc - (W - 1) / 2) ** 2
                value *= (1.0 + q2 * rho2) ** -2
            if gains is not None:
                value *= gains[cells[rr.astype(np.int64) % 2, cc.astype(np.int64) % 2]]
            out[r0:r0 + rows.shape[0]] = level * value
        return out

    def response(self, *, vignetting: bool = False, f_number: float = 2.8) -> np.ndarray:
        """The micro-image response of every pixel ``[H, W]`` float64, 1 at a disc centre.

        What a raw is multiplied by (the white image's shape, without its level).
        """
        return self.white_expected(None, 1.0, vignetting=vignetting, f_number=f_number)

    def as_meta(self) -> dict:
        grid = self.lens_grid()
        i, _, _, _ = grid.centres(self.sensor_shape)
        return {
            "grid": self.grid,
            "pitch": self.pitch,
            "rotation_deg": self.rotation_deg,
            "offset": list(self.offset),
            "origin": list(grid.origin),
            "row_step": list(grid.row_step),
            "col_step": list(grid.col_step),
            "sensor_shape": list(self.sensor_shape),
            "lenses_on_sensor": int(i.size),
            "micro_image": {"fill": self.fill, "edge_px": self.edge_px,
                            "model": "disc of diameter fill * pitch, Gaussian-blurred edge (edge_px rms)"},
            "centre": "(row, col) of lens (i, j) = origin + i*row_step + (j + (i mod 2)/2 if hex else j)*col_step",
        }


def render_white(geometry: GridGeometry, sensor, rng: np.random.Generator, pattern: str | None = "GRBG",
                 level: float = 0.8, **kwargs) -> np.ndarray:
    """A noisy uint16 white image of a :class:`GridGeometry` through ``sensor`` (a ``SensorModel``)."""
    return sensor.expose(geometry.white_expected(pattern, level, **kwargs), rng)


def scene_position(packing: str, s, t):
    """Scene frame coordinates ``(y, x)`` (lenses, :mod:`lfcl.sim.planes`) of the centre of regular lens (s, t).

    The frame is attached to the lens grid, in units of its pitch: a square grid
    puts lens (s, t) at ``(s + 1/2, t + 1/2)`` like the aligned camera; a
    hexagonal grid's lens rows are sqrt(3)/2 apart and its odd rows shifted by half
    a pitch: ``(s sqrt(3)/2 + 1/2, t + 1/2 + (s mod 2) / 2)`` (the regular block
    starts at an even lens row, lfcl/grid/resampling.py).
    """
    s, t = np.asarray(s), np.asarray(t)
    if packing == "hex":
        return s * (np.sqrt(3.0) / 2) + 0.5, t + 0.5 + 0.5 * (s % 2)
    return s + 0.5, t + 0.5


def scene_frame(packing: str, lenses) -> tuple[int, int]:
    """The scene frame (rows, columns of lenses) that holds an ``S x T`` block of lenses."""
    S, T = (int(n) for n in lenses)
    if packing == "hex":
        return max(1, round(S * np.sqrt(3.0) / 2)), T
    return S, T

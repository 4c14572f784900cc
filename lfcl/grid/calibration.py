"""What a calibration holds: the lens grid, the sensor it belongs to and the white-image weight model.

The weight model (docs/calibration.md) is compact: the white response of a pixel
is ``peak[c] * local[c](dr, dc) * global(row, col)`` with ``c`` the pixel's CFA
colour, ``(dr, dc)`` its offset from the centre of its nearest lens, ``local[c]``
an ``n x n`` table over the offsets (bilinear, max 1) and ``global`` a coarse
grid over the sensor (bilinear between cell centres, max 1) for the slow
main-lens falloff. The per-pixel *weight* is that response divided by
``peak[c]`` (1 for the best-lit pixels); pixels with weight below
``valid_threshold`` are not usable (between micro-images).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..layout import channel_map, parse_pattern
from .lattice import LensGrid

VERSION = 1
FORMAT = "lfcl-calibration"


def _bilinear(table: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``table`` sampled at fractional indices ``(y, x)``, clamped at the border."""
    ny, nx = table.shape
    y = np.clip(y, 0.0, ny - 1.0)
    x = np.clip(x, 0.0, nx - 1.0)
    y0 = np.minimum(np.floor(y).astype(np.int64), max(ny - 2, 0))
    x0 = np.minimum(np.floor(x).astype(np.int64), max(nx - 2, 0))
    fy, fx = y - y0, x - x0
    y1, x1 = np.minimum(y0 + 1, ny - 1), np.minimum(x0 + 1, nx - 1)
    top = table[y0, x0] * (1 - fx) + table[y0, x1] * fx
    bottom = table[y1, x0] * (1 - fx) + table[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


@dataclasses.dataclass
class WeightModel:
    """Mean white response around a lens (per colour) times a coarse sensor-wide falloff."""

    step_px: float  # table spacing, px; table index k <-> offset (k - (n - 1) / 2) * step_px
    colours: tuple[str, ...]  # ("R", "G", "B") or ("Y",) for an image without a CFA pattern
    peak: tuple[float, ...]  # white response (normalised raw units) of the best-lit pixels, per colour
    local: np.ndarray  # float32 [C, n, n], max 1 per colour
    global_map: np.ndarray  # float32 [gr, gc], max 1; cell (y, x) covers rows [y H/gr, (y+1) H/gr)
    valid_threshold: float = 0.2

    def __post_init__(self):
        self.local = np.asarray(self.local, dtype=np.float32)
        self.global_map = np.asarray(self.global_map, dtype=np.float32)
        if self.local.ndim != 3 or self.local.shape[1] != self.local.shape[2] or self.local.shape[1] % 2 != 1:
            raise ValueError(f"the local weight table must be [colours, n, n] with n odd, got {list(self.local.shape)}")
        if self.local.shape[0] != len(self.colours) or len(self.peak) != len(self.colours):
            raise ValueError("the weight model's colours, peaks and tables disagree in number")
        if self.global_map.ndim != 2 or min(self.global_map.shape) < 1:
            raise ValueError(f"the global weight map must be 2-D, got {list(self.global_map.shape)}")
        for name, arr in (("local", self.local), ("global", self.global_map)):
            if not np.all(np.isfinite(arr)) or arr.min() < 0:
                raise ValueError(f"the {name} weight table holds negative or non-finite values")
        if not (np.isfinite(self.step_px) and self.step_px > 0):
            raise ValueError(f"the weight table step must be positive, got {self.step_px!r}")
        if not all(np.isfinite(p) and p > 0 for p in self.peak):
            raise ValueError(f"the weight model's peaks must be positive, got {list(self.peak)}")
        if not 0 <= self.valid_threshold < 1:
            raise ValueError(f"valid_threshold must be in [0, 1), got {self.valid_threshold!r}")
        self.colours = tuple(self.colours)
        self.peak = tuple(float(p) for p in self.peak)

    @property
    def size(self) -> int:
        return int(self.local.shape[1])

    def local_at(self, colour, dr, dc) -> np.ndarray:
        """Relative response at offsets ``(dr, dc)`` from the lens centre for colour index array ``colour``."""
        half = (self.size - 1) / 2
        y = np.asarray(dr, np.float64) / self.step_px + half
        x = np.asarray(dc, np.float64) / self.step_px + half
        colour = np.broadcast_to(np.asarray(colour), y.shape)
        out = np.empty(y.shape, np.float64)
        for c in range(len(self.colours)):
            sel = colour == c
            if np.any(sel):
                out[sel] = _bilinear(self.local[c].astype(np.float64), y[sel], x[sel])
        return out

    def global_at(self, rows, cols, sensor_shape) -> np.ndarray:
        gr, gc = self.global_map.shape
        H, W = sensor_shape
        y = (np.asarray(rows, np.float64) + 0.5) * gr / H - 0.5
        x = (np.asarray(cols, np.float64) + 0.5) * gc / W - 0.5
        return _bilinear(self.global_map.astype(np.float64), y, x)

    def as_dict(self) -> dict:
        return {
            "model": "peak[c] * local[c](dr, dc) * global(row, col); weight = local * global",
            "colours": list(self.colours),
            "peak": [float(p) for p in self.peak],
            "valid_threshold": float(self.valid_threshold),
            "local": {"step_px": float(self.step_px), "size": self.size,
                      "index": "table[c][y][x] at (dr, dc) = ((y - (size-1)/2) * step_px, (x - (size-1)/2) * step_px)",
                      "table": np.round(self.local.astype(np.float64), 4).tolist()},
            "global": {"shape": list(self.global_map.shape),
                       "index": "cell (y, x) covers rows [y*H/gr, (y+1)*H/gr), cols [x*W/gc, (x+1)*W/gc); bilinear between cell centres",
                       "table": np.round(self.global_map.astype(np.float64), 4).tolist()},
        }

    @classmethod
    def from_dict(cls, data: dict) -> WeightModel:
        if not isinstance(data, dict):
            raise ValueError("the weight model must be an object or null")
        try:
            local, glob = data["local"], data["global"]
            return cls(step_px=float(local["step_px"]), colours=tuple(str(c) for c in data["colours"]),
                       peak=tuple(float(p) for p in data["peak"]),
                       local=np.asarray(local["table"], dtype=np.float64),
                       global_map=np.asarray(glob["table"], dtype=np.float64),
                       valid_threshold=float(data.get("valid_threshold", 0.2)))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"the weight model is malformed ({type(exc).__name__}: {exc})") from None


@dataclasses.dataclass
class Calibration:
    """A camera's lens grid and white-image weight model, valid for one sensor size."""

    grid: LensGrid
    sensor_shape: tuple[int, int]
    pattern: str | None = None
    weight: WeightModel | None = None
    fit: dict | None = None
    source: str | None = None
    version: int = VERSION

    def __post_init__(self):
        try:
            shape = tuple(int(v) for v in self.sensor_shape)
        except (TypeError, ValueError):
            raise ValueError(f"sensor_shape must be [rows, cols], got {self.sensor_shape!r}") from None
        if len(shape) != 2 or min(shape) < 1:
            raise ValueError(f"sensor_shape must be two positive integers, got {self.sensor_shape!r}")
        self.sensor_shape = shape
        if self.pattern is not None:
            self.pattern = parse_pattern(self.pattern)
        if self.weight is not None and self.pattern is None and len(self.weight.colours) != 1:
            raise ValueError("a per-colour weight model needs the CFA pattern")
        if self.weight is not None and self.pattern is not None and len(self.weight.colours) != 3:
            raise ValueError("a weight model for a CFA sensor must have R, G and B tables")

    def check(self, sensor_shape, pattern: str | None = None, what: str = "the raw") -> None:
        """``ValueError`` unless this calibration fits a raw of ``sensor_shape`` (and ``pattern``)."""
        shape = tuple(int(v) for v in sensor_shape)
        if shape != self.sensor_shape:
            H, W = self.sensor_shape
            raise ValueError(
                f"the calibration is for a {H}x{W} sensor but {what} is {shape[0]}x{shape[1]}: "
                "calibrate with a white image of this camera")
        if pattern is not None and self.pattern is not None and parse_pattern(pattern) != self.pattern:
            raise ValueError(f"the calibration is for a {self.pattern} sensor but {what} is {parse_pattern(pattern)}")

    def centres(self, margin: float = 0.0):
        """``(i, j, rows, cols)`` of every lens whose centre lies on the sensor."""
        return self.grid.centres(self.sensor_shape, margin)

    def weight_at(self, rows, cols) -> np.ndarray:
        """Per-pixel weight (0..1, 1 = best lit) at integer pixel positions; all ones without a model."""
        rows, cols = np.broadcast_arrays(np.asarray(rows), np.asarray(cols))
        if self.weight is None:
            return np.ones(rows.shape, np.float32)
        _, _, dr, dc = self.grid.nearest(rows, cols)
        if self.pattern is None:
            colour = np.zeros(rows.shape, np.int64)
        else:
            cells = channel_map((2, 2), self.pattern)
            colour = cells[np.asarray(rows) % 2, np.asarray(cols) % 2]
        w = self.weight.local_at(colour, dr, dc) * self.weight.global_at(rows, cols, self.sensor_shape)
        return w.astype(np.float32)

    def weight_map(self, block_rows: int = 256) -> np.ndarray:
        """The weight of every sensor pixel, float32 ``[H, W]`` (computed in row blocks)."""
        H, W = self.sensor_shape
        out = np.empty((H, W), np.float32)
        cols = np.arange(W)[None, :]
        for r0 in range(0, H, block_rows):
            rows = np.arange(r0, min(H, r0 + block_rows))[:, None]
            out[r0:r0 + rows.shape[0]] = self.weight_at(rows, cols)
        return out

    def valid_mask(self) -> np.ndarray:
        """``weight >= valid_threshold`` for every sensor pixel (all True without a weight model)."""
        if self.weight is None:
            return np.ones(self.sensor_shape, bool)
        return self.weight_map() >= self.weight.valid_threshold

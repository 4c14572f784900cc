"""Array layouts and the Bayer phase convention (see docs/layout.md).

Exchange layout (files, public API): a light field is ``[S, T, U, V, 3]`` float32:
S microlens rows (top to bottom), T microlens columns (left to right), U the pixel
row under a microlens, V the pixel column, then R, G, B.

Internal layout (device buffers, solvers): three colour *planes* shaped like the
sensor, ``[3, S*U, T*V]`` = ``[3, S, U, T, V]`` in C order. For an aligned grid
of pitch U x V, sample ``(s, t, u, v)`` sits on sensor pixel
``(row, col) = (s*U + u, t*V + v)``, so the planes are exactly "the lenslet image
with all three colours at every pixel", CFA sampling is a per-pixel pick, and a
step along u, v, s, t is a step of ``W``, ``1``, ``U*W``, ``V`` elements
(``W = T*V``).

Bayer phase (colour-demosaicing's convention): the 4 letters of a pattern name
the colours at sensor pixels (row 0, col 0), (0, 1), (1, 0), (1, 1). A pixel's
colour follows from its *sensor* coordinates, so a crop whose first row or
column is odd shifts the phase (``origin``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

PATTERNS = ("RGGB", "GRBG", "GBRG", "BGGR")
CHANNEL_INDEX = {"R": 0, "G": 1, "B": 2}
DIMS = ("u", "v", "s", "t")


def parse_pattern(pattern: str) -> str:
    """Normalise a Bayer pattern name; ``ValueError`` for anything else."""
    if not isinstance(pattern, str) or pattern.upper() not in PATTERNS:
        raise ValueError(f"unknown Bayer pattern {pattern!r}: expected one of {', '.join(PATTERNS)}")
    return pattern.upper()


def pattern_channels(pattern: str, origin: tuple[int, int] = (0, 0)) -> np.ndarray:
    """2x2 array of channel indices (0=R, 1=G, 2=B) for array rows/cols 0 and 1.

    ``origin`` is the sensor (row, col) of the array's first pixel.
    """
    pattern = parse_pattern(pattern)
    cells = np.array([CHANNEL_INDEX[c] for c in pattern], dtype=np.int32).reshape(2, 2)
    return np.roll(cells, shift=(-(origin[0] % 2), -(origin[1] % 2)), axis=(0, 1))


def packed_pattern(pattern: str, origin: tuple[int, int] = (0, 0)) -> np.int32:
    """The pattern as one int for the kernels: 2 bits per cell, cell = 2*(row&1) + (col&1)."""
    cells = pattern_channels(pattern, origin).ravel()
    return np.int32(sum(int(c) << (2 * i) for i, c in enumerate(cells)))


def channel_map(shape: tuple[int, int], pattern: str, origin: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Per-pixel channel index of a ``(H, W)`` mosaic."""
    cells = pattern_channels(pattern, origin)
    rows = np.arange(shape[0])[:, None] % 2
    cols = np.arange(shape[1])[None, :] % 2
    return cells[rows, cols]


def pattern_from_rawpy(raw_pattern: np.ndarray, color_desc: bytes | str) -> str:
    """Pattern name from rawpy's ``raw_pattern`` (2x2 indices into ``color_desc``)."""
    desc = color_desc.decode() if isinstance(color_desc, bytes) else color_desc
    letters = "".join(desc[int(i)] for i in np.asarray(raw_pattern)[:2, :2].ravel())
    return parse_pattern(letters)


@dataclasses.dataclass(frozen=True)
class LightFieldShape:
    """Sizes of a 4D light field on an aligned grid: S x T lenses of U x V pixels."""

    S: int
    T: int
    U: int
    V: int

    def __post_init__(self):
        for name in ("S", "T", "U", "V"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"light-field size {name} must be a positive integer, got {value!r}")

    @property
    def sensor_shape(self) -> tuple[int, int]:
        return (self.S * self.U, self.T * self.V)

    @property
    def planes_shape(self) -> tuple[int, int, int]:
        return (3, *self.sensor_shape)

    @classmethod
    def from_sensor(cls, sensor_shape: tuple[int, int], pitch: tuple[int, int]) -> LightFieldShape:
        """The light field an aligned grid of ``pitch`` cuts out of a sensor (whole lenses only)."""
        U, V = pitch
        H, W = sensor_shape
        if H < U or W < V:
            raise ValueError(f"sensor {H}x{W} is smaller than one {U}x{V} microlens")
        return cls(H // U, W // V, U, V)

    @classmethod
    def from_exchange(cls, lightfield: np.ndarray) -> LightFieldShape:
        if lightfield.ndim != 5 or lightfield.shape[-1] != 3:
            raise ValueError(f"a light field must have shape [S, T, U, V, 3], got {lightfield.shape}")
        return cls(*(int(n) for n in lightfield.shape[:4]))


def planes_to_exchange(planes: np.ndarray, shape: LightFieldShape) -> np.ndarray:
    """``[3, S*U, T*V]`` planes -> ``[S, T, U, V, 3]`` light field."""
    if planes.shape != shape.planes_shape:
        raise ValueError(f"planes must have shape {shape.planes_shape}, got {planes.shape}")
    five = planes.reshape(3, shape.S, shape.U, shape.T, shape.V)
    return np.ascontiguousarray(five.transpose(1, 3, 2, 4, 0))


def exchange_to_planes(lightfield: np.ndarray) -> np.ndarray:
    """``[S, T, U, V, 3]`` light field -> ``[3, S*U, T*V]`` planes."""
    shape = LightFieldShape.from_exchange(lightfield)
    planes = lightfield.transpose(4, 0, 2, 1, 3).reshape(shape.planes_shape)
    return np.ascontiguousarray(planes, dtype=np.float32)


def tiled_views(lightfield: np.ndarray) -> np.ndarray:
    """The paper's Figure 4b: ``[S, T, U, V, C]`` -> ``[U*S, V*T, C]``, a U x V grid of S x T views."""
    S, T, U, V, C = lightfield.shape
    return np.ascontiguousarray(lightfield.transpose(2, 0, 3, 1, 4)).reshape(U * S, V * T, C)


def dims_mask(dims) -> int:
    """Bit mask of a subset of ('u', 'v', 's', 't'), in that bit order."""
    if isinstance(dims, str):
        dims = tuple(dims)
    dims = tuple(dims)
    unknown = [d for d in dims if d not in DIMS]
    if unknown or not dims or len(set(dims)) != len(dims):
        raise ValueError(f"dims must be a non-empty subset of u, v, s, t without repeats, got {dims!r}")
    return sum(1 << DIMS.index(d) for d in dims)


def ordered_dims(dims) -> tuple[str, ...]:
    """A subset of dims in canonical (u, v, s, t) order: the order of gradient planes."""
    mask = dims_mask(dims)
    return tuple(d for i, d in enumerate(DIMS) if mask & (1 << i))

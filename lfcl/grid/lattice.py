"""Lens-grid models: square and hexagonal lattices of microlens centres on the sensor.

Coordinates are sensor pixels ``(row, col)``: pixel centres at integers, row 0 at
the top, col 0 at the left (docs/calibration.md).

A grid is its packing, the centre of lens ``(0, 0)`` (``origin``) and two step
vectors: ``col_step`` (to the next lens of the same lens row, ``j + 1``) and
``row_step`` (to the next lens row, ``i + 1``, perpendicular to the lens rows).
The centre of lens ``(i, j)`` is

    square:  origin + i * row_step + j * col_step
    hex:     origin + i * row_step + (j + (i mod 2) / 2) * col_step

i.e. the odd lens rows of a hexagonal grid are shifted by half a pitch along the
lens row. For the ideal grids of :meth:`LensGrid.from_params`, with ``p`` the
pitch (centre distance of neighbouring lenses) and ``theta`` the rotation::

    col_step = p * (sin theta, cos theta)
    row_step = h * p * (cos theta, -sin theta)      h = 1 (square), sqrt(3)/2 (hex)
    origin   = offset + ((p - 1) / 2, (p - 1) / 2)

so a positive rotation moves the lenses further right in a lens row further
*down* (clockwise on screen), and ``offset`` (0, 0) with pitch 9, square, no
rotation is the simulator's aligned camera: lens (0, 0) covers pixels 0..8 and
its centre is pixel (4, 4).

Internally, lattice coordinates ``(m, n)`` with the basis ``a = row_step +
col_step / 2`` (hex) or ``a = row_step`` (square) and ``b = col_step`` make both
packings a plain lattice ``origin + m a + n b``; ``i = m`` and ``j = n + m // 2``
(hex) or ``j = n`` (square).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

PACKINGS = ("square", "hex")
HEX_ROW = math.sqrt(3.0) / 2.0


def _pair(value, name: str) -> tuple[float, float]:
    try:
        pair = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be two numbers (row, col), got {value!r}") from None
    if len(pair) != 2 or not all(math.isfinite(v) for v in pair):
        raise ValueError(f"{name} must be two finite numbers (row, col), got {value!r}")
    return pair


def check_packing(packing: str) -> str:
    if not isinstance(packing, str) or packing.lower() not in PACKINGS:
        raise ValueError(f"unknown lens packing {packing!r}: expected square or hex")
    return packing.lower()


@dataclasses.dataclass(frozen=True)
class LensGrid:
    """A square or hexagonal lattice of lens centres (see the module docstring)."""

    packing: str
    origin: tuple[float, float]
    row_step: tuple[float, float]
    col_step: tuple[float, float]

    def __post_init__(self):
        object.__setattr__(self, "packing", check_packing(self.packing))
        for name in ("origin", "row_step", "col_step"):
            object.__setattr__(self, name, _pair(getattr(self, name), name))
        det = self.row_step[0] * self.col_step[1] - self.row_step[1] * self.col_step[0]
        shortest = min(math.hypot(*self.row_step), math.hypot(*self.col_step))
        if shortest < 1.0 or abs(det) < 0.5 * shortest**2:
            raise ValueError(f"degenerate lens grid: row_step {self.row_step}, col_step {self.col_step}")

    # --- construction -------------------------------------------------------
    @classmethod
    def from_params(cls, packing: str = "square", pitch: float = 9.0, rotation_deg: float = 0.0,
                    offset=(0.0, 0.0)) -> LensGrid:
        """The ideal grid of a packing, pitch (px), rotation (degrees) and offset (px)."""
        packing = check_packing(packing)
        try:
            p, theta = float(pitch), math.radians(float(rotation_deg))
        except (TypeError, ValueError):
            raise ValueError(f"pitch and rotation must be numbers, got {pitch!r}, {rotation_deg!r}") from None
        if not math.isfinite(p) or p < 2.0:
            raise ValueError(f"the lens pitch must be at least 2 pixels, got {pitch!r}")
        if not math.isfinite(theta):
            raise ValueError(f"the rotation must be finite, got {rotation_deg!r}")
        offset = _pair(offset, "offset")
        h = HEX_ROW if packing == "hex" else 1.0
        s, c = math.sin(theta), math.cos(theta)
        return cls(packing, (offset[0] + (p - 1) / 2, offset[1] + (p - 1) / 2),
                   (h * p * c + 0.0, -h * p * s + 0.0), (p * s + 0.0, p * c + 0.0))

    @classmethod
    def from_lattice(cls, packing: str, origin, a, b) -> LensGrid:
        """From the lattice basis ``(a, b)`` (module docstring)."""
        packing = check_packing(packing)
        a, b = np.asarray(a, float), np.asarray(b, float)
        row_step = a - b / 2 if packing == "hex" else a
        return cls(packing, tuple(origin), tuple(row_step), tuple(b))

    # --- derived parameters -------------------------------------------------
    @property
    def row_factor(self) -> float:
        """Lens-row spacing / pitch: 1 (square) or sqrt(3)/2 (hex)."""
        return HEX_ROW if self.packing == "hex" else 1.0

    @property
    def pitch(self) -> float:
        """Centre distance of neighbouring lenses, px (mean over the two lattice directions)."""
        return 0.5 * (math.hypot(*self.col_step) + math.hypot(*self.row_step) / self.row_factor)

    @property
    def rotation_deg(self) -> float:
        """Angle of the lens rows against the sensor rows, degrees (positive: clockwise on screen)."""
        a1 = math.atan2(self.col_step[0], self.col_step[1])
        a2 = math.atan2(-self.row_step[1], self.row_step[0])
        return math.degrees(math.atan2(math.sin(a1) + math.sin(a2), math.cos(a1) + math.cos(a2)))

    @property
    def offset(self) -> tuple[float, float]:
        """``origin - ((pitch - 1) / 2, (pitch - 1) / 2)``."""
        half = (self.pitch - 1) / 2
        return (self.origin[0] - half, self.origin[1] - half)

    @property
    def basis(self) -> np.ndarray:
        """2x2 lattice basis, columns ``a`` and ``b`` (module docstring)."""
        b = np.array(self.col_step)
        a = np.array(self.row_step) + (b / 2 if self.packing == "hex" else 0.0)
        return np.stack([a, b], axis=1)

    # --- indices -------------------------------------------------------------
    def index_to_lattice(self, i, j):
        i, j = np.asarray(i), np.asarray(j)
        return i, (j - i // 2) if self.packing == "hex" else j

    def lattice_to_index(self, m, n):
        m, n = np.asarray(m), np.asarray(n)
        return m, (n + m // 2) if self.packing == "hex" else n

    def lattice_point(self, m, n):
        """Centre ``(rows, cols)`` of lattice point(s) ``(m, n)`` (float64)."""
        m, n = np.asarray(m, np.float64), np.asarray(n, np.float64)
        basis = self.basis
        return (self.origin[0] + m * basis[0, 0] + n * basis[0, 1],
                self.origin[1] + m * basis[1, 0] + n * basis[1, 1])

    def centre(self, i, j):
        """Centre ``(rows, cols)`` of lens(es) ``(i, j)``."""
        return self.lattice_point(*self.index_to_lattice(np.asarray(i, np.int64), np.asarray(j, np.int64)))

    def lattice_coords(self, rows, cols):
        """Fractional lattice coordinates ``(m, n)`` of sensor positions."""
        inv = np.linalg.inv(self.basis)
        dr = np.asarray(rows, np.float64) - self.origin[0]
        dc = np.asarray(cols, np.float64) - self.origin[1]
        return inv[0, 0] * dr + inv[0, 1] * dc, inv[1, 0] * dr + inv[1, 1] * dc

    def nearest_lattice(self, rows, cols):
        """Nearest lattice point ``(m, n)`` (int64) of each position and the offset ``(dr, dc)`` from it.

        Square: rounding the lattice coordinates. Hex: the lattice is two rectangular
        lattices (even and odd lens rows); the nearer of the two rounded candidates.
        Exact for ideal grids (row_step perpendicular to col_step); for slightly
        sheared fitted grids only positions on a cell border can go to the other side.
        """
        fm, fn = self.lattice_coords(rows, cols)
        A, B = np.array(self.row_step), np.array(self.col_step)
        if self.packing == "square":
            m = np.rint(fm)
            n = np.rint(fn)
            fm -= m
            fn -= n
            return (m.astype(np.int64), n.astype(np.int64),
                    fm * A[0] + fn * B[0], fm * A[1] + fn * B[1])
        t = fn + 0.5 * fm  # coordinate along the lens row (x - origin = fm * A + t * B)
        m1 = 2.0 * np.rint(0.5 * fm)
        t1 = np.rint(t)
        m2 = 2.0 * np.rint(0.5 * (fm - 1.0)) + 1.0
        t2 = np.rint(t - 0.5) + 0.5
        ds1, dt1 = fm - m1, t - t1
        ds2, dt2 = fm - m2, t - t2
        dr1, dc1 = ds1 * A[0] + dt1 * B[0], ds1 * A[1] + dt1 * B[1]
        dr2, dc2 = ds2 * A[0] + dt2 * B[0], ds2 * A[1] + dt2 * B[1]
        second = dr2 * dr2 + dc2 * dc2 < dr1 * dr1 + dc1 * dc1
        m = np.where(second, m2, m1)
        tt = np.where(second, t2, t1)
        n = np.rint(tt - 0.5 * m)
        return (m.astype(np.int64), n.astype(np.int64),
                np.where(second, dr2, dr1), np.where(second, dc2, dc1))

    def nearest(self, rows, cols):
        """Nearest lens ``(i, j)`` of each position and the offset ``(dr, dc)`` from its centre."""
        m, n, dr, dc = self.nearest_lattice(rows, cols)
        i, j = self.lattice_to_index(m, n)
        return i, j, dr, dc

    def lattice_range(self, sensor_shape, margin: float = 0.0):
        """Bounds ``(m_lo, m_hi, n_lo, n_hi)`` (inclusive) of lattice points that can lie on the sensor."""
        H, W = sensor_shape
        corners_r = np.array([-0.5, -0.5, H - 0.5, H - 0.5]) + np.array([-1, -1, 1, 1]) * abs(margin)
        corners_c = np.array([-0.5, W - 0.5, -0.5, W - 0.5]) + np.array([-1, 1, -1, 1]) * abs(margin)
        fm, fn = self.lattice_coords(corners_r, corners_c)
        return (int(np.floor(fm.min())) - 1, int(np.ceil(fm.max())) + 1,
                int(np.floor(fn.min())) - 1, int(np.ceil(fn.max())) + 1)

    def centres(self, sensor_shape, margin: float = 0.0):
        """Every lens whose centre lies on the sensor: ``(i, j, rows, cols)``, sorted by ``(i, j)``.

        "On the sensor": ``0 <= row <= H - 1`` and ``0 <= col <= W - 1`` (the span of the
        pixel centres), shrunk by ``margin`` pixels on every side.
        """
        H, W = (int(v) for v in sensor_shape)
        m_lo, m_hi, n_lo, n_hi = self.lattice_range((H, W))
        m = np.arange(m_lo, m_hi + 1, dtype=np.int64)[:, None]
        n = np.arange(n_lo, n_hi + 1, dtype=np.int64)[None, :]
        m, n = np.broadcast_arrays(m, n)
        m, n = m.ravel(), n.ravel()
        rows, cols = self.lattice_point(m, n)
        inside = ((rows >= margin) & (rows <= H - 1 - margin)
                  & (cols >= margin) & (cols <= W - 1 - margin))
        m, n, rows, cols = m[inside], n[inside], rows[inside], cols[inside]
        i, j = self.lattice_to_index(m, n)
        order = np.lexsort((j, i))
        return i[order], j[order], rows[order], cols[order]

    def canonical(self) -> LensGrid:
        """The same lattice with lens (0, 0) the lattice point nearest ``((p - 1) / 2, (p - 1) / 2)``."""
        half = (self.pitch - 1) / 2
        m, n, _, _ = self.nearest_lattice(np.array([half]), np.array([half]))
        rows, cols = self.lattice_point(m[0], n[0])
        return dataclasses.replace(self, origin=(float(rows), float(cols)))

    # --- (de)serialisation --------------------------------------------------
    def as_dict(self) -> dict:
        return {
            "packing": self.packing,
            "pitch": self.pitch,
            "rotation_deg": self.rotation_deg,
            "offset": list(self.offset),
            "origin": list(self.origin),
            "row_step": list(self.row_step),
            "col_step": list(self.col_step),
        }

    @classmethod
    def from_dict(cls, data: dict) -> LensGrid:
        """From :meth:`as_dict` output: ``origin``/``row_step``/``col_step`` define the grid."""
        if not isinstance(data, dict):
            raise ValueError("the grid must be an object")
        missing = [k for k in ("packing", "origin", "row_step", "col_step") if k not in data]
        if missing:
            raise ValueError(f"the grid lacks {', '.join(missing)}")
        return cls(data["packing"], data["origin"], data["row_step"], data["col_step"])

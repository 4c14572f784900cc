"""Render a 4D light field from fronto-parallel textured planes, with occlusion.

Scene coordinates are in *lenses*: ``x`` runs along t (columns), ``y`` along s
(rows), and lens ``(s, t)`` covers the unit square ``[s, s+1) x [t, t+1)``, so
the frame is ``[0, S] x [0, T]``.

View ``(u, v)`` of lens ``(s, t)`` sees a plane of disparity ``d`` (lenses per
view step) at

    y = s + 1/2 + dy + d * (u - u0),    x = t + 1/2 + dx + d * (v - v0),

``u0 = (U - 1) / 2``, ``v0 = (V - 1) / 2``: the view at ``u - u0 = +1`` samples
the texture ``d`` lenses further down than the centre view, so a feature at row
``y`` of the centre view appears at ``y - d`` there. ``(dy, dx)`` run over an
``n x n`` grid of sub-sample offsets ``(k + 1/2) / n - 1/2`` (a box filter over
the lens footprint; ``n = 3`` by default), and the sample is their mean.

Every sub-sample takes the colour of the *frontmost* plane whose support
(rectangle, disc, or everywhere) covers it; planes are given front to back and
a full-frame background plane should come last (points no plane covers stay
black). Disparity is a property of the plane, independent of its depth order,
so any depth ordering and disparity sign can be modelled.

The work is vectorised over blocks of lens rows so that any lens count fits in a
bounded amount of memory (about ``CHUNK_POINTS`` sub-samples per block).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

Texture = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``texture(x, y) -> (N, 3)`` linear RGB at frame coordinates ``x, y`` (1-D float arrays)."""

CHUNK_POINTS = 3_000_000


@dataclasses.dataclass
class Plane:
    """A fronto-parallel textured plane.

    ``rect`` is ``(y0, x0, y1, x1)`` in frame coordinates (lenses), ``None`` for
    a plane that covers everything (the background). ``shape`` is ``"rect"`` or
    ``"disc"`` (the ellipse inscribed in ``rect``). ``depth_m`` is informative.
    """

    name: str
    disparity: float
    texture: Texture
    rect: tuple[float, float, float, float] | None = None
    shape: str = "rect"
    depth_m: float | None = None

    def __post_init__(self):
        if self.shape not in ("rect", "disc"):
            raise ValueError(f"plane shape must be 'rect' or 'disc', got {self.shape!r}")
        if not np.isfinite(self.disparity):
            raise ValueError(f"plane {self.name!r} has a non-finite disparity")

    def covers(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        if self.rect is None:
            return np.ones(x.shape, dtype=bool)
        y0, x0, y1, x1 = self.rect
        if self.shape == "rect":
            return (y >= y0) & (y < y1) & (x >= x0) & (x < x1)
        cy, cx, ry, rx = (y0 + y1) / 2, (x0 + x1) / 2, (y1 - y0) / 2, (x1 - x0) / 2
        return ((y - cy) / ry) ** 2 + ((x - cx) / rx) ** 2 < 1.0

    def as_meta(self) -> dict:
        return {
            "name": self.name,
            "disparity": float(self.disparity),
            "depth_m": self.depth_m,
            "rect_yxyx": None if self.rect is None else [float(c) for c in self.rect],
            "shape": self.shape if self.rect is not None else "everywhere",
        }


def subsample_offsets(n: int) -> np.ndarray:
    """Centres of an ``n``-cell box over ``[-1/2, 1/2)``."""
    return (np.arange(n) + 0.5) / n - 0.5


def _render_rows(planes, s_rows, T, du, dv, offsets):
    """Mean colour of the lens rows ``s_rows``: ``[len(s_rows), T, U, V, 3]``."""
    n = len(offsets)
    U, V = len(du), len(dv)
    shape = (len(s_rows), T, U, V, n, n)
    # Flat per-sub-sample coordinates of the centre view and the view offsets.
    y_base = np.broadcast_to((s_rows + 0.5)[:, None, None, None, None, None]
                             + offsets[None, None, None, None, :, None], shape).ravel()
    x_base = np.broadcast_to((np.arange(T) + 0.5)[None, :, None, None, None, None]
                             + offsets[None, None, None, None, None, :], shape).ravel()
    u_off = np.broadcast_to(du[None, None, :, None, None, None], shape).ravel()
    v_off = np.broadcast_to(dv[None, None, None, :, None, None], shape).ravel()
    return _shade(planes, y_base, x_base, u_off, v_off).reshape(shape + (3,)).mean(axis=(4, 5))


def _shade(planes, y_base, x_base, u_off, v_off) -> np.ndarray:
    """Colour of the frontmost plane at each flat sub-sample (view offsets ``u_off``, ``v_off``): [N, 3]."""
    colour = np.zeros((y_base.size, 3), dtype=np.float32)
    remaining = np.arange(y_base.size)
    for plane in planes:
        if remaining.size == 0:
            break
        y = y_base[remaining] + plane.disparity * u_off[remaining]
        x = x_base[remaining] + plane.disparity * v_off[remaining]
        if plane.rect is None:
            colour[remaining] = plane.texture(x, y)
            remaining = remaining[:0]
            continue
        hit = plane.covers(x, y)
        if hit.any():
            colour[remaining[hit]] = plane.texture(x[hit], y[hit])
            remaining = remaining[~hit]
    return colour


def render_points(planes, y, x, u_off, v_off, supersample: int = 3, footprint=(1.0, 1.0)) -> np.ndarray:
    """Mean colour of the planes at arbitrary light-field points: ``[N, 3]`` float32.

    Point k is the lens whose centre sits at frame coordinates ``(y[k], x[k])``
    seen from the continuous view offsets ``(u_off[k], v_off[k])`` (= ``u - u0``,
    ``v - v0``, view steps): the sub-samples ``y + footprint[0] * dy + d * u_off``,
    ``x + footprint[1] * dx + d * v_off`` for an ``n x n`` box of ``(dy, dx)``
    (as :func:`render_planes`, whose lens covers a unit square: footprint (1, 1)).
    The lattice-free twin of :func:`render_planes` for lens grids of any
    geometry (lfcl/sim/capture.py :func:`simulate_grid`).
    """
    y, x, u_off, v_off = (np.asarray(a, np.float64).ravel() for a in np.broadcast_arrays(y, x, u_off, v_off))
    if supersample < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    offsets = subsample_offsets(supersample)
    dy = (float(footprint[0]) * offsets)[:, None]
    dx = (float(footprint[1]) * offsets)[None, :]
    n2 = supersample * supersample
    out = np.empty((y.size, 3), np.float32)
    per_chunk = max(1, CHUNK_POINTS // n2)
    for k0 in range(0, y.size, per_chunk):
        k = slice(k0, min(y.size, k0 + per_chunk))
        count = k.stop - k.start
        y_base = np.broadcast_to(y[k, None, None] + dy[None], (count, supersample, supersample)).ravel()
        x_base = np.broadcast_to(x[k, None, None] + dx[None], (count, supersample, supersample)).ravel()
        u = np.repeat(u_off[k], n2)
        v = np.repeat(v_off[k], n2)
        out[k] = _shade(planes, y_base, x_base, u, v).reshape(count, n2, 3).mean(axis=1)
    return out


def render_planes(planes, lenses, pitch, supersample: int = 3, progress: bool | None = False) -> np.ndarray:
    """Render ``planes`` (front to back) into a ``[S, T, U, V, 3]`` float32 light field.

    ``pitch`` is an int or ``(U, V)``. ``progress``: ``True`` shows a tqdm bar,
    ``None`` shows one only on a terminal and for renders of several blocks.
    """
    S, T = (int(n) for n in lenses)
    U, V = (int(pitch), int(pitch)) if np.isscalar(pitch) else (int(n) for n in pitch)
    if min(S, T) < 1 or min(U, V) < 1:
        raise ValueError(f"cannot render {S}x{T} lenses of {U}x{V} pixels")
    if supersample < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    du = np.arange(U) - (U - 1) / 2.0
    dv = np.arange(V) - (V - 1) / 2.0
    offsets = subsample_offsets(supersample)
    rows_per_chunk = max(1, CHUNK_POINTS // (T * U * V * supersample**2))
    out = np.empty((S, T, U, V, 3), dtype=np.float32)
    starts = range(0, S, rows_per_chunk)
    if progress is False:
        iterator = starts
    else:
        from tqdm import tqdm

        disable = None if progress is None else False
        if progress is None and len(starts) < 4:
            disable = True
        iterator = tqdm(starts, desc="render", unit="block", disable=disable, leave=False)
    for s0 in iterator:
        s_rows = np.arange(s0, min(S, s0 + rows_per_chunk))
        out[s_rows[0]:s_rows[-1] + 1] = _render_rows(planes, s_rows.astype(np.float64), T, du, dv, offsets)
    return out

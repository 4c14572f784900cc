"""The ``deadleaves`` scene: dead-leaves textures on planes at several depths.

The dead-leaves ("spilled coins") target used in camera testing (Cao, Guichard
and Hornung; IEEE P1858 / ISO 19567-2): opaque discs with random centres,
random colours and power-law radii, ``p(r) ~ r^-3`` on ``[r_min, r_max]``
(scale invariant), dropped one over another until the plane is covered.

Here: ``r_min = 0.5`` lens, ``r_max`` a quarter of the plane's smaller side
(of the frame for the background); colours uniform in sRGB
code values ``[0.04, 0.96]^3`` decoded to linear (sRGB EOTF); enough discs for
an expected coverage of 8 (uncovered fraction e^-8 = 0.03 %, left mid grey).
Each texture is rasterised once at ``RASTER_SCALE`` pixels per lens (disc
index per raster pixel, tested at pixel centres) over the frame plus the margin
its disparity shifts into view, and sampled at the nearest raster pixel; the
renderer's 3x3 sub-sampling then box-filters the lens footprint.

Planes, front to back (every texture has its own random stream derived from
``--seed``, so the scene is deterministic):

* ``front disc`` disparity +0.35, a disc of diameter 0.36 * frame, upper left;
* ``focus square`` disparity 0 (in focus), the central 56 % x 56 %;
* ``back strip`` disparity -0.15, a strip along the right;
* ``background`` disparity -0.3, the whole frame.
"""

from __future__ import annotations

import numpy as np

from .planes import Plane

RASTER_SCALE = 6
R_MIN = 0.5
COVERAGE = 8.0


def _srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _power_law_radii(rng, n, r_min, r_max):
    """Inverse-CDF sampling of p(r) ~ r^-3 on [r_min, r_max]."""
    q = rng.random(n)
    a, b = r_min**-2, r_max**-2
    return (a - q * (a - b)) ** -0.5


class DeadLeavesTexture:
    """A dead-leaves texture over frame box ``(y0, x0, y1, x1)`` (lenses)."""

    def __init__(self, box, rng: np.random.Generator, r_min=R_MIN, r_max=None, scale=RASTER_SCALE):
        y0, x0, y1, x1 = box
        self.y0, self.x0, self.scale = float(y0), float(x0), int(scale)
        h = max(1, int(np.ceil((y1 - y0) * scale)))
        w = max(1, int(np.ceil((x1 - x0) * scale)))
        r_max = max(float(r_max if r_max is not None else min(y1 - y0, x1 - x0) / 4), 2 * r_min)
        # E[r^2] for p(r) ~ r^-3 on [r_min, r_max] is c ln(r_max / r_min), c = 2 / (r_min^-2 - r_max^-2).
        c = 2.0 / (r_min**-2 - r_max**-2)
        mean_area = np.pi * c * np.log(r_max / r_min)
        area = (y1 - y0 + 2 * r_max) * (x1 - x0 + 2 * r_max)
        n = int(np.ceil(COVERAGE * area / mean_area))
        radii = _power_law_radii(rng, n, r_min, r_max)
        cy = rng.uniform(y0 - r_max, y1 + r_max, n)
        cx = rng.uniform(x0 - r_max, x1 + r_max, n)
        colours = _srgb_to_linear(rng.uniform(0.04, 0.96, (n, 3)))
        self.colours = np.vstack([colours, [[0.2, 0.2, 0.2]]]).astype(np.float32)
        index = np.full((h, w), n, dtype=np.int32)  # n: "no disc" (mid grey)
        # Raster pixel centres in frame coordinates: y0 + (i + 0.5) / scale.
        py = (cy - y0) * scale - 0.5
        px = (cx - x0) * scale - 0.5
        pr = radii * scale
        i0 = np.clip(np.ceil(py - pr), 0, h).astype(np.int64)
        i1 = np.clip(np.floor(py + pr) + 1, 0, h).astype(np.int64)
        j0 = np.clip(np.ceil(px - pr), 0, w).astype(np.int64)
        j1 = np.clip(np.floor(px + pr) + 1, 0, w).astype(np.int64)
        visible = np.nonzero((i1 > i0) & (j1 > j0))[0]
        # Painter's algorithm: disc k is dropped after disc k-1 and lies on top of it.
        for k in visible:
            ii = np.arange(i0[k], i1[k]) - py[k]
            jj = np.arange(j0[k], j1[k]) - px[k]
            inside = ii[:, None] ** 2 + jj[None, :] ** 2 < pr[k] ** 2
            index[i0[k]:i1[k], j0[k]:j1[k]][inside] = k
        self.index = index
        self.discs = n

    def __call__(self, x, y):
        h, w = self.index.shape
        i = np.clip(((y - self.y0) * self.scale).astype(np.int64), 0, h - 1)
        j = np.clip(((x - self.x0) * self.scale).astype(np.int64), 0, w - 1)
        return self.colours[self.index[i, j]]


def _texture_box(rect, disparity, S, T, U=9, V=9):
    """The frame box a plane's texture must cover: its support (or the frame) plus the parallax margin."""
    margin = abs(disparity) * (max(U, V) - 1) / 2.0 + 1.0
    y0, x0, y1, x1 = rect if rect is not None else (0.0, 0.0, float(S), float(T))
    return (y0 - margin, x0 - margin, y1 + margin, x1 + margin)


PLANES = (
    # name, disparity, rect as fractions (y0, x0, y1, x1) or None, shape
    ("front disc", 0.35, (0.08, 0.06, 0.44, 0.42), "disc"),
    ("focus square", 0.0, (0.22, 0.22, 0.78, 0.78), "rect"),
    ("back strip", -0.15, (0.05, 0.70, 0.95, 0.92), "rect"),
    ("background", -0.30, None, "rect"),
)


def deadleaves_planes(lenses, seed: int = 0, pitch=(9, 9)) -> list[Plane]:
    """The dead-leaves scene for ``lenses = (S, T)``, front to back; deterministic in ``seed``."""
    S, T = lenses
    streams = np.random.SeedSequence([int(seed), 0xDEAD1EAF]).spawn(len(PLANES))
    planes = []
    for (name, disparity, frac, shape), stream in zip(PLANES, streams):
        rect = None if frac is None else (frac[0] * S, frac[1] * T, frac[2] * S, frac[3] * T)
        box = _texture_box(rect, disparity, S, T, *pitch)
        size = min(S, T) if rect is None else min(rect[2] - rect[0], rect[3] - rect[1])
        texture = DeadLeavesTexture(box, np.random.default_rng(stream), r_max=size / 4.0)
        planes.append(Plane(name, disparity, texture, rect, shape))
    return planes

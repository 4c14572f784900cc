"""Procedural training scenes for fitted demosaics (linear4d), disjoint from the evaluation scenes.

The built-in ``charts`` and ``deadleaves`` scenes are what methods are *scored* on,
so nothing fitted may see them. These scenes are drawn from other families, with a
fixed seed each (:func:`training_planes`):

* a full-frame background plane and 1-4 foreground planes (rectangles or discs
  covering 15-60 % of the frame side), front to back in random order;
* disparities uniform in [-0.45, 0.45] lenses per view step (the evaluation
  scenes use -0.3 .. +0.35), a quarter of the planes exactly in focus (0);
* every plane shows one texture: ``mondrian`` (random rotated rectangles,
  ellipses and triangles with sizes log-uniform from 0.3 lens to half the frame),
  ``grating`` (1-3 sine or square gratings, 0.03-0.8 cycles per lens, random
  orientation, grey or coloured), ``noise`` (1/f^a coloured noise, a in 1..2.5),
  ``lines`` (straight edges and thin lines, 0.1-1.5 lenses wide), or ``smooth``
  (a quadratic colour ramp);
* colours uniform in sRGB code values [0.03, 0.97] decoded to linear, a third of
  them grey (R = G = B), so grey edges (false colour) are represented.

Raster textures are drawn at ``RASTER_SCALE`` pixels per lens over the plane's box
plus its parallax margin and sampled at the nearest raster pixel (the renderer's
3x3 sub-sampling box-filters each lens); gratings are analytic.
"""

from __future__ import annotations

import numpy as np

from lfcl.sim.planes import Plane

RASTER_SCALE = 8
KINDS = ("mondrian", "grating", "noise", "lines", "smooth")
KIND_WEIGHTS = (0.3, 0.2, 0.2, 0.2, 0.1)
MAX_DISPARITY = 0.45
SEED_TAG = 0x7A1E4D


def _colours(rng, n: int, grey_share: float = 1 / 3) -> np.ndarray:
    codes = rng.uniform(0.03, 0.97, (n, 3))
    grey = rng.random(n) < grey_share
    codes[grey] = codes[grey, :1]
    return np.where(codes <= 0.04045, codes / 12.92, ((codes + 0.055) / 1.055) ** 2.4)


class RasterTexture:
    """An ``(h, w, 3)`` raster over frame box ``(y0, x0, y1, x1)``, nearest-pixel lookup."""

    def __init__(self, image: np.ndarray, box, scale: int = RASTER_SCALE):
        self.image = np.ascontiguousarray(np.clip(image, 0.0, None), dtype=np.float32)
        self.y0, self.x0, self.scale = float(box[0]), float(box[1]), int(scale)

    def __call__(self, x, y):
        h, w = self.image.shape[:2]
        i = np.clip(((y - self.y0) * self.scale).astype(np.int64), 0, h - 1)
        j = np.clip(((x - self.x0) * self.scale).astype(np.int64), 0, w - 1)
        return self.image[i, j]


class GratingTexture:
    """A sum of sine or square gratings: ``base + sum_i a_i wave(2 pi f_i (k_i . p) + phi_i)``."""

    def __init__(self, rng):
        n = int(rng.integers(1, 4))
        self.base = _colours(rng, 1)[0] * 0.5 + 0.1
        self.freq = np.exp(rng.uniform(np.log(0.03), np.log(0.8), n))
        angle = rng.uniform(0, np.pi, n)
        self.direction = np.stack([np.cos(angle), np.sin(angle)], axis=1)
        self.phase = rng.uniform(0, 2 * np.pi, n)
        self.square = rng.random(n) < 0.5
        amplitude = _colours(rng, n) * rng.uniform(0.3, 1.0, (n, 1))
        self.amplitude = amplitude / (2.0 * n)

    def __call__(self, x, y):
        out = np.broadcast_to(self.base, (x.size, 3)).astype(np.float64)
        for f, (dx, dy), phi, square, a in zip(self.freq, self.direction, self.phase, self.square, self.amplitude):
            wave = np.sin(2 * np.pi * f * (dx * x + dy * y) + phi)
            if square:
                wave = np.sign(wave)
            out = out + wave[:, None] * a
        return np.clip(out, 0.0, None).astype(np.float32)


def _grid(h: int, w: int):
    """Raster pixel centres in lenses relative to the raster's corner."""
    return (np.arange(h)[:, None] + 0.5) / RASTER_SCALE, (np.arange(w)[None, :] + 0.5) / RASTER_SCALE


def _mondrian(rng, h: int, w: int) -> np.ndarray:
    side = max(h, w) / RASTER_SCALE
    image = np.empty((h, w, 3))
    image[:] = _colours(rng, 1)[0]
    n = int(rng.integers(40, 200))
    colours = _colours(rng, n)
    sizes = np.exp(rng.uniform(np.log(0.3), np.log(side / 2), (n, 2)))
    centres = rng.uniform(0, 1, (n, 2)) * [h / RASTER_SCALE, w / RASTER_SCALE]
    angles = rng.uniform(0, np.pi, n)
    shapes = rng.integers(0, 3, n)  # 0 rectangle, 1 ellipse, 2 triangle
    for k in range(n):
        radius = float(np.hypot(*sizes[k])) / 2
        i0, i1 = (int(np.clip((centres[k, 0] + d * radius) * RASTER_SCALE, 0, h)) for d in (-1, 1))
        j0, j1 = (int(np.clip((centres[k, 1] + d * radius) * RASTER_SCALE, 0, w)) for d in (-1, 1))
        if i1 <= i0 or j1 <= j0:
            continue
        yy = (np.arange(i0, i1)[:, None] + 0.5) / RASTER_SCALE - centres[k, 0]
        xx = (np.arange(j0, j1)[None, :] + 0.5) / RASTER_SCALE - centres[k, 1]
        c, s = np.cos(angles[k]), np.sin(angles[k])
        a = (c * yy + s * xx) / (sizes[k, 0] / 2)
        b = (-s * yy + c * xx) / (sizes[k, 1] / 2)
        if shapes[k] == 0:
            inside = (np.abs(a) < 1) & (np.abs(b) < 1)
        elif shapes[k] == 1:
            inside = a**2 + b**2 < 1
        else:
            inside = (a > -1) & (np.abs(b) < (1 - a) / 2)
        image[i0:i1, j0:j1][inside] = colours[k]
    return image


def _noise(rng, h: int, w: int) -> np.ndarray:
    exponent = rng.uniform(1.0, 2.5)
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    radius = np.maximum(np.hypot(fy, fx), 1.0 / max(h, w))
    fields = []
    for _ in range(3):
        spectrum = (rng.normal(size=radius.shape) + 1j * rng.normal(size=radius.shape)) * radius ** (-exponent / 1.0)
        field = np.fft.irfft2(spectrum, s=(h, w))
        fields.append(field / (field.std() + 1e-12))
    luminance, chroma = fields[0], np.stack(fields[1:], axis=-1)
    base = _colours(rng, 1, grey_share=0.5)[0] * 0.6 + 0.1
    contrast = rng.uniform(0.1, 0.5)
    colour_amount = rng.choice([0.0, rng.uniform(0.05, 0.4)])
    image = base * (1 + contrast * luminance[..., None])
    image[..., 0] *= 1 + colour_amount * contrast * chroma[..., 0]
    image[..., 2] *= 1 + colour_amount * contrast * chroma[..., 1]
    return image


def _lines(rng, h: int, w: int) -> np.ndarray:
    yy, xx = _grid(h, w)
    image = np.empty((h, w, 3))
    image[:] = _colours(rng, 1)[0]
    n = int(rng.integers(5, 40))
    colours = _colours(rng, n, grey_share=0.5)
    for k in range(n):
        angle = rng.uniform(0, np.pi)
        point = rng.uniform(0, 1, 2) * [h / RASTER_SCALE, w / RASTER_SCALE]
        distance = np.cos(angle) * (yy - point[0]) + np.sin(angle) * (xx - point[1])
        if rng.random() < 0.3:
            inside = distance > 0  # a half-plane: a long straight edge
        else:
            inside = np.abs(distance) < rng.uniform(0.05, 0.75)
        image[inside] = colours[k]
    return image


def _smooth(rng, h: int, w: int) -> np.ndarray:
    yy, xx = _grid(h, w)
    yy, xx = yy / (h / RASTER_SCALE), xx / (w / RASTER_SCALE)
    corners = _colours(rng, 4)
    image = ((1 - yy)[..., None] * (1 - xx)[..., None] * corners[0] + (1 - yy)[..., None] * xx[..., None] * corners[1]
             + yy[..., None] * (1 - xx)[..., None] * corners[2] + yy[..., None] * xx[..., None] * corners[3])
    return image * (1 + 0.3 * np.sin(2 * np.pi * rng.uniform(0.01, 0.1) * (yy + xx) * h / RASTER_SCALE))[..., None]


RASTERS = {"mondrian": _mondrian, "noise": _noise, "lines": _lines, "smooth": _smooth}


def _texture(rng, kind: str, box):
    y0, x0, y1, x1 = box
    if kind == "grating":
        return GratingTexture(rng)
    h = max(1, int(np.ceil((y1 - y0) * RASTER_SCALE)))
    w = max(1, int(np.ceil((x1 - x0) * RASTER_SCALE)))
    return RasterTexture(RASTERS[kind](rng, h, w), box)


def training_planes(lenses, seed: int, pitch=(9, 9)) -> list[Plane]:
    """A random scene of 2-5 planes (front to back) for ``lenses = (S, T)``; deterministic in ``seed``."""
    S, T = (int(n) for n in lenses)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), SEED_TAG]))
    margin = MAX_DISPARITY * (max(pitch) - 1) / 2.0 + 1.0
    n_front = int(rng.integers(1, 5))
    planes = []
    for i in range(n_front + 1):
        background = i == n_front
        disparity = 0.0 if rng.random() < 0.25 else float(rng.uniform(-MAX_DISPARITY, MAX_DISPARITY))
        if background:
            rect, shape = None, "rect"
            box = (-margin, -margin, S + margin, T + margin)
        else:
            height, width = rng.uniform(0.15, 0.6, 2) * [S, T]
            y0, x0 = rng.uniform(0, 1, 2) * [S - height, T - width]
            rect, shape = (y0, x0, y0 + height, x0 + width), ("rect", "disc")[int(rng.integers(0, 2))]
            box = (y0 - margin, x0 - margin, y0 + height + margin, x0 + width + margin)
        kind = str(rng.choice(KINDS, p=KIND_WEIGHTS))
        name = f"{'background' if background else f'plane {i}'} ({kind})"
        planes.append(Plane(name, disparity, _texture(rng, kind, box), rect, shape))
    return planes

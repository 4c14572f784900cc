"""The ``finetexture`` scene: lens-scale detail on planes off the focal plane.

A stress scene for demosaicing and light-field priors: every plane carries
detail at or below the scale of one lens (one pixel of a view image), and no
plane is in focus, so the views disagree by 0.2 to 1.5 lenses per view step.
Everything is procedural in continuous frame coordinates (lenses, see
:mod:`lfcl.sim.planes`), defined everywhere (any parallax margin), and
*pre-filtered* with a box of ``PREFILTER`` = 1/3 lens, the spacing of the
renderer's default 3x3 sub-samples, so that detail finer than the sub-sample
spacing averages to its mean instead of aliasing; the renderer's sub-sampling
then box-filters each lens footprint. Planes, front to back:

* ``star disc``: a two-colour Siemens star filling a disc of 0.42 of the
  frame's smaller side; at least 12 spokes, their period at the rim 2.5 to 5
  lenses, narrowing to a fraction of a lens towards the centre (where the
  pre-filter averages them to the mean of the two colours);
* three cards (rectangles, 0.35 to 0.65 of the frame, laid out so that each is
  partly hidden by a nearer one; which card goes where is drawn per seed):

  - ``text card``: lines of random text in a built-in 5x7 bitmap font
    (:data:`FONT`), glyphs 0.35 to 0.75 lens per font pixel (2.5 to 5 lenses
    tall, strokes a fraction of a lens), ink neutral or saturated on light or
    dark paper;
  - ``lines card``: ten straight lines through random points at random angles, widths from 1 lens
    down to 0.12 lens, neutral and saturated, on a light or dark ground;
  - ``grain card``: high-contrast random grain, one value per cell of 0.8 to
    1.25 lens on a randomly rotated and shifted grid, saturated colours
    (:data:`COLOURS`);
* ``background`` (full frame): the same kind of grain, 85 % of the cells
  grey (:data:`GREYS`, 0.02 to 0.95), the rest coloured.

Disparities: five values drawn per seed with ``|d|`` uniform in
``[MIN_DISPARITY, MAX_DISPARITY]`` = [0.2, 1.5] lenses per view step and a
random sign, redrawn until both signs occur and neighbouring values are at
least 0.15 apart, then sorted so that nearer planes (larger ``d``) occlude
farther ones. Colours are linear values in 0.02..0.95. Every texture, layout
and disparity comes from one random stream derived from ``seed``: any seed
gives a valid, deterministic scene, and different seeds differ.
"""

from __future__ import annotations

import numpy as np

from .planes import Plane

PREFILTER = 1.0 / 3.0  # lenses: the box every texture is pre-filtered with (the default sub-sample spacing)
MIN_DISPARITY, MAX_DISPARITY, MIN_GAP = 0.2, 1.5, 0.15
SEED_TAG = 0xF1E7E7
GLYPH_ROWS, GLYPH_COLS, ADVANCE, LEADING = 7, 5, 6, 9.5  # font pixels; advance and leading include the gaps

GREYS = np.array([0.02, 0.06, 0.18, 0.45, 0.75, 0.95], dtype=np.float32)
COLOURS = np.array([
    (0.80, 0.04, 0.03), (0.05, 0.60, 0.08), (0.04, 0.08, 0.80), (0.90, 0.80, 0.04),
    (0.04, 0.70, 0.85), (0.75, 0.05, 0.70), (0.90, 0.35, 0.02), (0.25, 0.04, 0.55),
    (0.30, 0.02, 0.02), (0.02, 0.25, 0.05), (0.50, 0.90, 0.30), (0.60, 0.70, 0.95),
], dtype=np.float32)
INKS = np.array([(0.02, 0.02, 0.02), (0.80, 0.04, 0.03), (0.04, 0.08, 0.80), (0.05, 0.45, 0.06),
                 (0.55, 0.04, 0.50)], dtype=np.float32)
LIGHT_INKS = np.array([(0.95, 0.95, 0.95), (0.90, 0.80, 0.04), (0.04, 0.70, 0.85), (0.90, 0.35, 0.02)],
                      dtype=np.float32)
PAPER_LIGHT, PAPER_DARK = 0.85, 0.03
STAR_PAIRS = np.array([
    [(0.02, 0.02, 0.02), (0.92, 0.92, 0.92)], [(0.80, 0.04, 0.03), (0.04, 0.70, 0.85)],
    [(0.04, 0.08, 0.80), (0.90, 0.80, 0.04)], [(0.05, 0.60, 0.08), (0.75, 0.05, 0.70)],
], dtype=np.float32)

# A 5x7 bitmap font: 7 rows of 5 font pixels ('#' = ink), top row first.
FONT = {
    "A": ".###. #...# #...# ##### #...# #...# #...#", "B": "####. #...# #...# ####. #...# #...# ####.",
    "C": ".###. #...# #.... #.... #.... #...# .###.", "D": "###.. #..#. #...# #...# #...# #..#. ###..",
    "E": "##### #.... #.... ####. #.... #.... #####", "F": "##### #.... #.... ####. #.... #.... #....",
    "G": ".###. #...# #.... #.### #...# #...# .####", "H": "#...# #...# #...# ##### #...# #...# #...#",
    "I": ".###. ..#.. ..#.. ..#.. ..#.. ..#.. .###.", "J": "..### ...#. ...#. ...#. ...#. #..#. .##..",
    "K": "#...# #..#. #.#.. ##... #.#.. #..#. #...#", "L": "#.... #.... #.... #.... #.... #.... #####",
    "M": "#...# ##.## #.#.# #.#.# #...# #...# #...#", "N": "#...# #...# ##..# #.#.# #..## #...# #...#",
    "O": ".###. #...# #...# #...# #...# #...# .###.", "P": "####. #...# #...# ####. #.... #.... #....",
    "Q": ".###. #...# #...# #...# #.#.# #..#. .##.#", "R": "####. #...# #...# ####. #.#.. #..#. #...#",
    "S": ".#### #.... #.... .###. ....# ....# ####.", "T": "##### ..#.. ..#.. ..#.. ..#.. ..#.. ..#..",
    "U": "#...# #...# #...# #...# #...# #...# .###.", "V": "#...# #...# #...# #...# #...# .#.#. ..#..",
    "W": "#...# #...# #...# #.#.# #.#.# #.#.# .#.#.", "X": "#...# #...# .#.#. ..#.. .#.#. #...# #...#",
    "Y": "#...# #...# #...# .#.#. ..#.. ..#.. ..#..", "Z": "##### ....# ...#. ..#.. .#... #.... #####",
    "0": ".###. #...# #..## #.#.# ##..# #...# .###.", "1": "..#.. .##.. ..#.. ..#.. ..#.. ..#.. .###.",
    "2": ".###. #...# ....# ...#. ..#.. .#... #####", "3": "##### ...#. ..#.. ...#. ....# #...# .###.",
    "4": "...#. ..##. .#.#. #..#. ##### ...#. ...#.", "5": "##### #.... ####. ....# ....# #...# .###.",
    "6": "..##. .#... #.... ####. #...# #...# .###.", "7": "##### ....# ...#. ..#.. .#... .#... .#...",
    "8": ".###. #...# #...# .###. #...# #...# .###.", "9": ".###. #...# #...# .#### ....# ...#. .##..",
    " ": "..... ..... ..... ..... ..... ..... .....",
}
GLYPHS = "".join(FONT)
GLYPH_BITS = np.array([[[c == "#" for c in row] for row in FONT[g].split()] for g in GLYPHS], dtype=bool)


def glyph_codes(text: str) -> np.ndarray:
    """Indices into :data:`GLYPH_BITS` of ``text`` (upper-cased); ``ValueError`` for a character the font lacks."""
    missing = sorted(set(text.upper()) - set(GLYPHS))
    if missing:
        raise ValueError(f"the built-in font has no glyph for {''.join(missing)!r}")
    return np.array([GLYPHS.index(c) for c in text.upper()], dtype=np.int64)


# --------------------------------------------------------------------------- pre-filtering helpers

def _box_cells(gx, gy, width, lookup):
    """``lookup`` over unit cells, box-filtered with a square of side ``width`` (< 1, cell units) at ``(gx, gy)``.

    At most 2x2 cells meet the box; each contributes its overlap fraction.
    ``lookup(ix, iy) -> (N, 3)`` gives the value of the cells ``(ix, iy)``.
    """
    lo_x, lo_y = gx - width / 2, gy - width / 2
    ix, iy = np.floor(lo_x).astype(np.int64), np.floor(lo_y).astype(np.int64)
    wx = (np.minimum(ix + 1 - lo_x, width) / width)[:, None]  # share of cell column ix
    wy = (np.minimum(iy + 1 - lo_y, width) / width)[:, None]
    return (wy * (wx * lookup(ix, iy) + (1 - wx) * lookup(ix + 1, iy))
            + (1 - wy) * (wx * lookup(ix, iy + 1) + (1 - wx) * lookup(ix + 1, iy + 1)))


def _box_square_wave(a, period, width):
    """A 0/1 square wave (1 on the first half of each ``period``) box-filtered over ``width`` at ``a``."""
    def integral(s):
        return np.floor(s / period) * (period / 2) + np.minimum(np.mod(s, period), period / 2)
    return (integral(a + width / 2) - integral(a - width / 2)) / width


def _box_band(distance, band, width):
    """Coverage of a band ``|distance| < band / 2`` box-filtered over ``width``."""
    overlap = np.minimum(distance + width / 2, band / 2) - np.maximum(distance - width / 2, -band / 2)
    return np.clip(overlap / width, 0.0, 1.0)


def _hash(ix, iy, key: int) -> np.ndarray:
    """A 64-bit hash (splitmix64 finaliser) of integer cell coordinates and ``key``, as uint64."""
    with np.errstate(over="ignore"):
        z = ix.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        z ^= iy.astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
        z ^= np.uint64(key)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


# --------------------------------------------------------------------------- textures

class GrainTexture:
    """Random grain: one colour per cell of a rotated, shifted grid with cells of ``cell`` lenses.

    A cell is grey (one of :data:`GREYS`) with probability ``grey_share``, else
    one of :data:`COLOURS`; the cell values come from a hash of the cell index
    and ``key``, so the texture is defined over the whole plane.
    """

    def __init__(self, key: int, cell: float, angle: float, origin, grey_share: float):
        self.key, self.cell, self.grey_share = int(key), float(cell), float(grey_share)
        self.cos, self.sin = np.cos(angle), np.sin(angle)
        self.oy, self.ox = (float(o) for o in origin)

    def _cells(self, ix, iy):
        h = _hash(ix, iy, self.key)
        grey = (h & np.uint64(0xFFFF)).astype(np.float64) / 65536.0 < self.grey_share
        pick = (h >> np.uint64(16)).astype(np.float64)
        out = COLOURS[(pick % len(COLOURS)).astype(np.int64)]
        out[grey] = GREYS[(pick[grey] % len(GREYS)).astype(np.int64)][:, None]
        return out

    def __call__(self, x, y):
        dx, dy = x - self.ox, y - self.oy
        gx = (self.cos * dx + self.sin * dy) / self.cell
        gy = (-self.sin * dx + self.cos * dy) / self.cell
        return _box_cells(gx, gy, PREFILTER / self.cell, self._cells).astype(np.float32)


class StarTexture:
    """A two-colour Siemens star of ``spokes`` spokes about ``(cy, cx)``, filtered along the arc."""

    def __init__(self, cy, cx, spokes: int, colours):
        self.cy, self.cx, self.spokes = float(cy), float(cx), int(spokes)
        self.colours = np.asarray(colours, dtype=np.float32)

    def __call__(self, x, y):
        dy, dx = y - self.cy, x - self.cx
        r = np.hypot(dy, dx)
        # Arc length r * theta; one period of the wave is 2 pi r / spokes (the seam at theta = pi is
        # a whole number of periods, so the wave is continuous across it).
        period = np.maximum(2 * np.pi * r / self.spokes, 1e-9)
        share = _box_square_wave(r * np.arctan2(dy, dx), period, PREFILTER)
        share = np.where(r < PREFILTER / 2, 0.5, share)[:, None]
        return (self.colours[0] + share * (self.colours[1] - self.colours[0])).astype(np.float32)


class LinesTexture:
    """Straight lines ``(y, x, angle, width, colour)`` over a uniform ``ground``; later lines on top."""

    def __init__(self, ground, lines):
        self.ground = np.asarray(ground, dtype=np.float32)
        self.lines = [(float(y), float(x), float(a), float(w), np.asarray(c, np.float32)) for y, x, a, w, c in lines]

    def __call__(self, x, y):
        out = np.broadcast_to(self.ground, (x.size, 3)).astype(np.float64)
        for y0, x0, angle, width, colour in self.lines:
            distance = np.abs(-np.sin(angle) * (x - x0) + np.cos(angle) * (y - y0))
            share = _box_band(distance, width, PREFILTER)[:, None]
            out += share * (colour - out)
        return out.astype(np.float32)


class TextTexture:
    """Lines of bitmap text ``(top, left, pixel, text, ink)`` on ``paper``; ``pixel``: lenses per font pixel."""

    def __init__(self, paper, lines):
        self.paper = np.asarray(paper, dtype=np.float32)
        self.lines = [(float(t), float(left), float(p), glyph_codes(s), np.asarray(ink, np.float32))
                      for t, left, p, s, ink in lines]

    @staticmethod
    def _ink(codes):
        def lookup(ix, iy):
            char, col = np.divmod(ix, ADVANCE)
            inside = (iy >= 0) & (iy < GLYPH_ROWS) & (col < GLYPH_COLS) & (char >= 0) & (char < len(codes))
            bits = GLYPH_BITS[codes[np.clip(char, 0, len(codes) - 1)], np.clip(iy, 0, GLYPH_ROWS - 1),
                              np.clip(col, 0, GLYPH_COLS - 1)]
            return np.repeat((inside & bits).astype(np.float64)[:, None], 3, axis=1)
        return lookup

    def __call__(self, x, y):
        out = np.broadcast_to(self.paper, (x.size, 3)).astype(np.float64)
        for top, left, pixel, codes, ink in self.lines:
            near = (y > top - pixel) & (y < top + (GLYPH_ROWS + 1) * pixel)
            if not near.any():
                continue
            share = _box_cells((x[near] - left) / pixel, (y[near] - top) / pixel, PREFILTER / pixel,
                               self._ink(codes))
            out[near] += share * (ink - out[near])
        return out.astype(np.float32)


# --------------------------------------------------------------------------- the scene

CARD_RECTS = (  # fractions (y0, x0, y1, x1) of the frame, before jitter and flips; front to back
    (0.30, 0.32, 0.68, 0.96),
    (0.56, 0.04, 0.96, 0.56),
    (0.04, 0.56, 0.50, 0.96),
)
STAR_CENTRE, STAR_DIAMETER = (0.27, 0.27), 0.42  # fractions of the frame; the diameter of min(S, T)
JITTER = 0.03


def draw_disparities(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` disparities, descending: ``|d|`` in [0.2, 1.5], both signs, neighbours at least 0.15 apart."""
    for _ in range(10_000):
        d = np.sort(rng.uniform(MIN_DISPARITY, MAX_DISPARITY, n) * rng.choice([-1.0, 1.0], n))[::-1]
        if d[0] > 0 > d[-1] and (n < 2 or np.min(-np.diff(d)) >= MIN_GAP):
            return d
    raise RuntimeError("could not draw disparities")  # pragma: no cover - acceptance is about 1 in 4


def _grain(rng, grey_share: float) -> GrainTexture:
    return GrainTexture(int(rng.integers(0, 2**63)), rng.uniform(0.8, 1.25), rng.uniform(0, np.pi / 2),
                        rng.uniform(0, 1, 2), grey_share)


def _star(rng, rect) -> StarTexture:
    y0, x0, y1, x1 = rect
    pair = STAR_PAIRS[int(rng.integers(len(STAR_PAIRS)))]
    # Spoke period at the rim 2.5 to 5 lenses (resolvable), shrinking below a lens towards the centre.
    radius = min(y1 - y0, x1 - x0) / 2
    spokes = max(12, 2 * round(np.pi * radius / rng.uniform(2.5, 5.0)))
    return StarTexture((y0 + y1) / 2, (x0 + x1) / 2, spokes, pair[::rng.choice([1, -1])])


def _lines(rng, rect) -> LinesTexture:
    y0, x0, y1, x1 = rect
    dark = rng.random() < 0.4
    ground = np.full(3, PAPER_DARK if dark else PAPER_LIGHT)
    widths = np.geomspace(1.0, 0.12, 10)
    rng.shuffle(widths)
    inks = LIGHT_INKS if dark else INKS
    lines = [(rng.uniform(y0, y1), rng.uniform(x0, x1), rng.uniform(0, np.pi), w, inks[int(rng.integers(len(inks)))])
             for w in widths]
    return LinesTexture(ground, lines)


def _text(rng, rect) -> TextTexture:
    y0, x0, y1, x1 = rect
    dark = rng.random() < 0.35
    inks = LIGHT_INKS if dark else INKS
    lines, top = [], y0 + 0.5
    while True:
        pixel = rng.uniform(0.35, 0.75)
        if top + GLYPH_ROWS * pixel > y1:
            break
        count = int(np.ceil((x1 - x0) / (ADVANCE * pixel))) + 1
        chars = rng.choice(list(GLYPHS.strip()), count)
        chars[rng.random(count) < 0.15] = " "  # word gaps
        lines.append((top, x0 + rng.uniform(0.2, 1.0), pixel, "".join(chars), inks[int(rng.integers(len(inks)))]))
        top += LEADING * pixel
    return TextTexture(np.full(3, PAPER_DARK if dark else PAPER_LIGHT), lines)


def finetexture_planes(lenses, seed: int = 0, pitch=(9, 9)) -> list[Plane]:
    """The fine-texture scene for ``lenses = (S, T)``, front to back; deterministic in ``seed`` (``pitch`` unused)."""
    S, T = (float(n) for n in lenses)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), SEED_TAG]))
    disparities = draw_disparities(rng, 5)
    flip_y, flip_x = rng.random(2) < 0.5

    def place(fy0, fx0, fy1, fx1):
        jy, jx = rng.uniform(-JITTER, JITTER, 2)
        fy0, fy1 = (1 - fy1, 1 - fy0) if flip_y else (fy0, fy1)
        fx0, fx1 = (1 - fx1, 1 - fx0) if flip_x else (fx0, fx1)
        return ((fy0 + jy) * S, (fx0 + jx) * T, (fy1 + jy) * S, (fx1 + jx) * T)

    cy, cx = STAR_CENTRE
    half_y, half_x = STAR_DIAMETER * min(S, T) / (2 * S), STAR_DIAMETER * min(S, T) / (2 * T)
    star_rect = place(cy - half_y, cx - half_x, cy + half_y, cx + half_x)
    planes = [Plane("star disc", disparities[0], _star(rng, star_rect), star_rect, "disc")]
    kinds = [("text card", _text), ("lines card", _lines), ("grain card", lambda r, _: _grain(r, 0.0))]
    for i, frac in zip(rng.permutation(3), CARD_RECTS):
        rect = place(*frac)
        name, make = kinds[i]
        planes.append(Plane(name, disparities[len(planes)], make(rng, rect), rect))
    planes.append(Plane("background", disparities[4], _grain(rng, 0.85)))
    return planes

"""The ``charts`` scene: three planar resolution charts at different depths.

After the paper's second scene (section 2.2: "three planar resolution charts at
varying distances", 0.5 to 1.5 m). Everything is procedural and defined in
continuous frame coordinates (lenses, see :mod:`lfcl.sim.planes`), so the
renderer's sub-sampling integrates the true pattern. Front to back:

* ``star chart`` (0.6 m, disparity +1/3 lens per view step), upper left:
  a 36-spoke binary Siemens star and a 6x4 ColorChecker patch grid.
* ``bar chart`` (1.0 m, disparity 0: the plane in focus), lower middle: six
  groups of vertical bars and six of horizontal bars with periods from about a
  sixth of the group width down to 1 lens (the views' Nyquist period is 2
  lenses), and two 5-degree slanted edges (ISO 12233 style, 4:1 contrast).
  The star chart hides part of it.
* ``zone chart`` (1.4 m, disparity -1/7), upper right: a circular zone plate
  whose local frequency rises linearly to 0.6 cycles per lens at its rim, a
  six-step grey wedge and red/green/blue stripes. The bar chart hides part of it.
* ``wall`` (2.0 m, disparity -1/4): a dim, slightly warm checkerboard filling
  the frame.

Disparities follow ``d = 0.5 * (1/z - 1/z_focus)`` lenses per view step with
``z_focus = 1 m``. Reflectances: paper 0.80, ink 0.04, ColorChecker values as
linear sRGB (D65). The scene does not depend on the seed. Charts are laid out
in fractions of the frame, so they scale with the lens count.
"""

from __future__ import annotations

import numpy as np

from .planes import Plane

PAPER = 0.80
INK = 0.04
Z_FOCUS_M = 1.0
DISPARITY_SCALE = 0.5  # lenses per view step per (1/m)

# ColorChecker 24 (X-Rite, after November 2014), linear sRGB / D65 (Bradford from D50),
# computed with colour-science from CCS_COLOURCHECKERS; row-major from "dark skin".
COLORCHECKER = np.array([
    (0.1737, 0.0788, 0.0529), (0.5598, 0.2774, 0.2109), (0.1042, 0.1889, 0.3289),
    (0.1057, 0.1508, 0.0508), (0.2274, 0.2124, 0.4264), (0.1153, 0.5074, 0.4111),
    (0.7459, 0.2021, 0.0299), (0.0587, 0.1012, 0.3877), (0.5601, 0.0802, 0.1146),
    (0.1092, 0.0420, 0.1381), (0.3328, 0.4974, 0.0426), (0.7710, 0.3579, 0.0204),
    (0.0210, 0.0475, 0.2841), (0.0461, 0.2920, 0.0615), (0.4462, 0.0364, 0.0406),
    (0.8417, 0.5744, 0.0047), (0.5223, 0.0778, 0.2893), (0.0000, 0.2337, 0.3772),
    (0.8795, 0.8850, 0.8342), (0.5845, 0.5922, 0.5845), (0.3577, 0.3671, 0.3653),
    (0.1901, 0.1909, 0.1898), (0.0859, 0.0887, 0.0898), (0.0314, 0.0315, 0.0323),
], dtype=np.float32)


def disparity_at(depth_m: float) -> float:
    """Disparity (lenses per view step) of a plane at ``depth_m`` metres."""
    return DISPARITY_SCALE * (1.0 / depth_m - 1.0 / Z_FOCUS_M)


def _grey(values: np.ndarray) -> np.ndarray:
    return np.repeat(np.asarray(values, dtype=np.float32)[:, None], 3, axis=1)


# Elements: f(x, y) -> (N, 3) on points inside their box (frame coordinates).

def siemens_star(cy, cx, radius, spokes=36):
    def f(x, y):
        theta = np.arctan2(y - cy, x - cx)
        r2 = (x - cx) ** 2 + (y - cy) ** 2
        value = np.where(np.sin(spokes / 2 * theta) >= 0, PAPER, INK)
        return _grey(np.where(r2 < radius**2, value, PAPER))
    return f


def bar_groups(y0, x0, y1, x1, vertical: bool, groups=6):
    """``groups`` side-by-side bar groups; periods geometric from ~width/6 down to 1 lens."""
    width = (x1 - x0) / groups
    periods = np.geomspace(max(width / 3.0, 1.0), 1.0, groups)

    def f(x, y):
        k = np.clip(((x - x0) / width).astype(np.int64), 0, groups - 1)
        left = x0 + k * width
        inner = (x - left > 0.1 * width) & (x - left < 0.9 * width)
        coord = (x - left) if vertical else (y - y0)
        phase = np.mod(coord / periods[k], 1.0)
        return _grey(np.where(inner & (phase < 0.5), INK, PAPER))
    return f


def slanted_edge(cy, cx, angle_deg=5.0, dark=0.18, light=0.72):
    a = np.deg2rad(angle_deg)

    def f(x, y):
        side = (x - cx) * np.cos(a) + (y - cy) * np.sin(a)
        return _grey(np.where(side < 0, dark, light))
    return f


def zone_plate(cy, cx, radius, f_max=0.6):
    """Local frequency f_max * r / radius cycles per lens: phase = pi * f_max * r^2 / radius."""
    def f(x, y):
        r2 = (x - cx) ** 2 + (y - cy) ** 2
        value = 0.42 + 0.38 * np.cos(np.pi * f_max * r2 / radius)
        return _grey(np.where(r2 < radius**2, value, PAPER))
    return f


def patch_grid(y0, x0, y1, x1, colours, rows, cols, gap=0.12):
    colours = np.asarray(colours, dtype=np.float32)

    def f(x, y):
        fy = (y - y0) / (y1 - y0) * rows
        fx = (x - x0) / (x1 - x0) * cols
        iy = np.clip(fy.astype(np.int64), 0, rows - 1)
        ix = np.clip(fx.astype(np.int64), 0, cols - 1)
        inside = (np.mod(fy, 1.0) > gap / 2) & (np.mod(fy, 1.0) < 1 - gap / 2) & \
                 (np.mod(fx, 1.0) > gap / 2) & (np.mod(fx, 1.0) < 1 - gap / 2)
        out = colours[iy * cols + ix]
        out[~inside] = INK
        return out
    return f


class ChartTexture:
    """Paper with elements in boxes (frame coordinates); later elements win on overlap."""

    def __init__(self, elements):
        self.elements = elements  # [((y0, x0, y1, x1), f)]

    def __call__(self, x, y):
        out = np.full((x.size, 3), PAPER, dtype=np.float32)
        for (y0, x0, y1, x1), f in self.elements:
            m = (y >= y0) & (y < y1) & (x >= x0) & (x < x1)
            if m.any():
                out[m] = f(x[m], y[m])
        return out


def _box(rect, fy0, fx0, fy1, fx1):
    """A box given in fractions of ``rect`` (y0, x0, y1, x1)."""
    y0, x0, y1, x1 = rect
    h, w = y1 - y0, x1 - x0
    return (y0 + fy0 * h, x0 + fx0 * w, y0 + fy1 * h, x0 + fx1 * w)


def _frac_rect(S, T, fy0, fx0, fy1, fx1):
    return (fy0 * S, fx0 * T, fy1 * S, fx1 * T)


def wall_texture(S, T):
    period = max(4.0, min(S, T) / 8.0)
    dark = np.array([0.07, 0.065, 0.055], dtype=np.float32)
    light = np.array([0.16, 0.15, 0.13], dtype=np.float32)

    def f(x, y):
        check = (np.floor(x / period) + np.floor(y / period)) % 2 == 0
        return np.where(check[:, None], light, dark)
    return f


def star_chart(S, T) -> Plane:
    rect = _frac_rect(S, T, 0.06, 0.03, 0.62, 0.40)
    sy0, sx0, sy1, sx1 = _box(rect, 0.04, 0.05, 0.68, 0.95)
    radius = 0.48 * min(sy1 - sy0, sx1 - sx0)
    elements = [
        ((sy0, sx0, sy1, sx1), siemens_star((sy0 + sy1) / 2, (sx0 + sx1) / 2, radius)),
        (_box(rect, 0.72, 0.05, 0.96, 0.95), patch_grid(*_box(rect, 0.72, 0.05, 0.96, 0.95), COLORCHECKER, 4, 6)),
    ]
    return Plane("star chart", disparity_at(0.6), ChartTexture(elements), rect, depth_m=0.6)


def bar_chart(S, T) -> Plane:
    rect = _frac_rect(S, T, 0.30, 0.28, 0.96, 0.74)
    vbox = _box(rect, 0.05, 0.05, 0.40, 0.95)
    hbox = _box(rect, 0.45, 0.05, 0.68, 0.95)
    e1 = _box(rect, 0.74, 0.08, 0.95, 0.46)
    e2 = _box(rect, 0.74, 0.54, 0.95, 0.92)
    elements = [
        (vbox, bar_groups(*vbox, vertical=True)),
        (hbox, bar_groups(*hbox, vertical=False)),
        (e1, slanted_edge((e1[0] + e1[2]) / 2, (e1[1] + e1[3]) / 2, 5.0)),
        (e2, slanted_edge((e2[0] + e2[2]) / 2, (e2[1] + e2[3]) / 2, 95.0)),
    ]
    return Plane("bar chart", disparity_at(1.0), ChartTexture(elements), rect, depth_m=1.0)


def zone_chart(S, T) -> Plane:
    rect = _frac_rect(S, T, 0.04, 0.60, 0.58, 0.97)
    zy0, zx0, zy1, zx1 = _box(rect, 0.04, 0.05, 0.70, 0.95)
    radius = 0.48 * min(zy1 - zy0, zx1 - zx0)
    wedge = np.repeat(np.geomspace(0.8, 0.03, 6)[:, None], 3, axis=1)
    primaries = np.array([(0.6, 0.03, 0.03), (0.03, 0.6, 0.03), (0.03, 0.03, 0.6)])
    w_box = _box(rect, 0.74, 0.05, 0.84, 0.95)
    p_box = _box(rect, 0.86, 0.05, 0.96, 0.95)
    elements = [
        ((zy0, zx0, zy1, zx1), zone_plate((zy0 + zy1) / 2, (zx0 + zx1) / 2, radius)),
        (w_box, patch_grid(*w_box, wedge, 1, 6, gap=0.0)),
        (p_box, patch_grid(*p_box, primaries, 1, 3, gap=0.0)),
    ]
    return Plane("zone chart", disparity_at(1.4), ChartTexture(elements), rect, depth_m=1.4)


def charts_planes(lenses, seed: int = 0) -> list[Plane]:
    """The charts scene for ``lenses = (S, T)``, front to back (``seed`` is unused)."""
    S, T = lenses
    wall = Plane("wall", disparity_at(2.0), wall_texture(S, T), None, depth_m=2.0)
    return [star_chart(S, T), bar_chart(S, T), zone_chart(S, T), wall]

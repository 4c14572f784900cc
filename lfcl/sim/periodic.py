"""The ``periodic`` scene: repeating content, where a prior along the epipolar lines can follow a wrong line.

A stress scene for "never worse than Malvar" (an audit's cases, docs/auto.md "Periodic content"). Repeating
texture repeats its views too: a pattern of period ``P`` lenses looks the same in a view ``k`` steps from the centre
at disparities ``P / k`` apart, so the disparity that best explains the views can be a wrong one; and within a
micro-image a plane off the focal plane becomes a pattern of a few pixels' period, where filters learned on other
content break. Four rectangles tile the frame, each a fronto-parallel plane (frame coordinates in lenses,
:mod:`lfcl.sim.planes`):

* ``grating`` (top left): a grey sine grating of period 4 lenses at disparity +1, in the search range of
  :mod:`lfcl.depth`: along the columns it repeats every 4.3 lenses, so the views 4 steps out, shifted by 4
  lenses, see almost the same columns, and each micro-image holds a grating of about 4 pixels' period;
* ``far grating`` (top right): a grey sine grating of period 10 lenses at disparity -3, beyond that search range
  (+-2 lenses per view step);
* ``checker`` (bottom left): a grey checkerboard of 2-lens squares in focus (disparity 0), which every view an even
  number of steps out sees unchanged at disparities +-1 and +-2 too;
* ``primaries`` (bottom right): a checkerboard of 1-lens squares of pure red and pure blue in focus, whose lit
  channel clips first as the light rises.

The gratings run at an angle (``ANGLE`` from the column axis, so both view directions see their parallax); each
part's phase comes from ``seed``. Grey values lie in 0.05..0.95; the primaries are (0.95, 0, 0) and (0, 0, 0.95).
"""

from __future__ import annotations

import numpy as np

from .planes import Plane

#: The gratings' direction: this many radians from the frame's column (t) axis.
ANGLE = 0.35


class ColourGrating:
    """``first + (second - first) (0.5 + 0.5 sin(2 pi (x cos a + y sin a) / period + phase))``, linear RGB."""

    def __init__(self, period: float, phase: float, angle: float, first, second):
        self.period, self.phase, self.cos, self.sin = float(period), float(phase), np.cos(angle), np.sin(angle)
        self.first = np.asarray(first, np.float32)
        self.second = np.asarray(second, np.float32)

    def __call__(self, x, y):
        wave = 0.5 + 0.5 * np.sin(2 * np.pi * (x * self.cos + y * self.sin) / self.period + self.phase)
        return (self.first + (self.second - self.first) * wave[:, None]).astype(np.float32)


class SineGrating(ColourGrating):
    """Grey ``0.5 + 0.45 sin(2 pi (x cos a + y sin a) / period + phase)``."""

    def __init__(self, period: float, phase: float, angle: float = ANGLE):
        super().__init__(period, phase, angle, (0.05,) * 3, (0.95,) * 3)


class Checker:
    """A checkerboard of ``size``-lens squares alternating ``first`` and ``second`` (linear RGB), shifted by
    ``offset`` lenses."""

    def __init__(self, size: float, first, second, offset=(0.0, 0.0)):
        self.size, self.oy, self.ox = float(size), float(offset[0]), float(offset[1])
        self.colours = np.array([first, second], np.float32)

    def __call__(self, x, y):
        parity = (np.floor((x - self.ox) / self.size) + np.floor((y - self.oy) / self.size)).astype(np.int64) % 2
        return self.colours[parity]


def periodic_planes(lenses, seed: int = 0) -> list[Plane]:
    """The scene's four planes for ``lenses`` (S, T); the phases and offsets from ``seed``."""
    S, T = (float(n) for n in lenses)
    rng = np.random.default_rng([seed, 0x9E71])
    phase = rng.uniform(0.0, 2 * np.pi, 2)
    offset = rng.uniform(0.0, 2.0, (2, 2))
    hs, ht = S / 2, T / 2
    return [
        Plane("grating", 1.0, SineGrating(4.0, phase[0]), (0.0, 0.0, hs, ht)),
        Plane("far grating", -3.0, SineGrating(10.0, phase[1]), (0.0, ht, hs, T)),
        Plane("checker", 0.0, Checker(2.0, (0.05,) * 3, (0.95,) * 3, offset[0]), (hs, 0.0, S, ht)),
        Plane("primaries", 0.0, Checker(1.0, (0.95, 0.0, 0.0), (0.0, 0.0, 0.95), offset[1]), (hs, ht, S, T)),
    ]

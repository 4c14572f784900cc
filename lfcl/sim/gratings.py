"""The ``gratings`` scene: lens-scale sine gratings off the focal plane, drawn per seed.

A stress family for "never worse than Malvar" (docs/auto.md, "Lens-scale gratings"): fine texture off the
focal plane, the content every default is to be judged on, in its plainest form. Within a micro-image a plane at
disparity ``d`` shows the scene magnified: a grating of period ``P`` lenses becomes one of ``P / |d|`` pixels,
which the (u, v) priors take for noise, and where it lies near 4 pixels the Bayer pattern's red and blue see it at
their Nyquist period. Four rectangles tile the frame, as in :mod:`lfcl.sim.periodic`; each is a fronto-parallel
plane (frame coordinates in lenses, :mod:`lfcl.sim.planes`) holding a sine grating whose parameters come from
``seed``:

* period log-uniform in ``PERIODS`` (2.5 to 16 lenses; the views' Nyquist period is 2 lenses);
* disparity uniform in +-``DISPARITY`` lenses per view step, inside the search range of :mod:`lfcl.depth`;
* direction and phase uniform;
* between two colours: the first two quadrants (in a seed's random order) grey, from ``0.5 - a`` to ``0.5 + a`` with
  ``a`` uniform in 0.2..0.45; the other two between two colours uniform in 0.03..0.9 per channel (linear).
"""

from __future__ import annotations

import numpy as np

from .periodic import ColourGrating
from .planes import Plane

#: The gratings' periods (lenses): log-uniform between these.
PERIODS = (2.5, 16.0)
#: Their disparities (lenses per view step): uniform in +-this, inside lfcl.depth's default range of +-2.
DISPARITY = 1.9


def gratings_planes(lenses, seed: int = 0) -> list[Plane]:
    """The scene's four planes for ``lenses`` (S, T), drawn from ``seed`` (module docstring)."""
    S, T = (float(n) for n in lenses)
    rng = np.random.default_rng([seed, 0x6A7E])
    hs, ht = S / 2, T / 2
    rects = [(0.0, 0.0, hs, ht), (0.0, ht, hs, T), (hs, 0.0, S, ht), (hs, ht, S, T)]
    grey = np.zeros(4, bool)
    grey[rng.permutation(4)[:2]] = True
    planes = []
    for i, rect in enumerate(rects):
        period = float(np.exp(rng.uniform(*np.log(PERIODS))))
        disparity = float(rng.uniform(-DISPARITY, DISPARITY))
        angle, phase = (float(v) for v in rng.uniform(0.0, 2 * np.pi, 2))
        if grey[i]:
            a = float(rng.uniform(0.2, 0.45))
            first, second = (0.5 - a,) * 3, (0.5 + a,) * 3
        else:
            first, second = rng.uniform(0.03, 0.9, (2, 3))
        planes.append(Plane(f"grating {i + 1}", disparity, ColourGrating(period, phase, angle, first, second), rect))
    return planes

"""The ``gratings`` stress family (lfcl/sim/gratings.py): layout, draws, textures, determinism (the planes' parallax
is lfcl.sim.planes', tested in tests/test_sim_periodic.py and tests/test_sim.py)."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.sim import SCENES, render_scene
from lfcl.sim.gratings import DISPARITY, PERIODS, ColourGrating, gratings_planes
from lfcl.sim.scenes import render_disparity, scene_planes

LENSES = (24, 32)


def test_registered_with_four_quadrants_drawn_inside_their_ranges():
    assert "gratings" in SCENES
    for seed in range(20):
        planes = scene_planes("Gratings", LENSES, seed)
        assert [p.rect for p in planes] == [(0.0, 0.0, 12.0, 16.0), (0.0, 16.0, 12.0, 32.0), (12.0, 0.0, 24.0, 16.0),
                                            (12.0, 16.0, 24.0, 32.0)]
        assert all(abs(p.disparity) <= DISPARITY for p in planes)
        assert all(PERIODS[0] <= p.texture.period <= PERIODS[1] for p in planes)
        grey = [bool(np.all(p.texture.first == p.texture.first[0]) and np.all(p.texture.second == p.texture.second[0]))
                for p in planes]
        assert sum(grey) >= 2  # two grey ones (a coloured draw is grey only by chance)
    truth = render_disparity("gratings", LENSES, 3)
    for plane in gratings_planes(LENSES, 3):
        y0, x0, y1, x1 = (int(v) for v in plane.rect)
        np.testing.assert_allclose(truth[y0:y1, x0:x1], plane.disparity)


def test_a_grating_is_what_it_says():
    x = np.linspace(0.0, 40.0, 4001)
    first, second = (0.1, 0.2, 0.3), (0.7, 0.5, 0.3)
    values = ColourGrating(4.0, 0.3, 0.0, first, second)(x, np.zeros_like(x))
    assert values.shape == (x.size, 3)
    np.testing.assert_allclose(values.min(axis=0), [0.1, 0.2, 0.3], atol=1e-4)
    np.testing.assert_allclose(values.max(axis=0), [0.7, 0.5, 0.3], atol=1e-4)
    np.testing.assert_allclose(values[:-400], values[400:], atol=1e-5)  # period 4 lenses (100 steps a lens)
    turned = ColourGrating(4.0, 0.3, np.pi / 2, first, second)  # along y now: constant along x
    np.testing.assert_allclose(turned(x, np.zeros_like(x)), np.broadcast_to(turned(x[:1], x[:1]), (x.size, 3)),
                               atol=1e-6)


@pytest.mark.parametrize("seed", [1, 2, 7])
def test_deterministic_per_seed_and_seeds_differ(seed):
    a, b, c = (render_scene("gratings", LENSES, 9, seed=s)[:, :, 4, 4] for s in (seed, seed, seed + 10))
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).mean() > 0.02

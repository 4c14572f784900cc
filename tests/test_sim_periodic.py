"""The ``periodic`` stress scene (lfcl/sim/periodic.py): layout, disparities, textures, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.sim import SCENES, render_scene
from lfcl.sim.periodic import Checker, SineGrating
from lfcl.sim.scenes import render_disparity, scene_planes

LENSES = (24, 32)


def test_registered_with_four_quadrants_at_their_disparities():
    assert "periodic" in SCENES
    planes = scene_planes("Periodic", LENSES, 0)
    assert [(p.name, p.disparity) for p in planes] == [("grating", 1.0), ("far grating", -3.0), ("checker", 0.0),
                                                        ("primaries", 0.0)]
    truth = render_disparity("periodic", LENSES, 0)
    np.testing.assert_array_equal(truth[:12, :16], 1.0)
    np.testing.assert_array_equal(truth[:12, 16:], -3.0)
    np.testing.assert_array_equal(truth[12:], 0.0)


def test_textures_are_what_they_say():
    x = np.linspace(0.0, 40.0, 4001)
    grating = SineGrating(4.0, 0.3, angle=0.0)(x, np.zeros_like(x))
    assert grating.shape == (x.size, 3) and np.all(grating[:, 0] == grating[:, 2])  # grey
    assert grating.min() == pytest.approx(0.05, abs=1e-4) and grating.max() == pytest.approx(0.95, abs=1e-4)
    np.testing.assert_allclose(grating[:-400], grating[400:], atol=1e-5)  # period 4 lenses (100 steps a lens)
    checker = Checker(1.0, (0.95, 0.0, 0.0), (0.0, 0.0, 0.95))
    squares = checker(np.array([0.5, 1.5, 0.5, 1.5]), np.array([0.5, 0.5, 1.5, 1.5]))
    np.testing.assert_allclose(squares, [[0.95, 0, 0], [0, 0, 0.95], [0, 0, 0.95], [0.95, 0, 0]], atol=1e-7)


def test_the_gratings_move_along_their_epipolar_lines():
    """Each grating is a plane at an integer disparity: view u sees lens s + d (u - 4) of the centre view (the sign
    convention of lfcl.sim.planes), so its samples repeat along the lines a prior along them follows."""
    lf = render_scene("periodic", LENSES, 9, seed=3)
    for (rows, cols), d, views in (((slice(4, 8), slice(4, 12)), 1, (2, 3, 5, 6)),
                                   ((slice(4, 8), slice(20, 28)), -3, (3, 5))):  # the lines stay inside the plane
        for u in views:
            shift = d * (u - 4)
            moved = lf[rows.start + shift:rows.stop + shift, cols, 4, 4]
            np.testing.assert_allclose(lf[rows, cols, u, 4], moved, atol=2e-3)
        assert np.abs(lf[rows, cols, views[0], 4] - lf[rows, cols, 4, 4]).max() > 0.05  # the views do differ


def test_deterministic_per_seed_and_seeds_differ():
    a, b, c = (render_scene("periodic", LENSES, 9, seed=s)[:, :, 4, 4] for s in (5, 5, 6))
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).mean() > 0.05

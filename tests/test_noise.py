"""Noise estimation from a lenslet raw against the simulator's known noise model."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.noise.model import estimate_noise, from_noise_profile
from lfcl.sim import simulate


def model_sigma(capture) -> float:
    """The rms noise over a capture's mosaic, from the simulator's own constants."""
    mosaic = capture.normalised_raw()
    return float(np.sqrt(np.mean(capture.sensor.noise_sigma(np.clip(mosaic, 0, None)) ** 2)))


def smooth_lightfield(S=48, T=48):
    """A scene in focus and smooth within every lens: what the estimator assumes."""
    s, t = np.meshgrid(np.linspace(0, 1, S), np.linspace(0, 1, T), indexing="ij")
    rgb = np.stack([0.3 + 0.6 * s, 0.2 + 0.7 * t, 0.9 - 0.8 * s * t], axis=-1)
    return np.broadcast_to(rgb[:, :, None, None, :], (S, T, 9, 9, 3)).astype(np.float32)


@pytest.mark.parametrize("lux", [1.0, 12.0, 50.0])
def test_estimate_matches_the_sensor_model_on_a_smooth_scene(lux):
    capture = simulate(lightfield=smooth_lightfield(), lux=lux, seed=2)
    estimate = estimate_noise(capture.normalised_raw(), capture.pattern, (9, 9))
    assert estimate.source == "raw"
    assert estimate.sigma == pytest.approx(model_sigma(capture), rel=0.1)


@pytest.mark.parametrize("scene", ["charts", "deadleaves"])
def test_texture_inside_lenses_inflates_the_estimate_boundedly(scene):
    # Out-of-focus planes put texture under each lens, which reads as noise: the
    # estimate errs high (measured 1.1-1.5x at 1 lux, 64x64 lenses), never low.
    capture = simulate(scene, lenses=(64, 64), lux=1.0, seed=2)
    ratio = estimate_noise(capture.normalised_raw(), capture.pattern, (9, 9)).sigma / model_sigma(capture)
    assert 0.95 <= ratio <= 1.6


def test_noise_profile_gives_the_model_directly():
    capture = simulate("deadleaves", lenses=(8, 8), lux=4.0, seed=0)
    mosaic = capture.normalised_raw()
    s, o = capture.sensor.noise_profile()
    estimate = from_noise_profile([s, o] * 3, mosaic)
    assert estimate.sigma == pytest.approx(np.sqrt(s * mosaic.mean() + o), rel=1e-9)
    assert estimate.sigma_at(0.5) == pytest.approx(np.sqrt(s * 0.5 + o), rel=1e-9)


def test_too_small_a_mosaic_is_refused():
    with pytest.raises(ValueError, match="too few lenses"):
        estimate_noise(np.zeros((9, 9), np.float32), "GRBG", (9, 9))

"""Noise estimation from a lenslet raw against the simulator's known noise model."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import shared_path

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
    # estimate errs high, never far low (measured 0.98-1.08x at 0.5-50 lux, 48x48 lenses).
    capture = simulate(scene, lenses=(64, 64), lux=1.0, seed=2)
    ratio = estimate_noise(capture.normalised_raw(), capture.pattern, (9, 9)).sigma / model_sigma(capture)
    assert 0.9 <= ratio <= 1.3


def test_fine_texture_off_the_focal_plane_is_read_along_the_epipolar_lines():
    # Pixel-scale texture under every lens: the plane fit reads it as noise (5-15x the truth at 12 lux,
    # research/fit_noise.py); the same-point pairs along the epipolar lines do not.
    capture = simulate("finetexture", lenses=(48, 48), lux=12.0, seed=3)
    mosaic, truth = capture.normalised_raw(), model_sigma(capture)
    plane = estimate_noise(mosaic, capture.pattern, (9, 9), light_field=False)
    both = estimate_noise(mosaic, capture.pattern, (9, 9))
    assert plane.method == "plane fit" and plane.sigma / truth > 4
    assert both.method in ("epipolar pairs", "epipolar fit")
    assert 0.8 <= both.sigma / truth <= 2.5


def lambertian_plane(d, S=40, T=40, U=9, V=9, seed=0):
    """A grey-world light field of one textured plane at disparity ``d`` (HCI's sign): L(s, t, u, v) =
    f(s + d (u - uc), t + d (v - vc)), f a random sum of sines (defined between lenses)."""
    rng = np.random.default_rng(seed)
    k = rng.uniform(0.3, 2.5, (12, 2))
    phase = rng.uniform(0, 2 * np.pi, 12)
    s, t, u, v = np.meshgrid(np.arange(S), np.arange(T), np.arange(U), np.arange(V), indexing="ij")
    y, x = s + d * (u - (U - 1) / 2), t + d * (v - (V - 1) / 2)
    f = 0.5 + 0.04 * np.sin(k[:, 0, None, None, None, None] * y + k[:, 1, None, None, None, None] * x
                            + phase[:, None, None, None, None]).sum(axis=0)
    return np.repeat(f[..., None], 3, axis=-1)


@pytest.mark.parametrize("d", [0.0, 0.5, -1.0, 0.25])
def test_same_point_pairs_measure_the_noise_and_nothing_else(d):
    from lfcl.layout import channel_map
    from lfcl.noise.epipolar import TOLERANCE, pair_variances

    lf = lambertian_plane(d)
    S, T, U, V, _ = lf.shape
    channels = channel_map((S * U, T * V), "GRBG")
    clean = lf.transpose(0, 2, 1, 3, 4).reshape(S * U, T * V, 3)[..., 0]
    disparity = np.full((S, T), d)
    levels, variances, pairs = pair_variances(clean, channels, (U, V), disparity, TOLERANCE)
    assert levels.size > S * T // 2 and np.all(pairs >= 4)
    assert np.max(variances) < 1e-12  # exact same-point pairs: no texture left
    sigma = 0.01
    noisy = clean + np.random.default_rng(1).normal(0, sigma, clean.shape)
    _, variances, pairs = pair_variances(noisy, channels, (U, V), disparity, TOLERANCE)
    # The mean of the per-lens variances is sigma^2 within its own sampling error.
    assert np.mean(variances) == pytest.approx(sigma**2, rel=4 * np.sqrt(2 / pairs.sum()) + 0.02)


@pytest.mark.parametrize("estimate", ["pairs", "fit"])
@pytest.mark.parametrize("d", [0.0, 0.3, -0.7, 1.0, 1.5])
def test_the_variances_along_the_disparity_count_their_degrees_of_freedom(estimate, d):
    # Pure noise on a flat light field. Each lens colour's variance is sigma^2 on average, and spreads as a chi-square
    # of its degrees of freedom: var(v / sigma^2) = 2 / dof. For the fit they are the samples less the hat matrix's
    # trace (1 at d = 0, where every delta is 0); for the pairs, which share samples, Satterthwaite's count. The count
    # before it (the pairs or the lens's own samples in them, whichever fewer) spread 1.5x / 2.7x less than it claimed
    # at d = 1.5 / 1.
    from lfcl.layout import channel_map
    from lfcl.noise.epipolar import fit_variances, pair_variances

    S = T = 24
    channels = channel_map((S * 9, T * 9), "GRBG")
    sigma = 0.01
    noisy = 0.5 + np.random.default_rng(2).normal(0, sigma, channels.shape)
    disparity = np.full((S, T), d)
    if estimate == "pairs":
        levels, variances, dof = pair_variances(noisy, channels, (9, 9), disparity)
    else:
        levels, variances, dof = fit_variances(noisy, channels, (9, 9), disparity)
    if estimate == "pairs" and d in (0.3, -0.7):
        assert levels.size == 0  # no offset within TOLERANCE of whole lenses: what the fit is for
        return
    assert levels.size > S * T // 2 and np.all(dof >= 4)
    ratio = variances / sigma**2
    assert np.average(ratio, weights=dof) == pytest.approx(1.0, rel=4 * np.sqrt(2 / dof.sum()))
    assert np.mean((ratio - 1) ** 2 * dof / 2) == pytest.approx(1.0, abs=0.15)


@pytest.mark.parametrize("d", [0.3, -0.7, 1.5])
def test_the_fit_along_the_disparity_takes_the_texture_out(d):
    # A textured plane at a disparity that leaves no whole-lens pairs: the quadratic surface in the scene's
    # coordinates keeps a small part of the texture, the plane fit inside each micro-image most of it.
    from lfcl.layout import channel_map
    from lfcl.noise.epipolar import fit_variances
    from lfcl.noise.model import _plane_residual_variances

    lf = lambertian_plane(d)
    S, T, U, V, _ = lf.shape
    clean = lf.transpose(0, 2, 1, 3, 4).reshape(S * U, T * V, 3)[..., 0]
    _, along, _ = fit_variances(clean, channel_map(clean.shape, "GRBG"), (U, V), np.full((S, T), d))
    lenses = clean.reshape(S, U, T, V).transpose(0, 2, 1, 3).reshape(S * T, U, V)[:, 1:-1, 1:-1]
    mask = channel_map((U - 2, V - 2), "GRBG") == 1
    _, inside = _plane_residual_variances(lenses, mask)
    assert np.median(along) < 0.05 * np.median(inside)


def test_a_fine_grating_at_a_fractional_disparity_is_read_by_the_fit():
    # A grating of period 2.5 lenses filling the frame at d = 0.3: no view offset shifts by whole lenses, so there
    # are no pairs, and the plane fit reads the grating as 19x the noise (the default then smoothed it away, 17 dB
    # below Malvar at 50 lux without a noise profile; docs/noise.md).
    from lfcl.evaluation.evaluate import simulation_capture
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    capture = simulation_capture(simulate(planes=[Plane("grating", 0.3, SineGrating(2.5, 0.7))], lenses=(32, 32),
                                          lux=25, seed=3))
    truth = from_noise_profile(capture.noise_profile, capture.mosaic).sigma
    plane = estimate_noise(capture.mosaic, capture.pattern, capture.pitch, light_field=False)
    estimate = estimate_noise(capture.mosaic, capture.pattern, capture.pitch)
    assert plane.sigma / truth > 10
    assert estimate.method == "epipolar fit" and 0.9 <= estimate.sigma / truth <= 1.3


def test_pair_offsets_pair_one_colour_and_whole_lenses():
    from lfcl.layout import channel_map
    from lfcl.noise.epipolar import offset_shifts, view_offsets

    U = V = 9
    S = T = 12
    disparity = np.random.default_rng(0).uniform(-2, 2, (S, T))
    shift, error = offset_shifts(disparity, (U, V))
    offsets = view_offsets((U, V))
    colour = channel_map((5 * S * U, 5 * T * V), "RGGB")  # room for partners up to 16 lenses beyond the edge
    for s, t, k in zip(*np.nonzero(error < 0.12)):
        (du, dv), (ns, nt) = offsets[k], shift[s, t, k]
        assert max(abs(disparity[s, t] * du - ns), abs(disparity[s, t] * dv - nt)) == pytest.approx(error[s, t, k])
        row, col = (2 * S + s) * U, (2 * T + t) * V  # lens (s, t), away from the array's edge
        partner_row, partner_col = (2 * S + s - ns) * U + du, (2 * T + t - nt) * V + dv
        assert partner_row >= 0 and partner_col >= 0
        assert any(colour[row + u, col + v] == colour[partner_row + u, partner_col + v]
                   for u in range(2) for v in range(2))
    # offsets that pair no colour are refused: at d = 0, (0, 1) pairs green with red or blue
    _, at_zero = offset_shifts(np.zeros((1, 1)), (U, V))
    assert np.isinf(at_zero[0, 0, list(map(tuple, offsets)).index((0, 1))])
    assert at_zero[0, 0, list(map(tuple, offsets)).index((0, 2))] == 0


def test_a_raw_too_small_for_pairs_keeps_the_plane_fit():
    capture = simulate("charts", lenses=(6, 6), lux=4.0, seed=0)
    estimate = estimate_noise(capture.normalised_raw(), capture.pattern, (9, 9))
    assert estimate.method == "plane fit"


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


def test_the_disparity_tiles_spread_over_a_large_raw():
    from lfcl.noise.epipolar import tiles

    assert tiles(50, 96) == [(0, 50, 0, 96)]  # small enough: the whole raw
    spread = tiles(500, 40, tile=32, count=3)
    assert [(s0, s1) for s0, s1, _, _ in spread] == [(0, 32), (234, 266), (468, 500)]
    assert all((t0, t1) == (0, 40) for _, _, t0, t1 in spread)


def test_truth_noise_reads_the_noise_a_decoded_light_field_carries():
    """A light field decoded from a real camera carries that camera's noise in every view; truth_noise
    measures it against the sensor's, and reads a noise-free truth as (near) none."""
    from lfcl.evaluation.evaluate import simulation_capture, truth_noise

    rng = np.random.default_rng(3)
    flat = np.full((16, 16, 9, 9, 3), 0.4, np.float32)
    grain = (flat * (1 + 0.08 * rng.standard_normal(flat.shape))).astype(np.float32)
    ratios = {}
    for label, field in (("clean", flat), ("grain", grain)):
        capture = simulation_capture(simulate(lightfield=field, lux=12, seed=1))
        sensor = from_noise_profile(capture.noise_profile, capture.mosaic).sigma
        own = float(np.std(capture.truth / capture.truth.mean() - 1.0)) * float(capture.truth.mean())
        ratios[label] = (truth_noise(capture), own / sensor)
        assert truth_noise(dataclasses.replace(capture, noise_profile=None)) is None  # nothing to compare with
    assert ratios["clean"][0] < 0.05  # a flat noise-free truth: nothing of its own
    measured, expected = ratios["grain"]
    assert expected > 2 and measured == pytest.approx(expected, rel=0.15), (measured, expected)


@pytest.mark.parametrize("lux", [0.5, 2, 12, 50])
def test_a_flat_wall_reads_the_sensor_noise(lux):
    """A raw of one brightness (a flat wall, no noise profile): the brightness bins span only the noise, so a
    free line through them can come out steep; clipping its negative slope kept its intercept, up to 3.4x the
    noise here. The line is now fitted with both coefficients >= 0."""
    for seed in (1, 2, 3):
        wall = simulate(lightfield=np.full((16, 16, 9, 9, 3), 0.4, np.float32), lux=lux, seed=seed)
        raw = wall.normalised_raw()
        estimate = estimate_noise(raw, wall.pattern, tuple(wall.geometry.pitch))
        truth = from_noise_profile(list(wall.sensor.noise_profile()) * 3, raw)
        assert 0.9 < estimate.sigma / truth.sigma < 1.15, (seed, estimate)


def test_the_noise_line_stays_non_negative_and_fits_what_is_left():
    from lfcl.noise.model import fit_noise_model

    levels = np.repeat(np.linspace(0.1, 0.2, 8), 40)
    falling = np.repeat(np.linspace(2e-5, 1e-5, 8), 40)  # a free fit's slope < 0: the floor is their mean
    assert fit_noise_model(levels, falling, bins=8) == pytest.approx((0.0, falling.mean()), rel=1e-6)
    shot = np.repeat(np.linspace(1e-5, 3e-5, 8), 40)  # through the origin's far side: intercept < 0, refitted at 0
    gain, floor = fit_noise_model(levels, shot, bins=8)
    centres = np.linspace(0.1, 0.2, 8)
    # on the face floor = 0 the bins weighed by 1 / (gain x)^2 give the mean of their ratios
    assert floor == 0.0 and gain == pytest.approx(np.mean(np.linspace(1e-5, 3e-5, 8) / centres), rel=1e-6)


def test_the_noise_line_weighs_each_bin_by_its_own_scale():
    # Bins from nearly black to mid-grey whose quantiles err by +-5 % of their variance: unweighted, the bright bins'
    # scatter (4e-6) sets a floor of 1.7e-7; weighed by 1 / var^2 the dark bins pin it.
    from lfcl.noise.model import _non_negative_line, fit_noise_model

    gain, floor = 1.67e-4, 1.7e-7
    centres = np.geomspace(1e-3, 0.5, 12)
    scatter = 1 + 0.05 * np.resize([1, -1, -1, 1], 12)
    levels = np.repeat(centres, 40)
    variances = np.repeat((gain * centres + floor) * scatter, 40)
    _, unweighted = _non_negative_line(centres, (gain * centres + floor) * scatter)
    assert not 0.5 < unweighted / floor < 2
    fitted_gain, fitted_floor = fit_noise_model(levels, variances, bins=12)
    assert fitted_gain == pytest.approx(gain, rel=0.05) and fitted_floor == pytest.approx(floor, rel=0.3)


def test_a_brightness_bin_across_a_gap_in_the_levels_is_split():
    # Pure-colour content: unlit samples near 0, lit ones near 0.88, and a quantile bin holding some of each. Unsplit,
    # its low quantile was the dark members' and its centre a lit level, which bent the line (0.83x the gain, 0.58x
    # the floor on a red/blue checker).
    from lfcl.noise.model import fit_noise_model

    rng = np.random.default_rng(0)
    levels = np.concatenate([rng.uniform(0.0, 1e-3, 1000), rng.uniform(0.88, 0.89, 700)])
    edges = np.quantile(levels, np.linspace(0, 1, 17))
    assert np.any((edges[:-1] < 0.5) & (edges[1:] > 0.5))  # one bin does straddle the gap
    gain, floor = 1.7e-4, 1.7e-7
    gain_fit, floor_fit = fit_noise_model(levels, gain * levels + floor, bins=16)
    assert gain_fit == pytest.approx(gain, rel=0.01) and floor_fit == pytest.approx(floor, rel=0.1)


def test_pure_colour_lenses_give_the_noise_floor():
    # Lenses of pure red and pure blue at 2 lux, no noise profile: the unlit colours' samples measure the floor. With
    # the pairs pooled over colours per lens there were no dark levels, the pair fit's floor came out 0, and the
    # flat-lens test then called no lens flat (admm-epi 9.6 dB below Malvar; docs/noise.md).
    from lfcl.evaluation.evaluate import simulation_capture
    from lfcl.sim.periodic import Checker
    from lfcl.sim.planes import Plane

    capture = simulation_capture(simulate(planes=[Plane("c", 0.0, Checker(1.0, (0.95, 0, 0), (0, 0, 0.95)))],
                                          lenses=(48, 48), lux=2, seed=0))
    truth = from_noise_profile(capture.noise_profile, capture.mosaic)
    estimate = estimate_noise(capture.mosaic, capture.pattern, capture.pitch)
    assert 0.9 <= estimate.sigma / truth.sigma <= 1.15
    assert 0.5 <= estimate.floor / truth.floor <= 2


def test_the_lytro_frames_truth_carries_noise_of_its_own_and_antinous_does_not():
    """The finding behind docs/auto.md "A truth with noise of its own", on the real light fields: the Lytro frame
    (decoded from a real camera) carries more noise than the simulated sensor at 12 lux, the rendered antinous far
    less (measured 2.59x and 0.31x at 48x48 lenses)."""
    from lfcl.evaluation.evaluate import simulated_capture, truth_noise

    lytro = shared_path("realdata", "lytro_epinet", "2067")
    antinous = shared_path("realdata", "hci_epinet", "antinous")
    assert truth_noise(simulated_capture(32, 12, seed=7, lightfield=str(lytro))) > 1.5
    assert truth_noise(simulated_capture(32, 12, seed=7, lightfield=str(antinous))) < 0.6


def test_the_default_keeps_a_grating_at_a_fractional_disparity_without_a_profile():
    """A grating of period 8 lenses filling the frame at d = 1.5, 25 lux, the DNG's noise profile dropped: the pairs
    find no lens (the tile disparity reads 1.45, which leaves every offset 0.1 lens off whole lenses) and the plane fit
    reads the grating as 37x the noise; the default then smoothed the grating away, 19.5 dB below Malvar's centre
    view. The fit along the disparity reads 1.03x, and the default stays above Malvar."""
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    capture = simulation_capture(simulate(planes=[Plane("grating", 1.5, SineGrating(8.0, 0.7))], lenses=(32, 32),
                                          lux=25, seed=3))
    capture = dataclasses.replace(capture, noise_profile=None)
    malvar, default = run_method(capture, "malvar"), run_method(capture, "auto")
    assert default["psnr_center"] > malvar["psnr_center"] + 1
    assert default["psnr_mean"] > malvar["psnr_mean"] - 0.1

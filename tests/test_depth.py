"""Disparity from the raw (lfcl.depth): device vs numpy cost volume, recovery of known planes,
bad input, the HCI sign on antinous, the metrics and the `--outputs depth` files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import shared_path

from lfcl.depth import badpix, candidates, depth_scores, estimate_disparity, mse100, read_pfm
from lfcl.depth.cost import CostVolume, colour_penalty_np, cost_volume_np, half_apertures, lens_colour_np
from lfcl.depth.estimate import DEFAULTS
from lfcl.noise.model import NoiseEstimate
from lfcl.sim.capture import simulate
from lfcl.sim.deadleaves import DeadLeavesTexture, _texture_box
from lfcl.sim.planes import Plane

# (S, T, U, V, model, origin, views): odd and even pitch, one lens, a crop origin, a half aperture.
TWIN_CASES = [(3, 4, 9, 9, "plane", (0, 0), None), (2, 5, 5, 4, "mean", (1, 0), None),
              (1, 1, 9, 9, "plane", (1, 1), None), (4, 3, 3, 3, "plane", (0, 1), (0, 1, 0, 2)),
              (3, 3, 9, 9, "plane", (0, 0), (4, 8, 0, 8))]


@pytest.mark.parametrize("colour", [0.0, 0.5], ids=["no-colour-penalty", "colour-penalty"])
@pytest.mark.parametrize("case", TWIN_CASES, ids=str)
def test_device_cost_volume_matches_numpy(runtime, rng, case, colour):
    S, T, U, V, model, origin, views = case
    mosaic = rng.uniform(0.05, 0.6, (S * U, T * V)).astype(np.float32)
    ds = np.array([-1.3, -1.0, -0.5, -0.05, 0.0, 0.35, 1.0, 2.0], np.float32)
    expected = cost_volume_np(mosaic, "GRBG", (U, V), ds, origin=origin, noise=(1e-3, 1e-4), saturation=0.55,
                              model=model, views=views, colour=colour)
    op = CostVolume(runtime, mosaic.shape, "GRBG", (U, V), ds, origin=origin, model=model, colour=colour)
    got = op.forward(runtime.to_device(mosaic), (1e-3, 1e-4), 0.55, views).get()
    assert got.shape == (2, ds.size, S, T)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5 * scale)
    assert expected[1].max() > 0  # some samples were gathered (saturation left some in)


@pytest.mark.parametrize("S, T, U, V, model, origin", [(3, 4, 9, 9, "plane", (0, 0)), (2, 3, 4, 6, "mean", (1, 0)),
                                                     (2, 2, 1, 2, "plane", (0, 1)), (1, 1, 5, 3, "plane", (1, 1))],
                         ids=str)
@pytest.mark.parametrize("colour", [0.0, 0.5], ids=["no-colour-penalty", "colour-penalty"])
def test_device_half_apertures_in_one_gather_match_numpy(runtime, rng, S, T, U, V, model, origin, colour):
    mosaic = rng.uniform(0.05, 0.6, (S * U, T * V)).astype(np.float32)
    ds = np.array([-1.3, -0.5, 0.0, 0.35, 1.0], np.float32)
    apertures = [None, *half_apertures(U, V)]
    expected = np.stack([cost_volume_np(mosaic, "GRBG", (U, V), ds, origin=origin, noise=(1e-3, 1e-4),
                                        saturation=0.55, model=model, views=views, colour=colour)
                         for views in apertures])
    op = CostVolume(runtime, mosaic.shape, "GRBG", (U, V), ds, origin=origin, model=model, halves=True,
                    colour=colour)
    got = op.forward(runtime.to_device(mosaic), (1e-3, 1e-4), 0.55).get()
    assert got.shape == (5, 2, ds.size, S, T)
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5 * np.abs(expected).max())
    with pytest.raises(ValueError, match="gathers every view"):
        op.forward(runtime.to_device(mosaic), (1e-3, 1e-4), 0.55, views=(0, 1, 0, 1))


# Frames with an interior box (lenses whose every tap lies inside the frame), which depth_cost_interior gathers 8 lenses
# of a row at a time, beside the frame's edge and the box's last columns, which depth_cost gathers; odd and even
# pitch, the half apertures, a crop origin, and saturated samples inside the box (the lenses that reach them go to
# depth_cost).
@pytest.mark.parametrize("S, T, U, V, model, halves, origin, views", [
    (16, 30, 9, 9, "plane", True, (0, 0), None), (12, 29, 5, 5, "plane", False, (1, 0), None),
    (10, 27, 4, 6, "mean", False, (0, 1), None), (12, 26, 5, 5, "plane", False, (0, 0), (1, 3, 0, 2)),
    (10, 27, 4, 6, "plane", True, (1, 1), None)], ids=str)
@pytest.mark.parametrize("colour", [0.0, 0.5], ids=["no-colour-penalty", "colour-penalty"])
def test_device_cost_volume_interior_box_matches_numpy(runtime, rng, S, T, U, V, model, halves, origin, views,
                                                       colour):
    mosaic = rng.uniform(0.05, 0.5, (S * U, T * V)).astype(np.float32)
    ds = np.array([-1.3, -0.5, 0.0, 0.35, 1.0], np.float32)
    op = CostVolume(runtime, mosaic.shape, "GRBG", (U, V), ds, origin=origin, model=model, halves=halves,
                    colour=colour)
    s0, s1, t0, t1 = op.box
    assert s1 > s0 and t1 - t0 >= 8, op.box
    # Two saturated samples: one inside the box, one in the edge ring.
    mosaic[(s0 + (s1 - s0) // 2) * U + 1, (t0 + 3) * V + V - 1] = 0.97
    mosaic[1, 2] = 0.99
    apertures = [None, *half_apertures(U, V)] if halves else [views]
    expected = np.stack([cost_volume_np(mosaic, "GRBG", (U, V), ds, origin=origin, noise=(1e-3, 1e-4),
                                        saturation=0.9, model=model, views=a, colour=colour) for a in apertures])
    got = op.forward(runtime.to_device(mosaic), (1e-3, 1e-4), 0.9, None if halves else views).get()
    got = got if halves else got[None]
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5 * np.abs(expected).max())
    # Both kernels ran: the box, and the lenses listed for depth_cost (the ring, and those reaching the sample).
    listed = op._listed(runtime.to_device(mosaic), np.float32(0.9))
    inside = [(i // T, i % T) for i in listed if s0 <= i // T < s1 and t0 <= i % T < t1]
    assert inside and len(inside) < (s1 - s0) * (t1 - t0)


def test_cost_volume_of_a_large_frame_matches_numpy_on_crops(runtime, rng):
    """200x200 lenses, the search range of lfcl.depth's defaults: a box of 22 x 8 lenses by 183 rows, where PoCL, left to
    choose the work-groups, made groups of ~4000 work-items whose private arrays overflowed its thread's stack (a
    segmentation fault in `lfcl process` at this size). A lens's cost depends only on the lenses its taps reach, so the
    twin on a crop around it gives its value (the crop's CFA phase as its origin)."""
    S = T = 200
    mosaic = rng.uniform(0.05, 0.5, (9 * S, 9 * T)).astype(np.float32)
    ds = np.array([-2.0, 0.35, 2.0], np.float32)
    op = CostVolume(runtime, mosaic.shape, "GRBG", 9, ds, halves=True)
    assert op.box == (8, 191, 8, 184)
    got = op.forward(runtime.to_device(mosaic), (1e-3, 1e-4), 0.99).get()
    for s, t in ((8, 8), (100, 131), (190, 183), (3, 196)):  # box corners, inside, the edge ring
        r0, c0 = max(0, s - 9), max(0, t - 9)
        crop = mosaic[9 * r0:9 * min(S, s + 10), 9 * c0:9 * min(T, t + 10)]
        want = np.stack([cost_volume_np(crop, "GRBG", 9, ds, origin=(9 * r0, 9 * c0), noise=(1e-3, 1e-4),
                                        saturation=0.99, views=views)[..., s - r0, t - c0]
                         for views in [None, *half_apertures(9, 9)]])
        np.testing.assert_allclose(got[..., s, t], want, rtol=1e-4, atol=1e-5 * np.abs(want).max())


def test_device_lens_colour_matches_numpy(runtime, rng):
    S, T, U, V = 4, 5, 9, 9
    mosaic = rng.uniform(0.1, 0.6, (S * U, T * V)).astype(np.float32)
    mosaic[:U, :V] = 0.3 + 0.001 * rng.standard_normal((U, V))  # a grey lens
    mosaic[U:2 * U:2, 2 * V + 1:3 * V:2] = 0.97  # every red sample of lens (1, 2) saturated: unknown
    mosaic[3, 4 * V + 2] = 0.98  # one saturated sample: left out of that lens's means
    op = CostVolume(runtime, mosaic.shape, "GRBG", (U, V), [0.0], origin=(1, 0), colour=0.5)
    got = op.lens_colour(runtime.to_device(mosaic), (1e-5, 1e-6), 0.95).get()
    want = lens_colour_np(mosaic, "GRBG", (U, V), origin=(1, 0), noise=(1e-5, 1e-6), saturation=0.95)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
    assert want[3, 0, 0] == 0.0 and want[3, 1, 2] == 2.0 and (want[3] == 1.0).sum() == S * T - 2


def test_view_major_copy_and_unusable_lenses_match_numpy(runtime, rng):
    S, T, U, V = 3, 5, 4, 3
    mosaic = rng.uniform(0.0, 0.5, (S * U, T * V)).astype(np.float32)
    mosaic[5, 7] = 0.95  # lens (1, 2)
    mosaic[0, 14] = np.nan  # lens (0, 4)
    op = CostVolume(runtime, mosaic.shape, "RGGB", (U, V), [0.0])
    data = runtime.to_device(mosaic)
    np.testing.assert_array_equal(op.view_major(data).get().reshape(U, V, S, T),
                                  mosaic.reshape(S, U, T, V).transpose(1, 3, 0, 2))
    want = np.zeros((S, T), bool)
    want[1, 2] = want[0, 4] = True
    np.testing.assert_array_equal(op.unusable_lenses(data, 0.9), want)
    not_a_number = np.zeros((S, T), bool)
    not_a_number[0, 4] = True
    np.testing.assert_array_equal(op.unusable_lenses(data, np.inf), not_a_number)


@pytest.mark.parametrize("lenses, radius", [((6, 9), 4), ((1, 3), 1), ((5, 4), 0)])
def test_device_window_weights_match_numpy(runtime, rng, lenses, radius):
    """The window weights built on the device from the guide against their twin, neighbours past the frame 0."""
    from lfcl.depth.cost import WindowAggregate
    from lfcl.depth.estimate import _guide_scale, _window_weights

    guide = rng.uniform(0.0, 0.3, (3, *lenses))
    guide[:, 0, 0] += 0.05  # one lens unlike its neighbours: weights well below 1
    _, want = _window_weights(guide, radius, 30.0, 2e-4, 1e-6)
    got = WindowAggregate(runtime, 1, lenses, radius).weights(guide, _guide_scale(guide, 30.0, 2e-4, 1e-6)).get()
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)
    if radius:  # neighbours outside the frame weigh 0, the unlike lens's little
        assert want.min() == 0.0 and 0.0 < want[want > 0].min() < 0.5
    else:  # the lens itself
        np.testing.assert_array_equal(want, 1.0)


def test_device_choice_between_apertures_matches_numpy(runtime, rng):
    """Step 3's choice between the apertures' cost curves on the device (one aperture at a time, in place) against
    its twin: the chosen curve, score and noise; lenses where a half aperture wins and where the full one stays, and
    a lens with no weight (the 1e-12 guard)."""
    from lfcl.depth.cost import WindowAggregate
    from lfcl.depth.estimate import take_aperture_np

    ND, S, T = 6, 5, 7
    window = WindowAggregate(runtime, 2 * ND, (S, T), 1)
    best_dev = (runtime.empty((ND, S, T)), runtime.empty((S, T)), runtime.empty((S, T)))
    best, chosen = None, np.zeros((S, T), int)
    for index in range(5):
        sums = np.concatenate([rng.normal(0.0, 3.0, (ND, S, T)), rng.uniform(0.5, 40.0, (ND, S, T))]).astype(np.float32)
        sums[ND:, 0, 0] = 0.0
        before = None if best is None else best[1]
        best = take_aperture_np(best, sums[:ND].astype(np.float64), sums[ND:].astype(np.float64), half=index > 0)
        if before is not None:
            chosen[best[1] != before] = index
        window.take_aperture(runtime.to_device(sums), best_dev, half=index > 0, first=index == 0)
        for got, want in zip(best_dev, best):
            np.testing.assert_allclose(got.get(), want, rtol=1e-5)
    assert (chosen == 0).any() and (chosen > 0).any()  # some lenses kept the full aperture, some took a half


def test_cost_geometry_holds_the_sums_of_an_interior_lens(rng):
    """The table's 12 sums per colour are the twin's (rows 0-5 and 10-15 of its ``acc``), for a lens of each parity."""
    from lfcl.depth.cost import cost_geometry, tap_reach
    from lfcl.layout import packed_pattern

    U = V = 5
    ds = np.array([-0.7, 0.0, 0.45], np.float32)
    row_lo, row_hi, col_lo, col_hi = tap_reach(ds, U, V)
    assert (row_lo, row_hi, col_lo, col_hi) == (-2, 2, -2, 2)
    table = cost_geometry(ds, U, V, packed_pattern("RGGB"), [(0, U - 1, 0, V - 1)])
    # By the definition: every tap of lens (s, t) with its bilinear weight, under its own colour.
    for k, d in enumerate(ds):
        for s, t in ((6, 6), (6, 7), (7, 6), (7, 7)):
            want = np.zeros((3, 12))
            for u in range(U):
                for v in range(V):
                    y, x = s - float(d) * (u - 2), t - float(d) * (v - 2)
                    for sp in (int(np.floor(y)), int(np.floor(y)) + 1):
                        for tp in (int(np.floor(x)), int(np.floor(x)) + 1):
                            w = max(0.0, 1 - abs(sp - y)) * max(0.0, 1 - abs(tp - x))
                            py, px = sp - y, tp - x
                            c = {"R": 0, "G": 1, "B": 2}["RGGB"[2 * ((sp * U + u) % 2) + (tp * V + v) % 2]]
                            phi = np.array([1, py, px, py * py, px * px, py * px])
                            want[c, :6] += w * phi
                            want[c, 6:] += w * w * phi
            np.testing.assert_allclose(table[k, 0, 2 * (s % 2) + t % 2], want, atol=1e-5)


def test_half_apertures_hold_the_centre_rows_and_columns():
    assert half_apertures(9, 9) == [(0, 4, 0, 8), (4, 8, 0, 8), (0, 8, 0, 4), (0, 8, 4, 8)]
    assert half_apertures(4, 4) == [(0, 2, 0, 3), (1, 3, 0, 3), (0, 3, 0, 2), (0, 3, 1, 3)]


def test_cost_is_zero_in_expectation_for_pure_noise(rng):
    # A flat grey field plus Gaussian noise of the stated variance: excess / weight ~ 0 at every d.
    S, T, U, V = 6, 6, 9, 9
    sigma2 = 1e-4
    mosaic = (0.3 + np.sqrt(sigma2) * rng.standard_normal((S * U, T * V))).astype(np.float32)
    ds = np.array([-0.75, 0.0, 0.5, 1.0], np.float32)
    excess, weight = cost_volume_np(mosaic, "RGGB", (U, V), ds, noise=(0.0, sigma2))
    per_sample = excess.sum(axis=(1, 2)) / weight.sum(axis=(1, 2))
    assert np.all(np.abs(per_sample) < 0.1), per_sample


def test_colour_penalty_counts_only_colour_the_lens_lacks(rng):
    """The colour penalty (lfcl.depth.cost, module docstring) of hand-made means: none for the lens's own colour,
    any multiple of it or a grey offset (its noise-only expectation subtracted, 1 dof left); a grey lens pays for
    the candidate's colour; a candidate of one or two colours, or a lens of unknown colour, pays nothing."""
    k = np.array([2e4, 4e4, 2e4])[:, None]  # W / nv: ~20 samples a colour at a noise variance of 1e-3
    red = np.array([0.6, 0.2, 0.1, 1.0])[:, None]  # coloured
    for means in ([0.6, 0.2, 0.1], [0.3, 0.1, 0.05], [0.7, 0.3, 0.2], [0.3 + 0.05, 0.1 + 0.05, 0.05 + 0.05]):
        np.testing.assert_allclose(colour_penalty_np(np.array(means)[:, None], k, red), [-1.0], atol=1e-12)
    grey = np.array([0.4, 0.4, 0.4, 0.0])[:, None]
    magenta = np.array([0.9, 0.1, 0.9])[:, None]  # the checker's candidate at d = 2: R, B on white, G on black
    want = (k[:, 0] * (magenta[:, 0] - (k[:, 0] * magenta[:, 0]).sum() / k.sum()) ** 2).sum() - 2.0
    np.testing.assert_allclose(colour_penalty_np(magenta, k, grey), [want])
    assert want > 1e3
    np.testing.assert_allclose(colour_penalty_np(np.full((3, 1), 0.7), k, grey), [-2.0], atol=1e-12)
    # Equal red and blue gains: a grey lens reads (0.45, 1, 0.45) in the raw, and the checker's candidate at d = 2
    # (0.45, 0, 0.45) is a negative multiple of it plus an offset; only a non-negative multiple counts as its colour.
    raw_grey = np.array([0.45, 1.0, 0.45, 1.0])[:, None]
    assert colour_penalty_np(np.array([0.45, 0.0, 0.45])[:, None], k, raw_grey)[0] > 1e3
    assert colour_penalty_np(magenta, np.array([[2.0], [0.0], [0.0]]), grey)[0] == 0.0
    assert abs(colour_penalty_np(magenta, np.array([[2e4], [4e4], [0.0]]), red)[0]) < 1e-9  # 2 colours, 2 dof
    assert colour_penalty_np(magenta, k, np.array([0.4, 0.4, 0.4, 2.0])[:, None])[0] == 0.0
    # Numpy's lens colour: per-colour means of the unsaturated samples, its kind from their chi-square.
    U = V = 4
    mosaic = np.empty((2 * U, 3 * V), np.float32)
    mosaic[:, :V] = 0.4  # grey
    mosaic[:, V:2 * V] = np.where(np.arange(2 * U)[:, None] % 2 == 0, 0.6, 0.2) * np.ones((1, V))  # RGGB rows
    mosaic[:, 2 * V:] = 0.4
    mosaic[0::2, 2 * V::2] = 0.995  # every red sample of the third lens column saturated
    lens = lens_colour_np(mosaic, "RGGB", (U, V), noise=(0.0, 1e-4), saturation=0.99)
    np.testing.assert_allclose(lens[:, 0, 0], [0.4, 0.4, 0.4, 0.0], atol=1e-6)
    np.testing.assert_allclose(lens[:, 0, 1], [0.6, 0.4, 0.2, 1.0], atol=1e-6)
    assert lens[3, 0, 2] == 2.0


def test_colour_penalty_breaks_the_in_focus_checkers_tie():
    """A grey checkerboard of 2-lens squares in focus: the per-colour fits explain its samples exactly at d = 0 (grey)
    and at d = +-2 (red and blue white, green black), and without the penalty noise chose among them (about a third
    of the lenses each at 2 lux, confidence 0.06). With it, every lens takes d = 0, confidently (docs/depth.md)."""
    from lfcl.evaluation.evaluate import simulation_capture
    from lfcl.noise.model import from_noise_profile
    from lfcl.sim.periodic import Checker
    from lfcl.solvers.epi import epi_depth_options

    capture = simulation_capture(simulate(planes=[Plane("checker", 0.0, Checker(2.0, (0.05,) * 3, (0.95,) * 3,
                                                                                (0.3, 0.7)))],
                                          lenses=(24, 24), lux=2, seed=3))
    noise = from_noise_profile(capture.noise_profile, capture.mosaic)
    options = epi_depth_options(noise.sigma)
    found = {}
    for colour in (0.0, options.get("colour", DEFAULTS["colour"])):
        depth = estimate_disparity(capture.mosaic, capture.pattern, capture.pitch, noise=noise,
                                   **{**options, "colour": colour})
        inner = np.abs(depth.disparity[4:-4, 4:-4])
        found[colour] = float(np.mean(inner < 0.1)), float(depth.confidence[4:-4, 4:-4].mean())
    (share_off, _), (share_on, confidence_on) = found.values()
    assert share_off < 0.6 and share_on > 0.99 and confidence_on > 0.9, found


def _pure_colour_lenses():
    """A noise-free GRBG mosaic of 6x6 lenses of 9x9 in a checkerboard of pure red and pure blue lenses whose lit
    channel is clipped (1.0), the other samples dark (0.02; each lens's centre pixel, the cost's reference, green)."""
    S = T = 6
    red_lens = np.repeat(np.repeat(np.add.outer(np.arange(S), np.arange(T)) % 2 == 0, 9, 0), 9, 1)
    rows, cols = np.arange(9 * S) % 2, np.arange(9 * T) % 2
    mosaic = np.full((9 * S, 9 * T), 0.02, np.float32)
    mosaic[(rows[:, None] == 0) & (cols[None, :] == 1) & red_lens] = 1.0
    mosaic[(rows[:, None] == 1) & (cols[None, :] == 0) & ~red_lens] = 1.0
    return mosaic


def test_clipped_samples_bound_the_fit_from_below(runtime):
    """Pure red and blue lenses whose lit channel clips: with the clipped samples left out, a candidate whose lines
    cross from a red lens into its blue neighbours (d = 0.5) explains the dark samples as well as d = 0 (the red
    lens's own), and the clipped red samples it also gathers say nothing. Their bound (lfcl.depth.cost, "Clipped
    samples") makes it pay; d = 0, whose red samples are all clipped, pays nothing. Device and twin agree both ways."""
    mosaic = _pure_colour_lenses()
    ds = np.array([0.0, 0.5], np.float32)
    for clipped in (True, False):
        want = cost_volume_np(mosaic, "GRBG", 9, ds, noise=(1e-3, 1e-5), saturation=0.99, clipped=clipped)
        got = CostVolume(runtime, mosaic.shape, "GRBG", 9, ds, clipped=clipped).forward(
            runtime.to_device(mosaic), (1e-3, 1e-5), 0.99).get()
        # atol: noise-free samples 0.98 away from a lens's reference pixel (clipped where the centre pixel is the lit
        # colour) cancel to within ~0.7 noise units in float32, with or without the bound.
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1.0)
        rise = want[0, 1] - want[0, 0]  # excess at d = 0.5 less that at d = 0, per lens
        inner = rise[2:4, 2:4]
        if clipped:
            assert inner.min() > 1000, inner
        else:
            assert np.abs(inner).max() < 10, inner


def two_planes(S, T, d_front, d_back, seed=0):
    """A dead-leaves square (d_front) over a dead-leaves background (d_back) and its true disparity map."""
    streams = np.random.SeedSequence([seed, 77]).spawn(2)
    rect = (0.25 * S, 0.25 * T, 0.75 * S, 0.75 * T)
    planes = [Plane("front", d_front, DeadLeavesTexture(_texture_box(rect, d_front, S, T),
                                                        np.random.default_rng(streams[0]), r_max=S / 8), rect),
              Plane("back", d_back, DeadLeavesTexture(_texture_box(None, d_back, S, T),
                                                      np.random.default_rng(streams[1]), r_max=S / 4))]
    y, x = np.mgrid[0:S, 0:T] + 0.5
    truth = np.where(planes[0].covers(x, y), d_front, d_back)
    return planes, truth


def sensor_noise(capture, raw):
    gain, floor = capture.sensor.noise_profile()
    return NoiseEstimate(gain, floor, float(np.sqrt(gain * raw.mean() + floor)), "test")


@pytest.mark.parametrize("lux, tolerance, share", [(12.0, 0.1, 0.85), (0.5, 0.15, 0.75)])
def test_two_planes_are_recovered(lux, tolerance, share):
    S = T = 32
    planes, truth = two_planes(S, T, 0.7, -0.45)
    cap = simulate(planes=planes, lenses=(S, T), pitch=9, lux=lux, seed=2)
    raw = cap.normalised_raw()
    depth = estimate_disparity(raw, cap.pattern, 9, noise=sensor_noise(cap, raw))
    assert depth.disparity.shape == depth.confidence.shape == (S, T)
    assert depth.disparity.dtype == depth.confidence.dtype == np.float32
    inner = np.zeros((S, T), bool)  # away from the occlusion edge and the frame
    inner[3:-3, 3:-3] = True
    edge = np.zeros((S, T), bool)
    edge[6:26, 6:26] = True
    edge[10:22, 10:22] = False
    inner &= ~edge
    good = np.abs(depth.disparity - truth) <= tolerance
    assert good[inner].mean() >= share, good[inner].mean()
    # Both planes' medians within a tenth of their disparity.
    assert abs(np.median(depth.disparity[10:22, 10:22]) - 0.7) < 0.1
    assert abs(np.median(depth.disparity[:4, :]) + 0.45) < 0.1


def test_flat_scene_has_low_confidence_and_finite_output(rng):
    S, T, U, V = 12, 10, 9, 9
    mosaic = (0.2 + 0.004 * rng.standard_normal((S * U, T * V))).astype(np.float32)
    depth = estimate_disparity(mosaic, "GRBG", 9, noise=NoiseEstimate(0.0, 0.004**2, 0.004, "test"))
    assert np.all(np.isfinite(depth.disparity)) and np.all(np.isfinite(depth.confidence))
    assert depth.confidence.max() <= 1 and depth.confidence.min() >= 0
    assert np.median(depth.confidence) < 0.2
    # A textured scene, for contrast, is trusted.
    planes, _ = two_planes(S, T, 0.4, 0.4)
    cap = simulate(planes=planes, lenses=(S, T), pitch=9, lux=12, seed=1)
    raw = cap.normalised_raw()
    textured = estimate_disparity(raw, cap.pattern, 9, noise=sensor_noise(cap, raw))
    assert np.median(textured.confidence) > max(0.3, np.median(depth.confidence) + 0.2)


def test_saturated_scene_is_unknown():
    mosaic = np.ones((5 * 9, 6 * 9), np.float32)
    depth = estimate_disparity(mosaic, "RGGB", 9, noise=NoiseEstimate(1e-4, 1e-6, 0.01, "test"))
    assert np.all(depth.confidence == 0)
    assert np.all(np.isfinite(depth.disparity))


@pytest.mark.parametrize("lenses, pitch", [((1, 1), (9, 9)), ((3, 5), (9, 9)), ((5, 2), (7, 5)), ((2, 3), (4, 4))])
def test_tiny_and_odd_sizes_give_finite_output(rng, lenses, pitch):
    S, T = lenses
    U, V = pitch
    mosaic = rng.uniform(0.1, 0.5, (S * U, T * V)).astype(np.float32)
    depth = estimate_disparity(mosaic, "BGGR", pitch, origin=(1, 0))  # noise estimated (or MAD) from the raw
    assert depth.disparity.shape == (S, T)
    assert np.all(np.isfinite(depth.disparity)) and np.all(np.isfinite(depth.confidence))
    assert np.all(np.abs(depth.disparity) <= depth.dmax)


def test_numpy_backend_agrees_with_the_device(rng):
    planes, _ = two_planes(8, 8, 0.5, -0.3)
    cap = simulate(planes=planes, lenses=(8, 8), pitch=9, lux=12, seed=4)
    raw = cap.normalised_raw()
    noise = sensor_noise(cap, raw)
    options = {"dmax": 1.0, "step": 0.1}
    dev = estimate_disparity(raw, cap.pattern, 9, noise=noise, **options)
    ref = estimate_disparity(raw, cap.pattern, 9, noise=noise, backend="numpy", **options)
    np.testing.assert_allclose(dev.disparity, ref.disparity, atol=1e-3)
    np.testing.assert_allclose(dev.confidence, ref.confidence, atol=1e-3)


@pytest.mark.parametrize("bad, message", [(np.nan, "finite"), (np.inf, "finite")])
def test_non_finite_input_is_refused(bad, message):
    mosaic = np.full((18, 18), 0.3, np.float32)
    mosaic[4, 7] = bad
    with pytest.raises(ValueError, match=message):
        estimate_disparity(mosaic, "GRBG", 9)


@pytest.mark.parametrize("kwargs, message", [
    ({"pitch": 7}, "whole number"), ({"pattern": "RGBX"}, "Bayer"), ({"step": 0}, "step"),
    ({"radius": -1}, "radius"), ({"model": "cubic"}, "model"), ({"colour": -0.1}, "colour"),
    ({"colour": np.nan}, "colour"), ({"clipped": 1}, "clipped"), ({"hue": 1}, "unknown disparity options")])
def test_bad_arguments_are_refused(kwargs, message):
    args = {"pattern": "GRBG", "pitch": 9}
    args.update({k: kwargs.pop(k) for k in list(kwargs) if k in args})
    with pytest.raises(ValueError, match=message):
        estimate_disparity(np.full((18, 18), 0.3, np.float32), args["pattern"], args["pitch"], **kwargs)


def test_candidates_are_symmetric_and_include_zero():
    ds = candidates(2.0, 0.05)
    assert ds.size == 81 and ds[0] == pytest.approx(-2.0) and ds[-1] == pytest.approx(2.0) and 0.0 in ds


def test_antinous_sign_matches_the_hci_ground_truth():
    folder = shared_path("realdata", "hci_epinet", "antinous")
    gt = read_pfm(folder / "gt_disp_lowres.pfm")
    # A textured 48x48-lens crop (the left edge of the face against the background).
    s0, t0, n = 100, 150, 48
    from lfcl.sim.lightfield import load_lightfield

    lf = load_lightfield(folder)[s0:s0 + n, t0:t0 + n]
    cap = simulate(lightfield=lf, lux=12, seed=1)
    raw = cap.normalised_raw()
    depth = estimate_disparity(raw, cap.pattern, cap.geometry.pitch, noise=sensor_noise(cap, raw), dmax=3.0)
    truth = gt[s0:s0 + n, t0:t0 + n]
    corr = np.corrcoef(depth.disparity.ravel(), truth.ravel())[0, 1]
    assert corr > 0.5, corr
    assert np.corrcoef(depth.disparity.ravel(), -truth.ravel())[0, 1] < 0


def test_read_pfm_flips_bottom_up_rows(tmp_path):
    values = np.arange(6, dtype="<f4").reshape(2, 3)  # as stored: bottom row first
    path = tmp_path / "d.pfm"
    path.write_bytes(b"Pf\n3 2\n-1.0\n" + values.tobytes())
    np.testing.assert_array_equal(read_pfm(path), [[3, 4, 5], [0, 1, 2]])
    (tmp_path / "bad.pfm").write_bytes(b"P6\n")
    with pytest.raises(ValueError, match="not a PFM"):
        read_pfm(tmp_path / "bad.pfm")


def test_hci_metrics_on_hand_made_arrays():
    truth = np.zeros((2, 5))
    estimate = np.array([[0.0, 0.05, 0.08, 0.12, -0.2], [0.07, 0.1, -0.09, 0.0, 1.0]])
    # errors > 0.07: 0.08, 0.12, 0.2, 0.1, 0.09, 1.0 -> 6 of 10; > 0.1: 0.12, 0.2, 1.0 -> 3 of 10
    assert badpix(estimate, truth, 0.07) == pytest.approx(60.0)
    assert badpix(estimate, truth, 0.1) == pytest.approx(30.0)
    squares = np.array([0, 0.05, 0.08, 0.12, 0.2, 0.07, 0.1, 0.09, 0, 1.0]) ** 2
    assert mse100(estimate, truth) == pytest.approx(100 * squares.mean())
    mask = np.zeros((2, 5), bool)
    mask[0, :2] = True
    assert depth_scores(estimate, truth, mask) == {"badpix_0.07": 0.0, "badpix_0.1": 0.0,
                                                   "mse_x100": pytest.approx(100 * 0.05**2 / 2)}
    with pytest.raises(ValueError, match="shapes"):
        badpix(estimate, truth[:, :3])


def test_disparity_map_metadata_says_units_and_sign():
    meta = estimate_disparity(np.full((18, 27), 0.3, np.float32), "GRBG", 9, dmax=1.0, step=0.1).as_dict()
    assert meta["units"] == "lenses per view step"
    assert "s - d (u - uc)" in meta["sign"]
    assert meta["search_range"] == [-1.0, 1.0] and meta["step"] == pytest.approx(0.1)
    assert meta["lenses"] == [2, 3]
    json.dumps(meta)  # plain JSON for the file headers


def test_process_writes_the_depth_files(tmp_path):
    import OpenImageIO as oiio
    from click.testing import CliRunner

    from lfcl.cli import cli

    capture = tmp_path / "capture"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "deadleaves", "--lenses", "10x12", "--lux", "12",
                                      "--seed", "3", "-o", str(capture)])
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["process", str(capture / "raw.dng"), "--pitch", "9", "--method", "malvar",
                                      "--outputs", "center,depth", "-o", str(out), "--json"])
    assert result.exit_code == 0, result.output
    for name in ("depth.exr", "depth_confidence.exr", "depth.png", "center.exr"):
        assert (out / name).is_file(), name
    buf = oiio.ImageBuf(str(out / "depth.exr"))
    spec = buf.spec()
    assert (spec.height, spec.width, spec.nchannels) == (10, 12, 1)
    meta = json.loads(spec.getattribute("lfcl:depth"))
    assert meta["units"] == "lenses per view step" and "HCI" in meta["sign"]
    pixels = np.asarray(buf.get_pixels(oiio.FLOAT))
    assert np.all(np.isfinite(pixels)) and np.all(np.abs(pixels) <= meta["search_range"][1])
    conf = np.asarray(oiio.ImageBuf(str(out / "depth_confidence.exr")).get_pixels(oiio.FLOAT))
    assert conf.min() >= 0 and conf.max() <= 1
    png = oiio.ImageBuf(str(out / "depth.png")).spec()
    assert (png.height, png.width, png.nchannels) == (10, 12, 3)
    lo, hi = json.loads(png.getattribute("lfcl:preview_range"))
    assert lo < hi
    summary = json.loads((out / "summary.json").read_text())
    assert "depth.exr" in summary["outputs"]



def test_same_raw_same_depth_bytes_and_strict_json(tmp_path):
    # Two default runs (auto: admm-epi in this light) write the same bytes (no timings in the files' headers), and
    # every JSON they write parses strictly: JSON has no NaN or Infinity (the safety net's k was Infinity).
    import OpenImageIO as oiio
    from click.testing import CliRunner

    from lfcl.cli import cli

    def strict(text):
        def refuse(constant):
            raise AssertionError(f"not JSON: {constant}")
        return json.loads(text, parse_constant=refuse)

    capture = tmp_path / "capture"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "charts", "--lenses", "24x26", "--lux", "2",
                                      "--seed", "3", "-o", str(capture)])
    assert result.exit_code == 0, result.output
    runs = [tmp_path / "a", tmp_path / "b"]
    for out in runs:
        result = CliRunner().invoke(cli, ["process", str(capture / "raw.dng"), "--outputs", "center,depth",
                                          "-o", str(out), "--json"])
        assert result.exit_code == 0, result.output
        printed = strict(result.output)
    assert printed["parameters"]["auto"]["method"] == "admm-epi"
    summary = strict((runs[0] / "summary.json").read_text())
    assert summary["parameters"]["safety_net"]["k"] is None
    for name in ("depth.exr", "depth_confidence.exr", "depth.png", "center.exr", "center.png"):
        assert (runs[0] / name).read_bytes() == (runs[1] / name).read_bytes(), name
        strict(oiio.ImageBuf(str(runs[0] / name)).spec().getattribute("ImageDescription"))


def test_smoothing_fills_unknown_lenses_from_their_neighbours(rng):
    # A textured field at d = 0.6 with a flat (texture-less) square in the middle: its inner lenses are
    # unknown; smoothing moves them towards their neighbours and leaves the confident lenses alone.
    S = T = 20
    planes, _ = two_planes(S, T, 0.6, 0.6)
    cap = simulate(planes=planes, lenses=(S, T), pitch=9, lux=12, seed=5)
    raw = cap.normalised_raw()
    raw.reshape(S, 9, T, 9)[7:13, :, 7:13, :] = 0.2 + 0.003 * rng.standard_normal((6, 9, 6, 9))
    noise = sensor_noise(cap, raw)
    plain = estimate_disparity(raw, cap.pattern, 9, noise=noise, radius=1)
    smooth = estimate_disparity(raw, cap.pattern, 9, noise=noise, radius=1, smooth=1.0)
    hole = (slice(9, 11), slice(9, 11))
    assert plain.confidence[hole].max() < 0.2
    np.testing.assert_array_equal(smooth.confidence, plain.confidence)  # confidence stays the step-3 one
    assert np.all(np.isfinite(smooth.disparity))
    sure = plain.confidence > 0.98
    assert sure.sum() >= 10
    assert np.abs(smooth.disparity - plain.disparity)[sure].max() < 0.05
    # The unknown lenses take a weighted mean of their neighbours: inside their range, and moved.
    ring = plain.disparity[8:12, 8:12].copy()
    ring[1:3, 1:3] = np.nan
    assert np.nanmin(ring) - 1e-3 <= smooth.disparity[hole].min() <= smooth.disparity[hole].max() <= np.nanmax(ring) + 1e-3
    assert np.abs(smooth.disparity[hole] - plain.disparity[hole]).max() > 1e-3


# The kernel takes 8 lenses of a row at once: rows of 16 and 27 lenses hold whole blocks inside the frame, blocks
# whose window runs past a side, and a last block of 3.
@pytest.mark.parametrize("planes, lenses, radius", [(1, (1, 1), 0), (3, (5, 7), 1), (4, (9, 6), 4), (2, (3, 2), 4),
                                                    (19, (4, 5), 2), (9, (3, 16), 2), (5, (6, 27), 4)])
def test_device_window_aggregation_matches_numpy(runtime, rng, planes, lenses, radius):
    from lfcl.depth.cost import WindowAggregate, aggregate_window_np, window_offsets

    maps = rng.standard_normal((planes, *lenses)).astype(np.float32)
    weights = rng.random(((2 * radius + 1) ** 2, *lenses)).astype(np.float32)
    expected = aggregate_window_np(maps.astype(np.float64), window_offsets(radius), weights.astype(np.float64))
    got = WindowAggregate(runtime, planes, lenses, radius).forward(runtime.to_device(maps),
                                                                   runtime.to_device(weights)).get()
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)
    # By the definition: a lens's sum over its window, its own weights, lenses past the frame as 0.
    p, s, t = planes - 1, lenses[0] // 2, lenses[1] - 1
    by_hand = sum(weights[o, s, t] * maps[p, s + dy, t + dx] for o, (dy, dx) in enumerate(window_offsets(radius))
                  if 0 <= s + dy < lenses[0] and 0 <= t + dx < lenses[1])
    assert got[p, s, t] == pytest.approx(float(by_hand), rel=1e-5, abs=1e-5)
    with pytest.raises(ValueError, match="weights must be float32 of shape"):
        WindowAggregate(runtime, planes, lenses, radius).forward(runtime.to_device(maps),
                                                                 runtime.to_device(weights[:-1]))
    # Planes of a larger stack, read in place.
    stack = np.concatenate([rng.standard_normal((2, *lenses)).astype(np.float32), maps])
    got = WindowAggregate(runtime, planes, lenses, radius).forward(runtime.to_device(stack),
                                                                   runtime.to_device(weights), first=2).get()
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="no planes"):
        WindowAggregate(runtime, planes, lenses, radius).forward(runtime.to_device(stack),
                                                                 runtime.to_device(weights), first=3)


def test_depth_preview_ranges_over_the_sure_lenses_and_darkens_the_unsure():
    from matplotlib import colormaps

    from lfcl.depth.estimate import DisparityMap
    from lfcl.depth.output import UNSURE_BRIGHTNESS, preview, preview_range

    rng = np.random.default_rng(4)
    d = rng.uniform(-2, 2, (40, 50)).astype(np.float32)  # flat lenses: any candidate
    c = np.zeros_like(d)
    d[:20] = np.linspace(-0.3, 0.4, 50, dtype=np.float32)  # the scene, where the estimate is sure
    c[:20] = 1.0
    c[20:25] = 0.4  # unsure: outside the range, half-dark
    depth = DisparityMap(d, c, 2.0, 0.05, {}, {}, {})
    lo, hi = preview_range(depth)
    sure = d[c >= 0.5]
    assert (lo, hi) == tuple(float(v) for v in np.percentile(sure.astype(np.float64), [1, 99]))
    assert -0.31 < lo < hi < 0.41
    image = preview(depth)
    colour = colormaps["viridis"](np.clip((d.astype(np.float64) - lo) / (hi - lo), 0, 1))[..., :3]
    np.testing.assert_allclose(image[:20], colour[:20], atol=1e-6)  # sure: the map's colour
    np.testing.assert_allclose(image[25:], UNSURE_BRIGHTNESS * colour[25:], atol=1e-6)  # unknown: darkened
    np.testing.assert_allclose(image[20:25], (UNSURE_BRIGHTNESS + 0.4 * (1 - UNSURE_BRIGHTNESS)) * colour[20:25],
                               atol=1e-6)
    # hardly any sure lens: the range of every lens
    c_few = np.zeros_like(c)
    c_few[0, :10] = 1.0  # 10 of 2000 lenses, under 1 %
    lo, hi = preview_range(DisparityMap(d, c_few, 2.0, 0.05, {}, {}, {}))
    assert (lo, hi) == tuple(float(v) for v in np.percentile(d.astype(np.float64), [1, 99]))

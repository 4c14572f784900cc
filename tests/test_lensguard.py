"""The guarded start's device half (lfcl/kernels/lensguard.cl) against its float64 references."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.ops.lensguard import LensGuard, guard_lens_means_np, lens_disagreement_np, take_lenses_np


def test_disagreement_is_the_rms_difference_in_noise_sigmas():
    mosaic = np.full((18, 27), 0.25)  # 2x3 lenses of 9x9
    a, b = np.zeros((3, 18, 27)), np.zeros((3, 18, 27))
    a[1, 9:18, 0:9] = 0.06  # lens (1, 0): one colour of three differs by 0.06 everywhere
    d = lens_disagreement_np(a, b, mosaic, (9, 9), gain=0.0016, floor=0.0001**2)
    expected = np.zeros((2, 3))
    expected[1, 0] = np.sqrt(0.06**2 / 3) / np.sqrt(0.0016 * 0.25 + 0.0001**2)
    np.testing.assert_allclose(d, expected, rtol=1e-12)


@pytest.mark.parametrize("pitch, lenses", [((9, 9), (5, 7)), ((5, 7), (3, 4)), ((1, 1), (4, 6))])
def test_device_disagreement_matches_the_reference(runtime, rng, pitch, lenses):
    H, W = lenses[0] * pitch[0], lenses[1] * pitch[1]
    mosaic = rng.random((H, W)).astype(np.float32) - 0.05  # some negative levels: clipped to 0
    a = rng.random((3, H, W)).astype(np.float32)
    b = (a + 0.02 * rng.standard_normal((3, H, W))).astype(np.float32)
    guard = LensGuard(runtime, (H, W), pitch)
    got = guard.disagreement(runtime.to_device(a), runtime.to_device(b), runtime.to_device(mosaic), 2e-3, 1e-6)
    expected = lens_disagreement_np(a, b, mosaic, pitch, gain=2e-3, floor=1e-6)
    np.testing.assert_allclose(got, expected, rtol=2e-5)


def test_device_disagreement_of_a_noise_free_dark_frame_stays_finite(runtime):
    zeros = np.zeros((3, 9, 18), np.float32)
    ones = np.ones((3, 9, 18), np.float32)
    guard = LensGuard(runtime, (9, 18), (9, 9))
    d = guard.disagreement(runtime.to_device(ones), runtime.to_device(zeros), runtime.to_device(zeros[0]), 0.0, 0.0)
    assert np.all(np.isfinite(d)) and np.all(d > 1e10)  # no noise at all: any difference is far beyond it


def test_device_take_copies_the_chosen_lenses_only(runtime, rng):
    pitch, (S, T) = (9, 9), (4, 5)
    x = rng.random((3, S * 9, T * 9)).astype(np.float32)
    source = rng.random((3, S * 9, T * 9)).astype(np.float32)
    chosen = rng.random((S, T)) < 0.4
    guard = LensGuard(runtime, (S * 9, T * 9), pitch)
    got = guard.take(runtime.to_device(x), runtime.to_device(source), chosen).get()
    np.testing.assert_array_equal(got, take_lenses_np(x, source, chosen, pitch))
    assert 0 < chosen.sum() < chosen.size


def test_device_guard_refuses_wrong_shapes(runtime):
    guard = LensGuard(runtime, (9, 18), (9, 9))
    planes = runtime.to_device(np.zeros((3, 9, 18), np.float32))
    with pytest.raises(ValueError, match="chosen must be a 1x2 lens mask"):
        guard.take(planes, planes, np.ones((2, 1), bool))
    with pytest.raises(ValueError, match="mosaic must be float32 of shape"):
        guard.disagreement(planes, planes, runtime.to_device(np.zeros((9, 9), np.float32)), 0.0, 0.0)
    with pytest.raises(ValueError, match="not a whole number"):
        LensGuard(runtime, (10, 18), (9, 9))


def test_lens_mean_guard_soft_thresholds_each_colour_mean_towards_malvar():
    mosaic = np.full((9, 18), 0.25)  # 1x2 lenses of 9x9; sd of a lens mean = sqrt(var / 20.25)
    gain, floor, k = 0.0016, 0.0, 3.0
    limit = k * np.sqrt(gain * 0.25 / 20.25)
    rng = np.random.default_rng(5)
    m = rng.random((3, 9, 18))
    x = m + 0.01 * rng.standard_normal((3, 9, 18))  # texture of x kept, only its lens means move
    x[:, :, :9] -= x[:, :, :9].mean(axis=(1, 2), keepdims=True) - m[:, :, :9].mean(axis=(1, 2), keepdims=True)
    x[0, :, :9] += 0.5 * limit  # lens 0, red: within the limit -> Malvar's mean
    x[1, :, 9:] -= x[1, :, 9:].mean() - m[1, :, 9:].mean() - 3 * limit  # lens 1, green: 3 limits off -> 2 left
    out, replaced = guard_lens_means_np(x, m, mosaic, (9, 9), gain=gain, floor=floor, k=k)
    means = lambda a: a.reshape(3, 9, 2, 9).mean(axis=(1, 3))  # noqa: E731
    np.testing.assert_allclose(means(out)[0, 0], means(m)[0, 0], atol=1e-12)
    np.testing.assert_allclose(means(out)[1, 1] - means(m)[1, 1], 2 * limit, rtol=1e-9)
    spread = lambda a: a - np.repeat(np.repeat(means(a), 9, axis=1)[:, None], 9, axis=1)  # noqa: E731
    np.testing.assert_allclose(spread(out), spread(x), atol=1e-12)  # the texture inside each lens is x's
    assert replaced.tolist() == [[3.0, 2.0]]


def test_lens_mean_guard_fills_a_flat_lens_whose_malvar_means_read_another_lens():
    mosaic = np.full((9, 27), 0.25)  # 1x3 lenses; sd of a lens mean = sqrt(var / 20.25)
    gain, floor, k, j = 0.0016, 0.0, 3.0, 1.0
    sd = np.sqrt(gain * 0.25 / 20.25)
    rng = np.random.default_rng(6)
    m = rng.random((3, 9, 27))
    x = m + 0.01 * rng.standard_normal((3, 9, 27))
    means = lambda a: a.reshape(3, 9, 3, 9).mean(axis=(1, 3))  # noqa: E731
    own = np.moveaxis(means(m), 0, -1)[None].copy()  # [1, 3, 3]: Malvar's means, moved below
    own[0, 0, 1] += 1.5 * sd  # lens 0: flat, green 1.5 sd from Malvar's -> filled with its own means
    own[0, 1] += 0.5 * sd  # lens 1: flat, every colour within j sd -> the soft threshold
    own[0, 2, 0] += 5 * sd  # lens 2: far off, but not flat -> the soft threshold
    flat = np.array([[True, True, False]])
    out, replaced = guard_lens_means_np(x, m, mosaic, (9, 9), gain=gain, floor=floor, k=k, flat=flat,
                                        flat_means=own, j=j)
    np.testing.assert_allclose(out[:, :, :9], np.broadcast_to(own[0, 0][:, None, None], (3, 9, 9)), atol=1e-12)
    plain, plain_replaced = guard_lens_means_np(x, m, mosaic, (9, 9), gain=gain, floor=floor, k=k)
    np.testing.assert_allclose(out[:, :, 9:], plain[:, :, 9:], atol=1e-12)
    assert replaced[0, 0] == -1 and replaced[0, 1:].tolist() == plain_replaced[0, 1:].tolist()
    never, _ = guard_lens_means_np(x, m, mosaic, (9, 9), gain=gain, floor=floor, k=k, flat=flat, flat_means=own,
                                   j=np.inf)  # j = inf: no lens is filled, the net of before
    np.testing.assert_array_equal(never, plain)


@pytest.mark.parametrize("pitch, lenses", [((9, 9), (5, 7)), ((5, 7), (3, 4)), ((1, 1), (4, 6))])
@pytest.mark.parametrize("k, j", [(2.0, 1.0), (2.0, np.inf), (np.inf, 1.0)])
def test_device_lens_mean_guard_matches_the_reference(runtime, rng, pitch, lenses, k, j):
    H, W = lenses[0] * pitch[0], lenses[1] * pitch[1]
    mosaic = rng.random((H, W)).astype(np.float32) - 0.05
    m = rng.random((3, H, W)).astype(np.float32)
    x = (m + 0.05 * rng.standard_normal((3, H, W))).astype(np.float32)
    flat = rng.random(lenses) < 0.5
    m_means = np.moveaxis(m.astype(np.float64).reshape(3, lenses[0], pitch[0], lenses[1], pitch[1]).mean(axis=(2, 4)),
                          0, -1)
    # own means 0-2 sds (of a lens mean at level 0.45) from Malvar's: some flat lenses past j, some within
    own = (m_means + rng.uniform(-2, 2, m_means.shape) * np.sqrt((2e-3 * 0.45 + 1e-4) / (0.25 * pitch[0] * pitch[1])))
    own = own.astype(np.float32)
    guard = LensGuard(runtime, (H, W), pitch)
    x_dev = runtime.to_device(x)
    replaced = guard.guard_means(x_dev, runtime.to_device(m), runtime.to_device(mosaic), 2e-3, 1e-4, k, flat, own, j)
    expected, expected_replaced = guard_lens_means_np(x, m, mosaic, pitch, gain=2e-3, floor=1e-4, k=k, flat=flat,
                                                      flat_means=own, j=j)
    np.testing.assert_allclose(x_dev.get(), expected, atol=2e-6)
    np.testing.assert_array_equal(replaced, expected_replaced)
    filled = expected_replaced < 0
    if np.isfinite(j):  # flat lenses past j and within it occur
        assert 0 < filled.sum() < flat.sum()
    else:
        assert not filled.any()
    if np.isfinite(k) and np.isinf(j):  # both kinds of soft-thresholded lens occur
        assert 0 < expected_replaced.sum() < 3 * expected_replaced.size
    elif np.isinf(k):  # no soft threshold: every lens not filled is x's own
        assert (expected_replaced[~filled] == 0).all()
        per_pixel = np.repeat(np.repeat(filled, pitch[0], axis=0), pitch[1], axis=1)
        np.testing.assert_array_equal(expected[:, ~per_pixel], x[:, ~per_pixel])


@pytest.mark.parametrize("weight", [1.0, 0.5, 0.0])
def test_colour_differences_from_keeps_the_level_and_takes_the_colour(runtime, rng, weight):
    """The start's level (the mean of its three colours) stays; its colour differences move by ``weight`` towards the
    other's: by the definition, the twin, and the device against the twin."""
    from lfcl.ops.lensguard import colour_differences_from_np

    x = rng.random((3, 18, 27))
    m = rng.random((3, 18, 27))
    got = colour_differences_from_np(x, m, weight)
    np.testing.assert_allclose(got.mean(axis=0), x.mean(axis=0), atol=1e-12)  # the level kept
    for a, b in ((0, 1), (2, 1)):
        np.testing.assert_allclose(got[a] - got[b], (1 - weight) * (x[a] - x[b]) + weight * (m[a] - m[b]), atol=1e-12)
    x32, m32 = x.astype(np.float32), m.astype(np.float32)
    guard = LensGuard(runtime, (18, 27), (9, 9))
    device = guard.colour_differences_from(runtime.to_device(x32), runtime.to_device(m32), weight).get()
    np.testing.assert_allclose(device, colour_differences_from_np(x32, m32, weight), atol=1e-6)


def test_guarded_start_takes_malvars_colour_differences_when_asked(runtime, rng):
    """``malvar_colour`` 1: the guarded start's level stays and its colour differences are Malvar's; 0.5: half way
    (and the report says which); a share outside [0, 1] is refused."""
    from lfcl.demosaic.guarded_start import guarded_start
    from lfcl.noise.model import NoiseEstimate

    H, W = 27, 36
    mosaic = (0.3 + 0.01 * rng.standard_normal((H, W))).astype(np.float32)
    linear4d = (0.3 + 0.02 * rng.standard_normal((3, H, W))).astype(np.float32)
    malvar = (0.3 + 0.02 * rng.standard_normal((3, H, W))).astype(np.float32)
    noise = NoiseEstimate(gain=1e-4, floor=1e-5, sigma=0.005, source="test")

    def start(share):
        return guarded_start(runtime, runtime.to_device(linear4d.copy()), runtime.to_device(malvar),
                             runtime.to_device(mosaic), (9, 9), noise, malvar_colour=share)

    (plain, report), (full, full_report), (half, _) = start(0.0), start(1.0), start(0.5)
    plain, full, half = plain.get(), full.get(), half.get()
    assert report["malvar_colour"] == 0.0 and full_report["malvar_colour"] == 1.0
    for got in (full, half):
        np.testing.assert_allclose(got.mean(axis=0), plain.mean(axis=0), atol=1e-6)
    for a, b in ((0, 1), (2, 1)):
        np.testing.assert_allclose(full[a] - full[b], malvar[a] - malvar[b], atol=1e-6)
        np.testing.assert_allclose(half[a] - half[b], 0.5 * (plain[a] - plain[b] + malvar[a] - malvar[b]), atol=1e-6)
    assert np.abs((plain[0] - plain[1]) - (malvar[0] - malvar[1])).max() > 0.01  # it did change them
    for bad in (-0.1, 1.5, "malvar"):
        with pytest.raises(ValueError, match="malvar_colour must be a number"):
            start(bad)

"""Shift-and-add refocusing (lfcl.outputs.refocus) against a per-sample numpy reference and a known plane."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lfcl.outputs.refocus import focal_stack, parse_slopes, refocus, slope_label


def reference_refocus(lf: np.ndarray, slope: float) -> np.ndarray:
    """The definition, one output pixel and one bilinear tap at a time."""
    S, T, U, V, C = lf.shape
    u0, v0 = U // 2, V // 2
    out = np.zeros((S, T, C))
    for s in range(S):
        for t in range(T):
            acc, wsum = np.zeros(C), 0.0
            for u in range(U):
                for v in range(V):
                    y, x = s + slope * (u - u0), t + slope * (v - v0)
                    y0, x0 = math.floor(y), math.floor(x)
                    fy, fx = y - y0, x - x0
                    for yy, wy in ((y0, 1 - fy), (y0 + 1, fy)):
                        for xx, wx in ((x0, 1 - fx), (x0 + 1, fx)):
                            w = wy * wx
                            if w > 0 and 0 <= yy < S and 0 <= xx < T:
                                acc += w * lf[yy, xx, u, v]
                                wsum += w
            out[s, t] = acc / wsum
    return out


def texture(y, x):
    """A smooth, non-periodic texture (3 channels)."""
    return np.stack([0.5 + 0.2 * np.sin(0.31 * y + 0.17 * x) + 0.1 * np.cos(0.23 * x),
                     0.4 + 0.25 * np.cos(0.19 * y - 0.29 * x),
                     0.3 + 0.15 * np.sin(0.41 * x) * np.cos(0.13 * y)], axis=-1)


def plane_lightfield(S, T, U, V, d, tex=texture):
    """A fronto-parallel plane of disparity d: L(s, t, u, v) = tex(s - d (u - u0), t - d (v - v0))."""
    s, t, u, v = np.meshgrid(np.arange(S), np.arange(T), np.arange(U), np.arange(V), indexing="ij")
    return tex(s - d * (u - U // 2), t - d * (v - V // 2)).astype(np.float32)


@pytest.mark.parametrize("slope", [0.0, 0.25, -0.6, 1.0, 1.7])
def test_refocus_matches_the_reference(rng, slope):
    lf = rng.random((7, 8, 5, 5, 3)).astype(np.float32)
    np.testing.assert_allclose(refocus(lf, slope), reference_refocus(lf, slope), rtol=0, atol=2e-6)


def test_slope_zero_is_the_mean_image(rng):
    lf = rng.random((6, 9, 5, 5, 3)).astype(np.float32)
    np.testing.assert_allclose(refocus(lf, 0.0), lf.mean(axis=(2, 3)), atol=1e-6)


@pytest.mark.parametrize("d", [1.0, -1.0, 2.0])
def test_integer_disparity_plane_comes_back_sharp_exactly(d):
    S, T, U, V = 40, 44, 9, 9
    lf = plane_lightfield(S, T, U, V, d)
    focused = refocus(lf, d)
    m = math.ceil(abs(d) * (U // 2))  # every sample inside from here on
    s, t = np.meshgrid(np.arange(S), np.arange(T), indexing="ij")
    truth = texture(s, t)
    np.testing.assert_allclose(focused[m:S - m, m:T - m], truth[m:S - m, m:T - m], atol=1e-5)


def test_plane_sharp_at_its_disparity_blurred_at_zero():
    S, T, U, V, d = 48, 48, 9, 9, 0.5
    lf = plane_lightfield(S, T, U, V, d)
    s, t = np.meshgrid(np.arange(S), np.arange(T), indexing="ij")
    truth = texture(s, t)
    inner = (slice(4, S - 4), slice(4, T - 4))
    err_focus = np.sqrt(np.mean((refocus(lf, d)[inner] - truth[inner]) ** 2))
    err_zero = np.sqrt(np.mean((refocus(lf, 0.0)[inner] - truth[inner]) ** 2))
    err_wrong = np.sqrt(np.mean((refocus(lf, -d)[inner] - truth[inner]) ** 2))
    # half-lens shifts: bilinear interpolation of a smooth texture, nearly exact
    assert err_focus < 2e-3
    assert err_zero > 10 * err_focus and err_wrong > err_zero
    # the blur at slope 0 is the texture averaged over the aperture: lower contrast than the truth
    assert refocus(lf, 0.0)[inner].std() < 0.95 * truth[inner].std()


def test_focal_stack_picks_the_disparity():
    S, T, U, V, d = 40, 40, 9, 9, 0.75
    rng = np.random.default_rng(5)
    noise_tex = rng.random((200, 200, 3))

    def tex(y, x):  # a sharp texture (bilinear from a random grid, origin in the middle)
        from scipy.ndimage import map_coordinates

        coords = [y + 80, x + 80]
        return np.stack([map_coordinates(noise_tex[..., c], coords, order=1) for c in range(3)], axis=-1)

    lf = plane_lightfield(S, T, U, V, d, tex)
    slopes = parse_slopes("-1:1:0.25")
    stack = focal_stack(lf, slopes)
    inner = (slice(6, S - 6), slice(6, T - 6))
    sharpness = [float(np.mean(np.abs(np.diff(img[inner], axis=0))) + np.mean(np.abs(np.diff(img[inner], axis=1))))
                 for img in stack]
    assert slopes[int(np.argmax(sharpness))] == d


def test_constant_lightfield_stays_constant_at_the_borders():
    lf = np.full((5, 6, 9, 9, 3), 0.37, np.float32)
    for slope in (-2.3, -0.5, 0.3, 1.0, 7.5):
        np.testing.assert_allclose(refocus(lf, slope), 0.37, atol=1e-6)


@settings(max_examples=25, deadline=None)
@given(slope=st.floats(-3, 3, allow_nan=False), seed=st.integers(0, 2**16))
def test_refocus_is_a_weighted_mean(slope, seed):
    lf = np.random.default_rng(seed).random((4, 5, 3, 3, 3)).astype(np.float32)
    out = refocus(lf, slope)
    assert out.shape == (4, 5, 3) and out.dtype == np.float32
    assert np.all(out >= lf.min() - 1e-6) and np.all(out <= lf.max() + 1e-6)
    np.testing.assert_allclose(out, reference_refocus(lf, slope), atol=2e-6)


@pytest.mark.parametrize("spec,expected", [
    ("-1:1:0.25", [-1, -0.75, -0.5, -0.25, 0, 0.25, 0.5, 0.75, 1]),
    ("0:1:0.3", [0, 0.3, 0.6, 0.9]),
    ("1:-1:-1", [1, 0, -1]),
    ("0.5:0.5:1", [0.5]),
    ("0.5, -0.5,2", [0.5, -0.5, 2]),
    ("0,0,1", [0, 1]),
    ("0.1:0.3:0.1", [0.1, 0.2, 0.3]),
])
def test_parse_slopes(spec, expected):
    assert parse_slopes(spec) == pytest.approx(expected)


@pytest.mark.parametrize("spec,message", [
    ("", "empty"), ("1:2", "start:stop:step"), ("0:1:0", "must not be 0"), ("1:0:0.5", "never gets"),
    ("a,b", "not a number"), ("0:1:1e-6", "at most"), ("1,,2", "not a number"), ("nan", "not a number"),
])
def test_parse_slopes_rejects(spec, message):
    with pytest.raises(ValueError, match=message) as info:
        parse_slopes(spec)
    assert "\n" not in str(info.value)


def test_slope_labels():
    assert [slope_label(a) for a in (0.25, -1, 0, -0.0, 1.5, 0.125)] == ["+0.25", "-1", "+0", "+0", "+1.5", "+0.125"]

"""The cross-lens ratio (lfcl/demosaic/lens_ratio.py) against a plain loop, and what auto does with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfcl.demosaic.auto import choose, fit_rule
from lfcl.demosaic.lens_ratio import BAND_ROWS, cross_lens_ratio
from lfcl.grid.vignetting import DEFAULT_THRESHOLD
from lfcl.noise.model import NoiseEstimate

NOISE = NoiseEstimate(gain=2e-4, floor=1e-6, sigma=0.01, source="raw")


def ratio_loop(mosaic, pitch, noise, lens_response=None, lens_rows=None):
    """The definition, one pair at a time, in float64 (None unless both excesses are positive)."""
    U, V = pitch
    S, T = mosaic.shape[0] // U, mosaic.shape[1] // V
    response = np.ones((U, V)) if lens_response is None else np.asarray(lens_response, np.float64)
    lit = response >= (0 if lens_response is None else DEFAULT_THRESHOLD)

    def sample(s, t, u, v):
        raw = float(mosaic[s * U + u, t * V + v])
        g = 1 / response[u, v]
        return raw * g, (noise.gain * max(raw, 0) + noise.floor) * g * g

    rows = range(S) if lens_rows is None else lens_rows
    excess = {"within": [], "across": []}
    for s in rows:
        for t in range(T):
            for u in range(U):
                for v in range(V):
                    if not lit[u, v]:
                        continue
                    a, va = sample(s, t, u, v)
                    for kind, (s2, t2, u2, v2) in (("within", (s, t, u + 2, v)), ("within", (s, t, u, v + 2)),
                                                   ("across", (s + 2, t, u, v)), ("across", (s, t + 2, u, v))):
                        if u2 >= U or v2 >= V or s2 not in rows or t2 >= T or not lit[u2, v2]:
                            continue
                        b, vb = sample(s2, t2, u2, v2)
                        excess[kind].append((a - b) ** 2 - va - vb)
    # the pairs of both directions of a kind are pooled
    return float(np.mean(excess["across"])) / float(np.mean(excess["within"]))


def lenses_mosaic(lenses):
    S, T, U, V = lenses.shape
    return lenses.transpose(0, 2, 1, 3).reshape(S * U, T * V).astype(np.float32)


@pytest.fixture
def textured(rng):
    S, T, U, V = 7, 6, 5, 5
    base = rng.random((S + 4, T + 4)) * 0.5 + 0.2
    lenses = np.empty((S, T, U, V))
    for u in range(U):  # a plane at disparity 0.3 lens per view: lenses see shifted copies
        for v in range(V):
            shift = 0.3 * (u - U // 2), 0.3 * (v - V // 2)
            rows = np.clip(np.arange(S) + 2 + shift[0], 0, S + 3).round().astype(int)
            cols = np.clip(np.arange(T) + 2 + shift[1], 0, T + 3).round().astype(int)
            lenses[:, :, u, v] = base[np.ix_(rows, cols)]
    return lenses_mosaic(lenses + rng.normal(0, 0.01, lenses.shape))


def test_the_ratio_is_the_definition(textured):
    expected = ratio_loop(textured, (5, 5), NOISE)
    assert 0.5 < expected < 50  # a real ratio, not a degenerate one
    assert cross_lens_ratio(textured, (5, 5), NOISE) == pytest.approx(expected, rel=1e-4)


def test_a_white_image_flat_fields_and_leaves_out_the_dark_pixels(textured):
    response = np.full((5, 5), 0.8)
    response[0, 0] = response[4, 4] = 0.05  # dark corners: out
    response[2, :] = 0.5
    shaded = (textured.reshape(7, 5, 6, 5) * response[None, :, None, :]).reshape(textured.shape)
    expected = ratio_loop(shaded, (5, 5), NOISE, response)
    assert cross_lens_ratio(shaded, (5, 5), NOISE, response) == pytest.approx(expected, rel=1e-4)
    # without the response the vignetting inside each lens reads as structure within the lens
    assert cross_lens_ratio(shaded, (5, 5), NOISE) < 0.8 * expected


def test_large_raws_are_sampled_in_evenly_spaced_bands_of_three_lens_rows(rng):
    lenses = rng.random((30, 4, 5, 5))
    mosaic = lenses_mosaic(lenses)
    got = cross_lens_ratio(mosaic, (5, 5), NOISE, max_lenses=40)  # 120 lenses: every 9th lens row starts a band
    bands = [range(s0, s0 + BAND_ROWS) for s0 in range(0, 28, BAND_ROWS * math.ceil(120 / 40))]
    sums = {"within": [0.0, 0], "across": [0.0, 0]}
    for rows in bands:
        block = mosaic[rows[0] * 5:(rows[-1] + 1) * 5]
        # one band alone: its pairs are the ones inside it
        within, across = _excess_sums(block, (5, 5))
        sums["within"][0] += within[0]
        sums["within"][1] += within[1]
        sums["across"][0] += across[0]
        sums["across"][1] += across[1]
    expected = (sums["across"][0] / sums["across"][1]) / (sums["within"][0] / sums["within"][1])
    assert got == pytest.approx(expected, rel=1e-4)


def _excess_sums(mosaic, pitch):
    U, V = pitch
    S, T = mosaic.shape[0] // U, mosaic.shape[1] // V
    lenses = mosaic.astype(np.float64).reshape(S, U, T, V).transpose(0, 2, 1, 3)
    var = NOISE.gain * np.maximum(lenses, 0) + NOISE.floor
    out = []
    for pairs in (((np.s_[:, :, 2:], np.s_[:, :, :-2]), (np.s_[:, :, :, 2:], np.s_[:, :, :, :-2])),
                  ((np.s_[2:], np.s_[:-2]), (np.s_[:, 2:], np.s_[:, :-2]))):
        terms = [((lenses[a] - lenses[b]) ** 2 - var[a] - var[b]).ravel() for a, b in pairs]
        out.append((sum(float(t.sum()) for t in terms), sum(t.size for t in terms)))
    return out


def test_what_the_ratio_tells_apart(rng):
    noise = NoiseEstimate(gain=0.0, floor=1e-4, sigma=0.01, source="raw")
    flat_lenses = rng.random((12, 12, 1, 1)) * np.ones((1, 1, 5, 5))  # each lens one value: the in-focus case
    flat_lenses[:, :, :, 2] += 0.2  # and a stripe in each, so that within-lens differences are not noise alone
    assert cross_lens_ratio(lenses_mosaic(flat_lenses + rng.normal(0, 0.01, flat_lenses.shape)), (5, 5), noise) > 5
    same_lenses = rng.random((1, 1, 5, 5)) * np.ones((12, 12, 1, 1))  # every lens alike: a far, flat scene
    assert cross_lens_ratio(lenses_mosaic(same_lenses + rng.normal(0, 0.01, same_lenses.shape)), (5, 5), noise) is None
    pure_noise = rng.normal(0.3, 0.01, (60, 60)).astype(np.float32)
    assert cross_lens_ratio(pure_noise, (5, 5), noise) is None  # neither difference above the noise
    assert cross_lens_ratio(pure_noise[:10], (5, 5), noise) is None  # two lens rows: no pair two lenses apart


def _rule_row(sigma, ratio):
    return {"capture": "charts 1", "sigma": sigma, "lens_ratio": ratio,
            "malvar": {"center": 40.0, "mean": 45.0, "seconds": 0.01},
            "gains": {"admm-uv@1": {"center": 1.0, "mean": 0.5, "seconds": 0.1}}}


def test_auto_says_when_the_content_lies_outside_what_its_band_was_fitted_on():
    rule = fit_rule([_rule_row(0.005, 3.0), _rule_row(0.0052, 40.0), _rule_row(0.0051, None)], "both")
    assert rule[0]["lens_ratio_range"] == [3.0, 40.0]
    inside = choose(0.005, rule, lens_ratio=6.0)
    assert inside.seen_content is True and "has not seen" not in inside.reason
    outside = choose(0.005, rule, lens_ratio=1.2)
    assert outside.method == inside.method and outside.seen_content is False
    assert "cross-lens ratio 1.20 lies outside the 3.00-40.00" in outside.reason
    unknown = choose(0.005, rule)
    assert unknown.lens_ratio is None and unknown.seen_content is None and unknown.reason in inside.reason


def test_auto_records_the_ratio_of_the_raw(rng):
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid

    flat_lenses = rng.random((24, 24, 1, 1)) * np.ones((1, 1, 9, 9))  # auto's smallest frame for a prior
    flat_lenses[:, :, :, 4] += 0.2
    mosaic = lenses_mosaic(flat_lenses * 0.5 + rng.normal(0, 0.004, flat_lenses.shape))
    noise = NoiseEstimate(gain=0.0, floor=0.004**2, sigma=0.004, source="raw")
    result = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "auto", noise=noise)
    auto = result.parameters["auto"]
    assert auto["lens_ratio"] == pytest.approx(cross_lens_ratio(mosaic, (9, 9), noise))
    trained = choose(noise.sigma)  # the shipped band
    assert isinstance(auto["seen_content"], bool) and trained.method == auto["method"]

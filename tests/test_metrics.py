"""Colour-artefact metrics (lfcl/evaluation/metrics.py, docs/colour-metrics.md): CIEDE2000 and false colour."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from lfcl.evaluation.evaluate import format_sweep, format_table
from lfcl.evaluation.metrics import (
    COLOUR_KEYS,
    camera_to_lab,
    centre_view,
    colour_scores,
    lab_scale,
    lightfield_colour_scores,
    mean_image,
    reference_white_xy,
)

# IEC 61966-2-1 linear sRGB -> XYZ, written out so the tests do not just repeat the module's call.
SRGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])


def lab_by_hand(rgb, scale):
    """CIE 1976 L*a*b* of linear sRGB divided by ``scale``, white = XYZ of RGB (1, 1, 1)."""
    xyz = np.asarray(rgb, np.float64) @ SRGB_TO_XYZ.T / scale
    white = SRGB_TO_XYZ.sum(axis=1)
    t = xyz / white
    delta = 6 / 29
    f = np.where(t > delta**3, np.cbrt(t), t / (3 * delta**2) + 4 / 29)
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], axis=-1)


def rgb_from_lab(lab, scale=1.0):
    """Inverse of the documented conversion (colour-science), to build test images from Lab values."""
    xyz = colour.Lab_to_XYZ(np.asarray(lab, np.float64), reference_white_xy()) * scale
    return xyz @ np.linalg.inv(SRGB_TO_XYZ).T


def grey_stripes_and_flat(size=48, period=8):
    """Left half: vertical grey stripes 0.08 / 0.5 (edges every period/2 columns); right half: flat 0.3 grey."""
    img = np.full((size, size, 3), 0.3)
    cols = np.arange(size // 2)
    img[:, : size // 2] = np.where((cols // (period // 2)) % 2 == 0, 0.08, 0.5)[None, :, None]
    return img


def add_fringe(img, columns, amount=0.03):
    """A red/green fringe: +amount on R and -amount on G in the given columns (alternating sign)."""
    out = img.copy()
    for i, c in enumerate(columns):
        sign = 1 if i % 2 == 0 else -1
        out[:, c, 0] += sign * amount
        out[:, c, 1] -= sign * amount
    return out


def textured_truth(rng, shape=(40, 44)):
    """Grey stripes over part of the frame, smooth colour gradients elsewhere."""
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]] / max(shape)
    img = np.stack([0.2 + 0.3 * xx, 0.15 + 0.2 * yy, 0.1 + 0.25 * xx * yy], axis=-1)
    img[: shape[0] // 2, : shape[1] // 2] = np.where((np.arange(shape[1] // 2) // 3) % 2, 0.05, 0.4)[None, :, None]
    return img + 0.01 * rng.random(img.shape)


def test_identical_images_score_zero(rng):
    truth = textured_truth(rng)
    scores = colour_scores(truth, truth.copy())
    assert set(scores) == set(COLOUR_KEYS)
    assert all(v == 0.0 for v in scores.values()), scores


def test_uniform_shift_matches_colour_science_ciede2000():
    truth = np.broadcast_to([0.3, 0.2, 0.1], (16, 16, 3)).copy()
    shift = np.array([0.02, -0.01, 0.005])
    scores = colour_scores(truth + shift, truth)
    scale = SRGB_TO_XYZ[1] @ truth[0, 0]  # every pixel has the same Y: that is its 99th percentile
    assert lab_scale(truth) == pytest.approx(scale, rel=1e-12)
    lab_t, lab_e = lab_by_hand(truth[0, 0], scale), lab_by_hand(truth[0, 0] + shift, scale)
    np.testing.assert_allclose(camera_to_lab(truth[:1, :1], scale)[0, 0], lab_t, atol=1e-9)
    expected = float(colour.delta_E(lab_t, lab_e, method="CIE 2000"))
    assert expected > 1
    assert scores["de2000_mean"] == pytest.approx(expected, rel=1e-9)
    assert scores["de2000_p95"] == pytest.approx(expected, rel=1e-9)
    # A flat image has no high-contrast pixels: the edge measures are undefined, not 0.
    assert scores["false_colour"] is None and scores["hf_chroma_error"] is None


def test_published_ciede2000_pair_survives_the_conversion():
    # Sharma, Wu & Dalal (2005), test pair 1: dE00 = 2.0425. A white patch (> 1 % of the pixels)
    # pins the truth's 99th percentile of Y at 1, so the Lab values come back exactly.
    truth = np.empty((20, 20, 3))
    estimate = np.empty_like(truth)
    truth[:] = rgb_from_lab([50.0, 2.6772, -79.7751])
    estimate[:] = rgb_from_lab([50.0, 0.0, -82.7485])
    truth[:10, :4] = estimate[:10, :4] = rgb_from_lab([100.0, 0.0, 0.0])
    scores = colour_scores(estimate, truth)
    assert lab_scale(truth) == pytest.approx(1.0, rel=1e-9)
    assert scores["de2000_mean"] == pytest.approx(2.0425 * 360 / 400, abs=1e-4)
    assert scores["de2000_p95"] == pytest.approx(2.0425, abs=1e-4)


def test_fringe_on_grey_edges_counts_and_in_flat_region_does_not():
    truth = grey_stripes_and_flat()
    edge_columns = [c for c in range(1, 24) if c % 4 in (0, 3)]  # both sides of every stripe edge
    flat_columns = list(range(30, 30 + len(edge_columns)))       # inside the flat right half
    on_edges = colour_scores(add_fringe(truth, edge_columns), truth)
    in_flat = colour_scores(add_fringe(truth, flat_columns), truth)
    assert on_edges["false_colour"] > 3 and on_edges["hf_chroma_error"] > 3
    assert in_flat["false_colour"] == 0.0 and in_flat["hf_chroma_error"] == 0.0
    # CIEDE2000 sees both fringes; false colour tells them apart.
    assert in_flat["de2000_mean"] > 0.5 and on_edges["de2000_mean"] > 0.5


def test_false_colour_needs_grey_edges_but_hf_chroma_error_does_not(rng):
    # Saturated colours everywhere: no achromatic pixels, so false colour is undefined (None).
    truth = np.zeros((32, 32, 3))
    truth[..., 0] = np.where((np.arange(32) // 4) % 2, 0.6, 0.1)[None, :]
    truth[..., 2] = 0.05
    scores = colour_scores(truth + 0.01 * rng.standard_normal(truth.shape), truth)
    assert scores["false_colour"] is None
    assert scores["hf_chroma_error"] > 0


@pytest.mark.parametrize("factor", [1e-3, 0.37, 25.0])
def test_invariant_to_the_common_normalisation(rng, factor):
    truth = textured_truth(rng)
    estimate = truth + 0.01 * rng.standard_normal(truth.shape)
    base = colour_scores(estimate, truth)
    scaled = colour_scores(estimate * factor, truth * factor)
    assert lab_scale(truth * factor) == pytest.approx(lab_scale(truth) * factor, rel=1e-12)
    for key in COLOUR_KEYS:
        assert scaled[key] == pytest.approx(base[key], rel=1e-9, abs=1e-12), key
    # ... but a gain error on the estimate alone is a colour/lightness error.
    assert colour_scores(estimate * 1.2, truth)["de2000_mean"] > base["de2000_mean"] + 1


@pytest.mark.parametrize("estimate_shape,truth_shape,message", [
    ((8, 8, 3), (8, 9, 3), "cannot compare shapes"),
    ((8, 8), (8, 8), "(H, W, 3)"),
    ((8, 8, 4), (8, 8, 4), "(H, W, 3)"),
    ((2, 8, 8, 3), (2, 8, 8, 3), "(H, W, 3)"),
    ((1, 8, 3), (1, 8, 3), "at least 2x2"),
])
def test_colour_scores_reject_bad_shapes(estimate_shape, truth_shape, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        colour_scores(np.ones(estimate_shape), np.ones(truth_shape))


def test_black_truth_is_an_error():
    with pytest.raises(ValueError, match="no light"):
        colour_scores(np.zeros((8, 8, 3)), np.zeros((8, 8, 3)))


def test_lightfield_colour_scores_score_centre_view_and_mean_image(rng):
    truth = rng.uniform(0.05, 0.6, (10, 12, 3, 3, 3))
    truth[:, ::2] = truth[:, ::2].mean(axis=-1, keepdims=True)  # some grey columns
    estimate = truth + 0.01 * rng.standard_normal(truth.shape)
    scores = lightfield_colour_scores(estimate, truth)
    assert set(scores) == {f"{k}_{v}" for k in COLOUR_KEYS for v in ("center", "mean")}
    for view, fn in (("center", centre_view), ("mean", mean_image)):
        expected = colour_scores(fn(estimate), fn(truth))
        for key in COLOUR_KEYS:
            assert scores[f"{key}_{view}"] == pytest.approx(expected[key], rel=1e-12), (key, view)
    with pytest.raises(ValueError, match="differ in shape"):
        lightfield_colour_scores(estimate[:, :-1], truth)
    with pytest.raises(ValueError, match=r"\[S, T, U, V, 3\]"):
        lightfield_colour_scores(truth[0], truth[0])


def test_tables_carry_the_colour_rows():
    def row(method, fc):
        scores = {f"{k}_{v}": 1.5 for k in COLOUR_KEYS for v in ("center", "mean")}
        scores["false_colour_center"] = fc
        return {"method": method, "psnr_center": 40.0, "psnr_mean": 45.0, "seconds": 0.1, "iterations": 3, **scores}

    table = format_table([row("malvar", 2.25), row("admm-uv", None)], "t")
    for label in ("ΔE00 mean (centre)", "ΔE00 p95 (centre)", "False colour (centre)", "HF chroma error (centre)",
                  "ΔE00 mean (mean image)", "ΔE00 p95 (mean image)", "False colour (mean image)"):
        assert f"| {label} |" in table
    assert "| False colour (centre) | 2.25 | n/a |" in table
    sweep = format_sweep([{"lux": 4, "results": [row("malvar", 2.25), row("admm-uv", None)]}])
    assert "Colour errors against illumination, centre" in sweep and "| 4 | 1.50 / 1.50 / 2.25 / 1.50 | 1.50 / 1.50 / n/a / 1.50 |" in sweep

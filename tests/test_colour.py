"""Camera RGB -> sRGB previews (lfcl.outputs.previews) against colour-science."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from lfcl.outputs.previews import LUMA, TARGET, ColourPipeline, d65_xyz

XYZ_TO_SRGB = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, np.float64)
# A real camera's ColorMatrix (Adobe's for the Canon EOS 5D Mark II, / 10000): camera from XYZ
CANON_5D2 = np.array([[4716, 603, -830], [-7798, 15474, 2480], [-1496, 1937, 6651]]) / 10000.0


@pytest.fixture
def rgb(rng):
    return rng.random((6, 7, 3)) * 0.8


@pytest.mark.parametrize("meta", [
    {},                                                             # no matrix at all
    {"color_matrix": np.hstack([np.eye(3), np.zeros((3, 1))])},    # rawpy rgb_cam identity (lfcl's simulator)
    {"xyz_to_camera": XYZ_TO_SRGB},                                 # ColorMatrix = XYZ -> sRGB
])
def test_camera_as_srgb_with_neutral_balance_is_colour_sciences_srgb(rgb, meta):
    pipe = ColourPipeline.from_camera(as_shot_wb=(1.0, 1.0, 1.0), **meta)
    np.testing.assert_allclose(pipe.to_linear_srgb(rgb), rgb, atol=2e-4)
    scale = 1.1
    expected = colour.cctf_encoding(np.clip(rgb * scale, 0, 1), function="sRGB")
    np.testing.assert_allclose(pipe.preview(rgb, scale), expected, atol=3e-4)
    # the same through XYZ: colour-science's own encoding of those values
    via_xyz = colour.XYZ_to_sRGB(colour.sRGB_to_XYZ(np.clip(rgb * scale, 0, 1), apply_cctf_decoding=False))
    np.testing.assert_allclose(pipe.preview(rgb, scale), via_xyz, atol=3e-4)


def test_no_matrix_is_said_in_the_metadata():
    meta = ColourPipeline.from_camera(as_shot_wb=(1, 1, 1)).metadata(2.0)
    assert any("linear sRGB" in n for n in meta["notes"]) and meta["scale"] == 2.0
    meta = ColourPipeline.from_camera(as_shot_wb=(1, 1, 1), xyz_to_camera=CANON_5D2).metadata()
    assert "notes" not in meta


def test_identity_xyz_matrix_is_xyz_scaled_to_d65(rgb):
    """Camera RGB = XYZ: the matrix is scaled so that (1, 1, 1) lands on D65 (von Kries in camera space)."""
    pipe = ColourPipeline.from_camera(as_shot_wb=(1, 1, 1), xyz_to_camera=np.eye(3))
    expected = colour.XYZ_to_sRGB(rgb * d65_xyz(), apply_cctf_encoding=False)
    np.testing.assert_allclose(pipe.to_linear_srgb(rgb), expected, atol=1e-6)
    # ... which is colour-science's "XYZ Scaling" adaptation from illuminant E to D65
    adapted = colour.XYZ_to_sRGB(rgb, illuminant=colour.XYZ_to_xy([1, 1, 1]),
                                 chromatic_adaptation_transform="XYZ Scaling", apply_cctf_encoding=False)
    np.testing.assert_allclose(pipe.to_linear_srgb(rgb), adapted, atol=1e-6)


def test_real_matrix_keeps_the_white_balanced_neutral_neutral():
    pipe = ColourPipeline.from_camera(as_shot_wb=(2.0, 1.0, 1.5), xyz_to_camera=CANON_5D2)
    grey = np.array([0.5 / 2.0, 0.5, 0.5 / 1.5])  # camera response to a grey under the as-shot light
    np.testing.assert_allclose(pipe.to_xyz(grey), 0.5 * d65_xyz(), atol=1e-9)
    # colour-science's sRGB matrix is the IEC one, rounded to 4 digits: D65 -> (1, 1, 1) within 2e-4
    np.testing.assert_allclose(pipe.to_linear_srgb(grey), [0.5, 0.5, 0.5], atol=2e-4)
    # and it is the camera matrix: XYZ of a colour = inv(ColorMatrix) @ (camera RGB scaled per channel)
    colourful = np.array([0.3, 0.2, 0.05])
    k = CANON_5D2 @ d65_xyz()
    np.testing.assert_allclose(pipe.to_xyz(colourful),
                               np.linalg.inv(CANON_5D2) @ (k * colourful * [2.0, 1.0, 1.5]), atol=1e-9)


def test_white_balance_gains_are_applied(rgb):
    gains = (1.8, 1.0, 1.4)
    pipe = ColourPipeline.from_camera(as_shot_wb=gains)
    np.testing.assert_allclose(pipe.to_linear_srgb(rgb), rgb * gains, atol=2e-4)
    cast = np.array([1 / 1.8, 1.0, 1 / 1.4]) * 0.4  # a grey seen through the as-shot cast
    out = pipe.to_linear_srgb(cast)
    np.testing.assert_allclose(out, [0.4, 0.4, 0.4], atol=2e-4)
    assert pipe.metadata()["white_balance"] == {"gains": [1.8, 1.0, 1.4], "source": "as shot"}


def test_missing_white_balance_falls_back_to_daylight_from_the_matrix():
    pipe = ColourPipeline.from_camera(as_shot_wb=None, xyz_to_camera=CANON_5D2)
    d65_in_camera = CANON_5D2 @ d65_xyz()
    np.testing.assert_allclose(pipe.to_xyz(d65_in_camera), d65_in_camera[1] * d65_xyz(), atol=1e-9)
    assert pipe.wb_source.startswith("daylight")
    assert ColourPipeline.from_camera().wb_source == "none"


def test_exposure_maps_the_99th_percentile_of_luminance_to_target(rng):
    pipe = ColourPipeline.from_camera(as_shot_wb=(1, 1, 1))
    samples = rng.random((50, 40, 3)) * 0.1
    scale = pipe.exposure(samples)
    luminance = samples.reshape(-1, 3) @ LUMA
    assert np.percentile(luminance * scale, 99) == pytest.approx(TARGET, rel=1e-3)
    assert pipe.exposure(np.zeros((4, 4, 3))) == 1.0


def test_preview_is_clipped_and_encoded(rng):
    pipe = ColourPipeline.from_camera(as_shot_wb=(1, 1, 1))
    rgb = np.array([[[-0.2, 0.5, 3.0]]])
    out = pipe.preview(rgb, 1.0)
    assert out.dtype == np.float32 and out.min() >= 0 and out.max() <= 1
    np.testing.assert_allclose(out[0, 0], [0.0, colour.cctf_encoding(0.5, function="sRGB"), 1.0], atol=3e-4)

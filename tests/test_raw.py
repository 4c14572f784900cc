"""lfcl.io.raw.read_mosaic on real files (../shared) and on small files written here.

The expected shapes, patterns and levels of the real raws are copied from
../shared/realdata/RAWPY_REPORT.txt (an independent rawpy 0.28 / LibRaw 0.22.2
run), not produced by lfcl.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from lfcl.io.raw import Mosaic, read_mosaic

SHARED = Path(os.environ.get("LFCL_SHARED", Path(__file__).resolve().parents[2] / "shared"))
REALDATA = SHARED / "realdata"
LIGHTHOUSE = SHARED / "data" / "lighthouse"


def shared_file(relative: str, root: Path = REALDATA) -> Path:
    path = root / relative
    if not SHARED.is_dir():
        pytest.skip(f"shared test data folder {SHARED} is absent (set LFCL_SHARED to point at it)")
    assert path.is_file(), f"{path} is missing from the shared data"
    return path


# file: (visible rows, cols), pattern, black (R, G, B, G2), white, raw min, raw max (whole raw),
# margins top/left -- all from RAWPY_REPORT.txt
REPORT = {
    "a2tools_quicktake/QT100_IMAGE01.QTK": ((240, 320), "GRBG", 0, 1023, 0, 1023, (0, 0)),
    "a2tools_quicktake/QT100_TEST100.QTK": ((480, 640), "GRBG", 0, 1023, 0, 1023, (0, 0)),
    "a2tools_quicktake/QT150_TEST150.QTK": ((480, 640), "GRBG", 0, 16383, 0, 16383, (0, 0)),
    "digicam_corpus/Canon_PowerShot_G2_CRW_0304.CRW": ((1720, 2312), "RGGB", 32, 1023, 29, 815, (6, 12)),
    "digicam_corpus/Canon_PowerShot_S40_CRW_0101.CRW": ((1720, 2312), "RGGB", 32, 1023, 28, 738, (6, 12)),
    "digicam_corpus/Canon_PowerShot_S40_CRW_0119.CRW": ((1720, 2312), "RGGB", 32, 1023, 28, 1023, (6, 12)),
    "digicam_corpus/Kodak_DC120_P003908_uncompressed.KDC": ((976, 848), "GRBG", 0, 255, 0, 130, (0, 0)),
    "digicam_corpus/Kodak_DC120_P003911_better.KDC": ((976, 848), "GRBG", 0, 510, 0, 326, (0, 0)),
    "digicam_corpus/Kodak_DC50_DC0008L.KDC": ((512, 768), "GRBG", 0, 16383, 942, 16383, (0, 0)),
    "imageio_test_images/Blackmagic.dng": ((2176, 4128), "RGGB", 512, 65535, 0, 65472, (0, 0)),
    "tinydng/colorchart.dng": ((1156, 1734), "RGGB", 2056, 15000, 1702, 12128, (26, 152)),
}


@pytest.mark.parametrize("name", sorted(REPORT))
def test_real_raw_matches_rawpy_report(name):
    shape, pattern, black, white, raw_min, raw_max, margins = REPORT[name]
    mosaic = read_mosaic(shared_file(name))
    assert isinstance(mosaic, Mosaic)
    assert mosaic.kind == "raw"
    assert mosaic.data.shape == shape
    assert mosaic.data.dtype == np.float32
    assert mosaic.data.flags.c_contiguous
    assert mosaic.pattern == pattern
    assert mosaic.origin == (0, 0)
    assert mosaic.black == [black] * 4
    assert mosaic.white == white
    assert mosaic.bits == int(white).bit_length()
    assert mosaic.source.endswith(Path(name).name)

    # Normalisation: (raw - black) / (white - black), not clipped. The visible area is
    # inside the whole raw, so its range is inside the report's (equal without margins).
    lo = (raw_min - black) / (white - black)
    hi = (raw_max - black) / (white - black)
    data_min, data_max = float(mosaic.data.min()), float(mosaic.data.max())
    assert lo - 1e-6 <= data_min and data_max <= hi + 1e-6
    assert raw_min <= mosaic.raw_max <= raw_max
    if margins == (0, 0):
        assert data_min == pytest.approx(lo, abs=1e-6)
        assert data_max == pytest.approx(hi, abs=1e-6)
        assert mosaic.raw_max == raw_max
    # every value maps back to an integer raw code
    codes = mosaic.data * (white - black) + black
    assert np.allclose(codes, np.round(codes), atol=1e-3 * max(1.0, white / 1000))


def test_black_below_zero_survives():
    """colorchart.dng has raw values below its black level 2056 (down to 1702 in the whole
    raw): they come out negative, not clipped."""
    mosaic = read_mosaic(shared_file("tinydng/colorchart.dng"))
    assert (1702 - 2056) / (15000 - 2056) - 1e-6 <= mosaic.data.min() < 0


def test_clipped_pixels_reach_one():
    mosaic = read_mosaic(shared_file("digicam_corpus/Canon_PowerShot_S40_CRW_0119.CRW"))
    assert mosaic.data.max() == pytest.approx(1.0)


@pytest.mark.parametrize(
    "name",
    ["tinydng/colorchart.dng", "digicam_corpus/Canon_PowerShot_G2_CRW_0304.CRW", "digicam_corpus/Kodak_DC50_DC0008L.KDC"],
)
def test_pattern_agrees_with_libraw_half_size_decode(name):
    """LibRaw's half-size decode puts each 2x2 block's R and B samples in one output pixel:
    they must sit where our pattern says, whatever the margins (colorchart: 26, 152)."""
    import rawpy

    path = shared_file(name)
    mosaic = read_mosaic(path)
    with rawpy.imread(str(path)) as raw:
        visible = raw.raw_image_visible.astype(np.int64)
        half = raw.postprocess(
            half_size=True, no_auto_bright=True, gamma=(1, 1), user_wb=[1, 1, 1, 1],
            output_color=rawpy.ColorSpace.raw, output_bps=16, user_black=0, user_sat=65535,
            no_auto_scale=True,
        ).astype(np.int64)
    h, w = half.shape[:2]
    blocks = visible[: 2 * h, : 2 * w].reshape(h, 2, w, 2)
    for channel, letter in ((0, "R"), (2, "B")):
        k = mosaic.pattern.index(letter)
        np.testing.assert_array_equal(blocks[:, k // 2, :, k % 2], half[:, :, channel])


def test_raw_metadata_colorchart():
    mosaic = read_mosaic(shared_file("tinydng/colorchart.dng"))
    # camera_wb [1.0, 0.404, 0.684] in the report -> normalised to G = 1
    r, g, b = mosaic.as_shot_wb
    assert g == 1.0
    assert r == pytest.approx(1.0 / 0.4037, rel=1e-3)
    assert b == pytest.approx(0.684 / 0.4037, rel=1e-3)
    assert "EOS Kiss X4" in mosaic.camera
    assert mosaic.noise_profile is None
    assert mosaic.color_matrix is None or mosaic.color_matrix.shape == (3, 4)
    meta = mosaic.metadata()
    assert meta["pattern"] == "RGGB" and meta["black"] == [2056.0] * 4 and meta["white"] == 15000.0


def test_raw_metadata_crw():
    mosaic = read_mosaic(shared_file("digicam_corpus/Canon_PowerShot_G2_CRW_0304.CRW"))
    # camera_wb [1687, 1036, 1655, 1036]
    assert mosaic.as_shot_wb == pytest.approx((1687 / 1036, 1.0, 1655 / 1036))
    assert mosaic.xyz_to_camera is not None and mosaic.xyz_to_camera.shape == (3, 3)
    assert mosaic.camera_to_xyz.shape == (3, 3)


def test_raw_without_white_balance():
    """QuickTake: camera_wb [0, 1, 0, 0] is no white balance."""
    assert read_mosaic(shared_file("a2tools_quicktake/QT100_IMAGE01.QTK")).as_shot_wb is None


def test_given_pattern_must_agree_with_raw():
    path = shared_file("tinydng/colorchart.dng")
    assert read_mosaic(path, "rggb").pattern == "RGGB"
    with pytest.raises(ValueError, match="GRBG disagrees"):
        read_mosaic(path, "GRBG")
    with pytest.raises(ValueError, match="unknown Bayer pattern"):
        read_mosaic(path, "RGBG")


def test_gopro_gpr_is_refused():
    with pytest.raises(ValueError, match="GOPR8508.GPR.*Unsupported file format"):
        read_mosaic(shared_file("digicam_corpus/GoPro_Hero7Black_GOPR8508.GPR"))


def test_film_scanner_nef_is_not_bayer():
    with pytest.raises(ValueError, match="not a Bayer sensor"):
        read_mosaic(shared_file("imageio_test_images/Nikon_uncompressed.nef"))


def test_truncated_dng(tmp_path):
    truncated = tmp_path / "truncated.dng"
    truncated.write_bytes(shared_file("tinydng/colorchart.dng").read_bytes()[:10 * 1024])
    with pytest.raises(ValueError, match="truncated.dng") as info:
        read_mosaic(truncated)
    assert "\n" not in str(info.value)


def test_random_bytes_dng(tmp_path):
    junk = tmp_path / "junk.dng"
    junk.write_bytes(np.random.default_rng(1).integers(0, 256, 50_000, dtype=np.uint8).tobytes())
    with pytest.raises(ValueError, match="junk.dng") as info:
        read_mosaic(junk)
    assert "\n" not in str(info.value)


def test_empty_file(tmp_path):
    empty = tmp_path / "empty.CR2"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match="empty.CR2"):
        read_mosaic(empty)


def test_missing_file(tmp_path):
    missing = tmp_path / "nothere.dng"
    with pytest.raises((ValueError, FileNotFoundError), match="nothere.dng"):
        read_mosaic(missing)
    with pytest.raises((ValueError, FileNotFoundError), match="nothere.exr"):
        read_mosaic(tmp_path / "nothere.exr", "RGGB")


def test_directory_is_refused(tmp_path):
    with pytest.raises(ValueError, match="not a file"):
        read_mosaic(tmp_path)


def test_size_limit():
    path = shared_file("tinydng/colorchart.dng")
    with pytest.raises(ValueError, match="more than the limit"):
        read_mosaic(path, max_pixels=1000)
    with pytest.raises(ValueError, match="more than the limit"):
        read_mosaic(shared_file("halide/bayer_small.png"), "GRBG", max_pixels=1000)


# --------------------------------------------------------------------------- image mosaics


def test_png_mosaic():
    mosaic = read_mosaic(shared_file("halide/bayer_small.png"), "grbg")
    assert mosaic.kind == "image"
    assert mosaic.pattern == "GRBG" and mosaic.origin == (0, 0)
    assert mosaic.data.shape == (344, 256) and mosaic.data.dtype == np.float32
    assert mosaic.black == [0.0] * 4 and mosaic.white == 1.0
    assert mosaic.bits == 16
    assert mosaic.raw_max == 1053  # SOURCES.md: 10-bit data in 16-bit, max 1053
    assert float(mosaic.data.max()) == pytest.approx(1053 / 65535)
    assert np.allclose(mosaic.data * 65535, np.round(mosaic.data * 65535), atol=1e-3)


def test_png_mosaic_needs_pattern():
    with pytest.raises(ValueError, match="pattern"):
        read_mosaic(shared_file("halide/bayer_small.png"))


def test_lighthouse_exr_mosaic():
    from lfcl.io.images import read_image

    path = shared_file("Lighthouse_CFA_GRBG.exr", LIGHTHOUSE)
    mosaic = read_mosaic(path, "GRBG")
    assert mosaic.data.shape == (768, 512)
    assert mosaic.pattern == "GRBG"
    assert mosaic.bits is None  # half float: taken as it is
    pixels = read_image(path)
    np.testing.assert_array_equal(mosaic.data, pixels[:, :, 0])
    # and it is the GRBG sampling of the ground truth
    truth = read_image(LIGHTHOUSE / "Lighthouse.exr")
    cells = np.array([[1, 0], [2, 1]])
    colour = cells[np.arange(768)[:, None] % 2, np.arange(512)[None, :] % 2]
    np.testing.assert_array_equal(mosaic.data, np.take_along_axis(truth, colour[..., None], 2)[..., 0])


def test_rgb_image_is_not_a_mosaic():
    with pytest.raises(ValueError, match="768x512x3"):
        read_mosaic(shared_file("Lighthouse.exr", LIGHTHOUSE), "GRBG")


def _write(path, image):
    from lfcl.io.images import write_image

    write_image(path, image)
    return path


def test_a_float_mosaic_in_camera_units_is_refused(tmp_path):
    # A float EXR of raw counts (black 64, white 4095) read as normalised would be "saturated" everywhere: refused.
    from lfcl.io.raw import FLOAT_MOSAIC_MAX

    counts = np.full((18, 18), 900.0, np.float32)
    counts[::2, ::2] = 4095.0
    with pytest.raises(ValueError, match="up to 4095: a float mosaic must be normalised"):
        read_mosaic(_write(tmp_path / "counts.exr", counts), "GRBG")
    edge = np.full((18, 18), FLOAT_MOSAIC_MAX, np.float32)  # at the limit: read, unclipped
    np.testing.assert_array_equal(read_mosaic(_write(tmp_path / "edge.exr", edge), "GRBG").data, edge)


def test_synthetic_image_layouts(tmp_path):
    rng = np.random.default_rng(0)
    plane = rng.uniform(-0.1, 1.3, (6, 8)).astype(np.float32)
    one = read_mosaic(_write(tmp_path / "one.exr", plane), "BGGR")
    np.testing.assert_array_equal(one.data, plane)  # float: unclipped, unscaled
    equal = read_mosaic(_write(tmp_path / "equal.exr", np.stack([plane] * 3, axis=2)), "RGGB")
    np.testing.assert_array_equal(equal.data, plane)
    rgba = np.concatenate([np.stack([plane] * 3, axis=2), np.ones((6, 8, 1), np.float32)], axis=2)
    np.testing.assert_array_equal(read_mosaic(_write(tmp_path / "rgba.exr", rgba), "RGGB").data, plane)
    first = np.stack([plane, np.zeros_like(plane), np.zeros_like(plane)], axis=2)
    np.testing.assert_array_equal(read_mosaic(_write(tmp_path / "first.exr", first), "RGGB").data, plane)

    rgb = rng.uniform(0, 1, (6, 8, 3)).astype(np.float32)
    with pytest.raises(ValueError, match="6x8x3"):
        read_mosaic(_write(tmp_path / "rgb.exr", rgb), "RGGB")
    two = rng.uniform(0, 1, (6, 8, 2)).astype(np.float32)
    with pytest.raises(ValueError, match="6x8x2"):
        read_mosaic(_write(tmp_path / "two.exr", two), "RGGB")


def test_integer_tiff_normalised(tmp_path):
    import OpenImageIO as oiio

    values = np.array([[0, 1000], [30000, 65535]], dtype=np.uint16)
    path = tmp_path / "m.tif"
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(2, 2, 1, oiio.UINT16))
    assert out.write_image(values[:, :, None].copy())  # OIIO's Python binding misreads 2D arrays
    out.close()
    mosaic = read_mosaic(path, "GBRG")
    np.testing.assert_allclose(mosaic.data, values / 65535, rtol=1e-6)
    assert mosaic.bits == 16 and mosaic.raw_max == 65535


def test_nan_mosaic_refused(tmp_path):
    import OpenImageIO as oiio

    plane = np.zeros((4, 4), np.float32)
    plane[1, 2] = np.nan
    path = tmp_path / "nan.exr"  # write_image refuses NaN, so write it directly
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(4, 4, 1, oiio.FLOAT))
    assert out.write_image(plane[:, :, None].copy())
    out.close()
    with pytest.raises(ValueError, match="NaN or infinite"):
        read_mosaic(path, "RGGB")


def test_corrupt_image_file(tmp_path):
    path = tmp_path / "broken.exr"
    path.write_bytes(b"not an exr at all" * 10)
    with pytest.raises(ValueError, match="broken.exr") as info:
        read_mosaic(path, "RGGB")
    assert "\n" not in str(info.value)


# --------------------------------------------------------------------------- synthetic DNGs

SIGNAL = {0: 1000, 1: 2000, 2: 3000}  # raw signal above black per colour (R, G, B)


def _write_dng(path, *, top=0, left=0, height=32, width=48, cfa=(0, 1, 1, 2), black=(100,),
               noise=None, photometric=32803, samples=1):
    """A minimal uncompressed DNG: CFA (or linear / monochrome) data with an ActiveArea.

    Per the DNG spec, CFAPattern and a 2x2 BlackLevel pattern start at the ActiveArea's
    top-left corner; every pixel is black(position) + SIGNAL[colour].
    """
    import tifffile  # a dependency of lfcl
    rows = (np.arange(height)[:, None] - top) % 2
    cols = (np.arange(width)[None, :] - left) % 2
    colour = np.array(cfa).reshape(2, 2)[rows, cols]
    black_cells = np.array(black * 4 if len(black) == 1 else black).reshape(2, 2)
    image = black_cells[rows, cols] + np.vectorize(SIGNAL.get)(colour)
    if samples > 1:
        image = np.repeat(image[..., None], samples, axis=2)
    tags = [
        (50706, "B", 4, (1, 4, 0, 0), True),  # DNGVersion
        (50708, "s", 0, "Synthetic Cam", True),  # UniqueCameraModel
        (50721, "2i", 9, tuple(x for v in (1, 0, 0, 0, 1, 0, 0, 0, 1) for x in (10000 * v, 10000)), True),
        (50778, "H", 1, 21, True),  # CalibrationIlluminant1 D65
        (50829, "I", 4, (top, left, height, width), True),  # ActiveArea
        (50717, "H", 1, 4000, True),  # WhiteLevel
        (50728, "2I", 3, (1, 2, 1, 1, 1, 1), True),  # AsShotNeutral
        (271, "s", 0, "Synth", True),
        (272, "s", 0, "Synthetic Cam", True),
    ]
    if photometric == 32803:
        tags += [(33421, "H", 2, (2, 2), True), (33422, "B", 4, tuple(cfa), True)]
    if len(black) == 4:
        tags += [(50713, "H", 2, (2, 2), True), (50714, "H", 4, tuple(black), True)]
    else:
        tags += [(50714, "H", 1, black[0], True)]
    if noise is not None:
        tags.append((51041, "d", len(noise), tuple(noise), True))
    tifffile.imwrite(path, image.astype(np.uint16), photometric=photometric, extratags=tags, subfiletype=0)
    return path


@pytest.mark.parametrize("top,left", [(0, 0), (1, 0), (0, 1), (1, 1), (3, 5), (2, 4)])
def test_dng_active_area_phase_and_black(tmp_path, top, left):
    """Odd ActiveArea origins: LibRaw rounds the margins up to even numbers (losing a row or
    column); the pattern and the per-position black levels must follow the visible area."""
    path = _write_dng(tmp_path / "odd.dng", top=top, left=left, black=(100, 110, 120, 130), noise=(1e-4, 2e-6))
    mosaic = read_mosaic(path)
    # the visible area starts at an even margin >= the ActiveArea origin
    top_margin, left_margin = top + top % 2, left + left % 2
    assert mosaic.data.shape == (32 - top_margin, 48 - left_margin)
    rggb = np.array([[0, 1], [1, 2]])
    expected = "".join("RGB"[c] for c in np.roll(rggb, (-(top_margin - top), -(left_margin - left)), (0, 1)).ravel())
    assert mosaic.pattern == expected
    # normalised values are constant per colour: SIGNAL / (white - black at that position)
    black_cells = np.roll(np.array([[100, 110], [120, 130]]), (-(top_margin - top), -(left_margin - left)), (0, 1))
    for y in range(2):
        for x in range(2):
            colour = "RGB".index(expected[2 * y + x])
            want = SIGNAL[colour] / (4000 - black_cells[y, x])
            np.testing.assert_allclose(mosaic.data[y::2, x::2], want, rtol=1e-6)
    assert mosaic.white == 4000
    assert mosaic.noise_profile == (1e-4, 2e-6)
    assert mosaic.camera == "Synthetic Cam"


def test_dng_pattern_phases(tmp_path):
    for cfa, name in (((0, 1, 1, 2), "RGGB"), ((1, 0, 2, 1), "GRBG"), ((1, 2, 0, 1), "GBRG"), ((2, 1, 1, 0), "BGGR")):
        mosaic = read_mosaic(_write_dng(tmp_path / f"{name}.dng", cfa=cfa))
        assert mosaic.pattern == name
        assert mosaic.noise_profile is None


def test_linear_dng_is_not_bayer(tmp_path):
    path = _write_dng(tmp_path / "linear.dng", photometric=34892, samples=3)
    with pytest.raises(ValueError, match="not a Bayer sensor"):
        read_mosaic(path)


def _write_cfa_dng(path, repeat, cfa, plane_colors=None):
    import tifffile  # a dependency of lfcl
    tags = [
        (50706, "B", 4, (1, 4, 0, 0), True),
        (50708, "s", 0, "Synthetic Cam", True),
        (50721, "2i", 9, tuple(x for v in (1, 0, 0, 0, 1, 0, 0, 0, 1) for x in (10000 * v, 10000)), True),
        (50778, "H", 1, 21, True),
        (50717, "H", 1, 4000, True),
        (33421, "H", 2, tuple(repeat), True),
        (33422, "B", len(cfa), tuple(cfa), True),
    ]
    if plane_colors is not None:
        tags.append((50710, "B", len(plane_colors), tuple(plane_colors), True))  # CFAPlaneColor
    tifffile.imwrite(path, np.full((36, 48), 1000, np.uint16), photometric=32803, extratags=tags, subfiletype=0)
    return path


def test_xtrans_dng_is_not_bayer(tmp_path):
    xtrans = (1, 1, 0, 1, 1, 2, 1, 1, 2, 1, 1, 0, 2, 0, 1, 0, 2, 1,
              1, 1, 2, 1, 1, 0, 1, 1, 0, 1, 1, 2, 0, 2, 1, 2, 0, 1)
    with pytest.raises(ValueError, match="not a Bayer sensor .*X-Trans"):
        read_mosaic(_write_cfa_dng(tmp_path / "xtrans.dng", (6, 6), xtrans))


def test_four_colour_cfa_is_not_bayer(tmp_path):
    # R, G, cyan, B in a 2x2 cell (CFAPlaneColor red, green, blue, cyan)
    with pytest.raises(ValueError, match="not a Bayer sensor"):
        read_mosaic(_write_cfa_dng(tmp_path / "rgcb.dng", (2, 2), (0, 1, 3, 2), plane_colors=(0, 1, 2, 3)))

"""The lenslet-camera simulator (lfcl.sim, ``lfcl simulate``): DNG, truth, noise, geometry, loaders, CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rawpy
import tifffile
from click.testing import CliRunner
from conftest import shared_path

from lfcl.layout import PATTERNS, channel_map, pattern_from_rawpy, tiled_views
from lfcl.sim import (
    LensletGeometry,
    Plane,
    SensorModel,
    load_lightfield,
    parse_lenses,
    render_planes,
    render_scene,
    simulate,
    write_capture,
)
from lfcl.sim.dng import read_noise_profile
from lfcl.sim.texture import read_linear, srgb_decode

ANTINOUS = Path(__file__).resolve().parents[1] / ".." / "shared" / "realdata" / "hci_epinet" / "antinous"
LYTRO = ANTINOUS.parents[1] / "lytro_epinet" / "2067"
LUMA = np.array([0.2126, 0.7152, 0.0722])


def flat(value):
    value = np.asarray(value, dtype=np.float32)
    return lambda x, y: np.broadcast_to(value, (x.size, 3)).copy()


def luminance(lf):
    return lf.reshape(-1, 3).astype(np.float64) @ LUMA


# --- DNG -------------------------------------------------------------------

@pytest.mark.parametrize("pattern", PATTERNS)
def test_dng_roundtrip_rawpy(tmp_path, pattern):
    cap = simulate("charts", lenses=(6, 7), pattern=pattern, lux=12.0, seed=3)
    out = write_capture(cap, tmp_path / "cap")
    for name, data in (("raw.dng", cap.raw), ("white.dng", cap.white)):
        with rawpy.imread(str(out / name)) as raw:
            assert pattern_from_rawpy(raw.raw_pattern, raw.color_desc) == pattern
            assert list(raw.black_level_per_channel) == [64, 64, 64, 64]
            assert raw.white_level == 4095
            assert raw.raw_image.dtype == np.uint16
            np.testing.assert_array_equal(raw.raw_image, data)
    assert data.shape == (54, 63)
    s, o = cap.sensor.noise_profile()
    np.testing.assert_allclose(np.asarray(read_noise_profile(out / "raw.dng"), float), [(s, o)] * 3, rtol=1e-12)
    with tifffile.TiffFile(out / "raw.dng") as tif:
        tags = tif.pages[0].tags
        assert tags[262].value == 32803
        assert bytes(tags[50706].value) == bytes([1, 4, 0, 0])
        assert tags[50708].value == "lfcl simulated lenslet camera"
        assert tags[50778].value == 21
        assert tags[33421].value == (2, 2)


def test_dng_colour_matrix_is_srgb(tmp_path):
    cap = simulate("charts", lenses=(4, 4), lux=12.0)
    out = write_capture(cap, tmp_path / "cap")
    with rawpy.imread(str(out / "raw.dng")) as raw:
        np.testing.assert_allclose(np.asarray(raw.color_matrix)[:3, :3], np.eye(3), atol=2e-3)
        assert list(raw.camera_whitebalance)[:3] == [1.0, 1.0, 1.0]


# --- truth and exposure ----------------------------------------------------

def test_truth_shape_and_scale():
    sensor = SensorModel()
    cap = simulate("charts", lenses=(12, 10), pitch=9, lux=12.0, seed=0)
    truth = cap.truth
    assert truth.shape == (12, 10, 9, 9, 3) and truth.dtype == np.float32
    assert truth.min() >= 0 and truth.max() <= 1.0
    # Mean luminance of the truth is the requested lux in normalised units.
    assert luminance(truth).mean() == pytest.approx(12.0 * sensor.electrons_per_lux / sensor.full_well_e, rel=1e-4)
    assert cap.meta["electrons_per_lux"] == pytest.approx(63.051, rel=1e-4)
    # The raw's normalised mean follows the CFA-sampled truth.
    expected = cap.geometry.mosaic(truth, cap.pattern)
    assert cap.normalised_raw().mean() == pytest.approx(expected.mean(), rel=0.01)


def test_truth_clips_at_full_well():
    cap = simulate(planes=[Plane("bright", 0.0, flat((1, 1, 1))), Plane("bg", 0.0, flat((0.01, 0.01, 0.01)))],
                   lenses=(4, 4), lux=5000.0)
    assert cap.truth.max() == 1.0
    assert cap.raw.max() == 4095


def test_sensor_constants():
    s = SensorModel()
    assert s.photons_per_lux == pytest.approx(131.36, rel=1e-3)
    assert s.electrons_per_lux == pytest.approx(131.36 * 0.6 * 0.8, rel=1e-3)
    assert s.white_level_dn == 4095 and s.black_level_dn == 64
    with pytest.raises(ValueError, match="full_well_e"):
        SensorModel(full_well_e=0)


@pytest.mark.parametrize("x", [0.005, 0.126, 0.6])
def test_noise_variance_matches_model(x):
    sensor = SensorModel()
    dn = sensor.expose(np.full((300, 300), x), np.random.default_rng(1))
    normalised = (dn.astype(np.float64) - 64) / (4095 - 64)
    dark = sensor.dark_electrons / sensor.full_well_e
    assert normalised.mean() == pytest.approx(x + dark, rel=0.01, abs=2e-5)
    assert normalised.var() == pytest.approx(sensor.noise_sigma(x + dark) ** 2, rel=0.06)


def test_noise_of_a_flat_grey_patch_in_a_capture():
    grey = Plane("grey card", 0.0, flat((0.18, 0.18, 0.18)))
    cap = simulate(planes=[grey], lenses=(24, 24), lux=12.0, seed=5)
    green = channel_map(cap.raw.shape, cap.pattern) == 1
    x = cap.normalised_raw()[green].astype(np.float64)
    predicted = cap.sensor.noise_sigma(cap.truth[0, 0, 0, 0, 1]) ** 2
    assert x.var() == pytest.approx(predicted, rel=0.1)
    assert cap.meta["noise"]["sigma_at_mean"] == pytest.approx(np.sqrt(predicted), rel=0.01)


def test_lux_scaling():
    low = simulate("charts", lenses=(16, 16), lux=6.0, seed=2)
    high = simulate("charts", lenses=(16, 16), lux=12.0, seed=2)
    ratio = (high.raw.astype(np.float64) - 64).mean() / (low.raw.astype(np.float64) - 64).mean()
    assert ratio == pytest.approx(2.0, rel=0.02)
    np.testing.assert_allclose(high.truth, 2 * low.truth, rtol=1e-5, atol=1e-7)


def test_vignetting_only_in_raw_and_white():
    plain = simulate("charts", lenses=(8, 8), seed=1)
    vign = simulate("charts", lenses=(8, 8), seed=1, vignetting=True)
    np.testing.assert_array_equal(plain.truth, vign.truth)
    falloff = LensletGeometry((8, 8)).vignetting()
    assert falloff[4, 4] == 1.0 and falloff[0, 0] == pytest.approx(0.906, abs=1e-3)
    white = vign.white.astype(np.float64).reshape(8, 9, 8, 9) - 64
    assert white[:, 0, :, 0].mean() == pytest.approx(0.906 * white[:, 4, :, 4].mean(), rel=0.01)
    assert vign.meta["vignetting"]["enabled"] is True


# --- geometry: disparity and occlusion ---------------------------------------

@pytest.mark.parametrize("d", [0.3, -0.45])
def test_disparity_shift_with_a_ramp(d):
    ramp = Plane("ramp", d, lambda x, y: np.stack([y, x, np.ones_like(x)], axis=1).astype(np.float32))
    lf = render_planes([ramp], (6, 7), 9)
    # View u0+1 samples d lenses further along s than the centre view (R = y), v0+1 along t (G = x).
    np.testing.assert_allclose(lf[:, :, 5, 4, 0] - lf[:, :, 4, 4, 0], d, atol=1e-4)
    np.testing.assert_allclose(lf[:, :, 4, 5, 1] - lf[:, :, 4, 4, 1], d, atol=1e-4)
    np.testing.assert_allclose(lf[:, :, 8, 4, 0] - lf[:, :, 4, 4, 0], 4 * d, atol=1e-4)
    np.testing.assert_allclose(lf[:, :, 4, 4, 0], np.broadcast_to(np.arange(6)[:, None] + 0.5, (6, 7)), atol=1e-5)


def test_disparity_one_lens_shifts_a_random_texture():
    rng = np.random.default_rng(0)
    table = rng.random((64, 64, 3)).astype(np.float32)

    def texture(x, y):
        return table[np.floor(y).astype(int) % 64, np.floor(x).astype(int) % 64]

    lf = render_planes([Plane("tex", 1.0, texture)], (10, 10), 5, supersample=1)
    np.testing.assert_array_equal(lf[:-1, :, 3, 2], lf[1:, :, 2, 2])  # u - u0 = +1: d = 1 lens along s
    np.testing.assert_array_equal(lf[:, :-1, 2, 3], lf[:, 1:, 2, 2])


def test_occlusion_front_plane_wins():
    front = Plane("front", 0.5, flat((1, 0, 0)), rect=(2.0, 2.0, 6.0, 6.0))
    middle = Plane("middle", 0.0, flat((0, 1, 0)), rect=(0.0, 0.0, 8.0, 8.0))
    back = Plane("back", -0.5, flat((0, 0, 1)))
    lf = render_planes([front, middle, back], (10, 10), 9)
    np.testing.assert_array_equal(lf[2:6, 2:6, 4, 4], [[[1, 0, 0]] * 4] * 4)
    # View u - u0 = +2 sees the front plane 1 lens further along s: lens rows 1..4.
    np.testing.assert_array_equal(lf[1:5, 2:6, 6, 4, 0], 1)
    assert lf[5, 3, 6, 4, 1] == 1  # uncovered there: the middle plane shows
    np.testing.assert_array_equal(lf[8:, :, 4, 4, 2], 1)  # only the background below the middle plane
    # Planes in the other order: the big opaque one hides the small one completely.
    lf2 = render_planes([middle, front, back], (10, 10), 9)
    np.testing.assert_array_equal(lf2[0:8, 0:8, 4, 4], [[[0, 1, 0]] * 8] * 8)


def test_partial_coverage_is_antialiased():
    half = Plane("half", 0.0, flat((1, 1, 1)), rect=(0.0, 0.0, 10.0, 2.5))
    lf = render_planes([half, Plane("bg", 0.0, flat((0, 0, 0)))], (3, 4), 3, supersample=4)
    np.testing.assert_allclose(lf[:, 2, :, :, 0], 0.5)


# --- scenes, determinism ---------------------------------------------------

def test_scenes_render_and_are_deterministic():
    a = simulate("deadleaves", lenses=(16, 16), seed=7)
    b = simulate("deadleaves", lenses=(16, 16), seed=7)
    c = simulate("deadleaves", lenses=(16, 16), seed=8)
    np.testing.assert_array_equal(a.raw, b.raw)
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_array_equal(a.white, b.white)
    assert not np.array_equal(a.truth, c.truth)
    assert not np.array_equal(a.raw, c.raw)
    charts = render_scene("charts", (16, 16), 9)
    assert charts.shape == (16, 16, 9, 9, 3)
    # Planes at non-zero disparity: the corner views differ from the centre view.
    assert np.abs(charts[:, :, 0, 0] - charts[:, :, 4, 4]).max() > 0.1


def test_texture_image_on_planes(tmp_path):
    from lfcl.io.images import write_image

    rng = np.random.default_rng(0)
    image = rng.random((40, 50, 3)).astype(np.float32)
    write_image(tmp_path / "tex.tif", image)
    decoded = read_linear(tmp_path / "tex.tif")  # 16-bit sRGB-encoded -> linear
    import OpenImageIO as oiio

    held = oiio.ImageInput.open(str(tmp_path / "tex.tif"))
    codes = held.read_image(0, 0, 0, 3, oiio.UINT16)
    held.close()
    # the writer's float -> uint16 rounding is OpenImageIO's (one element of 6000 rounded the other way
    # on an AVX-512 machine); the decoding of the codes the file holds is exact
    assert np.abs(codes.astype(np.int32) - np.rint(image * 65535)).max() <= 1
    np.testing.assert_allclose(decoded, srgb_decode(codes), atol=1e-6)
    lf = render_scene("charts", (10, 10), 9, texture=tmp_path / "tex.tif")
    assert lf.shape == (10, 10, 9, 9, 3)
    assert lf.max() <= decoded.max() + 1e-6
    assert not np.allclose(lf, render_scene("charts", (10, 10), 9))


def test_a_camera_raw_textures_a_plane_developed_linear(tmp_path):
    """A raw OpenImageIO cannot read is developed by LibRaw: full size, linear, not brightened."""
    dim = write_capture(simulate("charts", lenses=(6, 7), lux=6.0, seed=3), tmp_path / "dim") / "raw.dng"
    bright = write_capture(simulate("charts", lenses=(6, 7), lux=12.0, seed=3), tmp_path / "bright") / "raw.dng"
    dim_rgb, bright_rgb = read_linear(dim), read_linear(bright)
    assert dim_rgb.shape == (54, 63, 3) and dim_rgb.dtype == np.float32
    assert dim_rgb.min() >= 0.0 and bright_rgb.max() <= 1.0
    assert bright_rgb.mean() / dim_rgb.mean() == pytest.approx(2.0, rel=0.05)  # twice the light, twice the value
    lf = render_scene("charts", (10, 10), 9, texture=bright)
    assert lf.shape == (10, 10, 9, 9, 3) and np.all(np.isfinite(lf))


def test_a_camera_raw_texture_declaring_too_many_pixels_is_refused(tmp_path, monkeypatch):
    import lfcl.io.raw

    dng = write_capture(simulate("charts", lenses=(6, 7), lux=6.0, seed=3), tmp_path / "cap") / "raw.dng"
    monkeypatch.setattr(lfcl.io.raw, "MAX_PIXELS", 54 * 63 - 1)
    with pytest.raises(ValueError, match="declares 3402 pixels, more than the limit"):
        read_linear(dng)


def test_a_file_neither_reads_says_both_failed(tmp_path):
    junk = tmp_path / "photo.cr2"
    junk.write_bytes(b"not a raw at all" * 64)
    with pytest.raises(ValueError, match="nor is it a camera raw LibRaw reads"):
        read_linear(junk)


def test_a_tiff_based_raw_is_developed_not_read_as_its_thumbnail():
    kdc = shared_path("realdata", "digicam_corpus", "Kodak_DC120_P003908_uncompressed.KDC")
    assert read_linear(kdc).shape == (976, 1301, 3)  # OpenImageIO alone opens its 80-pixel-wide thumbnail


# --- light-field loading ---------------------------------------------------

def make_hci(folder: Path, side=3, h=5, w=4):
    from lfcl.io.images import write_image

    folder.mkdir()
    views = []
    for k in range(side * side):
        codes = np.zeros((h, w, 3), dtype=np.uint8)  # exact 8-bit code values
        codes[..., 0] = 25 * k
        codes[..., 1] = 40 * np.arange(h)[:, None]
        codes[..., 2] = 60 * np.arange(w)[None, :] + 7
        write_image(folder / f"input_Cam{k:03d}.png", codes / np.float32(255))
        views.append(codes)
    return views


def test_hci_folder_loading(tmp_path):
    views = make_hci(tmp_path / "lf")
    lf = load_lightfield(tmp_path / "lf")
    assert lf.shape == (5, 4, 3, 3, 3) and lf.dtype == np.float32
    for k, view in enumerate(views):
        np.testing.assert_allclose(lf[:, :, k // 3, k % 3], srgb_decode(view), atol=1e-6)
    crop = load_lightfield(tmp_path / "lf", lenses=(3, 2))
    np.testing.assert_array_equal(crop, lf[1:4, 1:3])
    cap = simulate(lightfield=tmp_path / "lf", lux=12.0)
    assert cap.geometry.pitch == (3, 3) and cap.geometry.lenses == (5, 4)
    assert cap.raw.shape == (15, 12)
    with pytest.raises(ValueError, match="larger than"):
        load_lightfield(tmp_path / "lf", lenses=(6, 4))
    with pytest.raises(ValueError, match="does not match"):
        simulate(lightfield=tmp_path / "lf", pitch=9)
    (tmp_path / "lf" / "input_Cam004.png").unlink()
    with pytest.raises(ValueError, match="square"):
        load_lightfield(tmp_path / "lf")


def test_npy_loading(tmp_path):
    rng = np.random.default_rng(0)
    data = rng.random((6, 5, 4, 4, 3)).astype(np.float32)
    np.save(tmp_path / "lf.npy", data)
    np.testing.assert_array_equal(load_lightfield(tmp_path / "lf.npy"), data)
    np.testing.assert_array_equal(load_lightfield(tmp_path / "lf.npy", lenses=(2, 3)), data[2:4, 1:4])
    cap = simulate(lightfield=tmp_path / "lf.npy", lux=3.0)
    assert cap.truth.shape == data.shape
    np.testing.assert_allclose(cap.truth / cap.truth.mean(), data / data.mean(), rtol=1e-4)
    np.save(tmp_path / "bad.npy", data[..., :2])
    with pytest.raises(ValueError, match=r"\[S, T, U, V, 3\]"):
        load_lightfield(tmp_path / "bad.npy")
    (tmp_path / "junk.npy").write_text("not a numpy file")
    with pytest.raises(ValueError, match="cannot read"):
        load_lightfield(tmp_path / "junk.npy")


def test_grid_named_folder_loading(tmp_path):
    """NAME_UU_VV.png views (1-based row, column; EPINET's decoded Lytro layout) load like HCI ones."""
    views = make_hci(tmp_path / "hci")
    folder = tmp_path / "grid"
    folder.mkdir()
    for k in range(9):
        (tmp_path / "hci" / f"input_Cam{k:03d}.png").rename(folder / f"0042_{k // 3 + 1:02d}_{k % 3 + 1:02d}.png")
    lf = load_lightfield(folder)
    assert lf.shape == (5, 4, 3, 3, 3)
    for k, view in enumerate(views):
        np.testing.assert_allclose(lf[:, :, k // 3, k % 3], srgb_decode(view), atol=1e-6)
    (folder / "0042_02_03.png").unlink()
    with pytest.raises(ValueError, match="square grid"):
        load_lightfield(folder)
    (folder / "0043_02_03.png").write_bytes((folder / "0042_01_01.png").read_bytes())
    with pytest.raises(ValueError, match="2 captures"):
        load_lightfield(folder)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no input_CamNNN.png or NAME_UU_VV.png"):
        load_lightfield(empty)


@pytest.mark.skipif(not LYTRO.is_dir(), reason="../shared/realdata/lytro_epinet/2067 is not present")
def test_decoded_lytro_folder():
    lf = load_lightfield(LYTRO, lenses=(16, 24))
    assert lf.shape == (16, 24, 9, 9, 3)
    centre = read_linear(LYTRO / "2067_05_05.png")
    s0, t0 = (centre.shape[0] - 16) // 2, (centre.shape[1] - 24) // 2
    np.testing.assert_array_equal(lf[:, :, 4, 4], centre[s0:s0 + 16, t0:t0 + 24])
    corner = read_linear(LYTRO / "2067_09_01.png")
    np.testing.assert_array_equal(lf[:, :, 8, 0], corner[s0:s0 + 16, t0:t0 + 24])


@pytest.mark.skipif(not ANTINOUS.is_dir(), reason="../shared/realdata/hci_epinet/antinous is not present")
def test_hci_antinous():
    lf = load_lightfield(ANTINOUS, lenses=(32, 32))
    assert lf.shape == (32, 32, 9, 9, 3)
    centre = read_linear(ANTINOUS / "input_Cam040.png")
    s0 = (centre.shape[0] - 32) // 2
    t0 = (centre.shape[1] - 32) // 2
    np.testing.assert_array_equal(lf[:, :, 4, 4], centre[s0:s0 + 32, t0:t0 + 32])
    cap = simulate(lightfield=lf, lux=12.0)
    assert cap.raw.shape == (288, 288)


# --- output folder and CLI -------------------------------------------------

def test_views_tiling():
    lf = np.random.default_rng(0).random((3, 4, 2, 5, 3)).astype(np.float32)
    tiles = tiled_views(lf)
    assert tiles.shape == (6, 20, 3)
    np.testing.assert_array_equal(tiles[3:6, 8:12], lf[:, :, 1, 2])


def test_write_capture_replaces_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "raw.dng").write_text("old")
    (out / "keep.txt").write_text("mine")
    write_capture(simulate("charts", lenses=(4, 4)), out)
    assert (out / "keep.txt").read_text() == "mine"
    assert (out / "raw.dng").stat().st_size > 100
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary folder left


@pytest.fixture(scope="module")
def cli():
    try:
        from lfcl.cli import cli as group
    except ImportError:  # another command module is broken right now: test ours alone
        import click

        from lfcl.cli.commands.simulate import command

        group = click.Group("lfcl", commands={"simulate": command})
    return group


def test_cli_end_to_end(tmp_path, cli):
    out = tmp_path / "sim"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "deadleaves", "--lenses", "16x16", "--lux", "12",
                                      "--seed", "0", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["raw.dng", "white.dng", "meta.json", "truth.npy", "truth_views.exr", "disparity.npy"])
    meta = json.loads((out / "meta.json").read_text())
    assert meta["lenses"] == [16, 16] and meta["pitch"] == [9, 9] and meta["grid"] == "aligned-square"
    assert meta["pattern"] == "GRBG" and meta["lux"] == 12.0 and meta["seed"] == 0
    assert meta["scene"]["name"] == "deadleaves"
    assert meta["black_level"] == 64 and meta["white_level"] == 4095
    assert meta["noise"]["sigma_at_mean"] == pytest.approx(0.0046, rel=0.02)
    truth = np.load(out / "truth.npy")
    assert truth.shape == (16, 16, 9, 9, 3) and truth.dtype == np.float32
    from lfcl.io.images import read_image

    views = read_image(out / "truth_views.exr")
    np.testing.assert_array_equal(views, tiled_views(truth))
    with rawpy.imread(str(out / "raw.dng")) as raw:
        assert raw.raw_image.shape == (144, 144)
        assert pattern_from_rawpy(raw.raw_pattern, raw.color_desc) == "GRBG"
    white = rawpy.imread(str(out / "white.dng")).raw_image.astype(np.float64)
    assert 0.7 < (white.mean() - 64) / 4031 < 0.9 and white.max() < 4095


@pytest.mark.parametrize("args, words", [
    (["--lux", "0"], "lux"),
    (["--lux", "-3"], "lux"),
    (["--lenses", "0x16"], "lenses"),
    (["--lenses", "16by16"], "lenses"),
    (["--scene", "teapot"], "scene"),
    (["--pitch", "1"], "pitch"),
    (["--pattern", "RGBW"], "pattern"),
    (["--texture", "/nonexistent/tex.png"], "texture"),
    (["--lightfield", "/nonexistent/lf"], "light field"),
    (["--lightfield", "BADNPY"], "[S, T, U, V, 3]"),
    (["--texture", "NOTANIMAGE"], "cannot read image"),
])
def test_cli_bad_input(tmp_path, cli, args, words):
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros((2, 2, 3, 3)))
    junk = tmp_path / "junk.png"
    junk.write_text("not an image")
    args = [str(bad) if a == "BADNPY" else str(junk) if a == "NOTANIMAGE" else a for a in args]
    out = tmp_path / "never" / "out"
    result = CliRunner().invoke(cli, ["simulate", "--lenses", "8x8", *args, "-o", str(out)]
                                if "--lenses" not in args else ["simulate", *args, "-o", str(out)])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lfcl: error:") and words in lines[0], result.output
    assert not (tmp_path / "never").exists()


def test_parse_lenses():
    assert parse_lenses("64x48") == (64, 48)
    assert parse_lenses("32") == (32, 32)
    assert parse_lenses((5, 6)) == (5, 6)
    for bad in ("", "x", "4x4x4", "0x3", "-1x2"):
        with pytest.raises(ValueError):
            parse_lenses(bad)


# --- raws of any lens grid (simulate_grid) -------------------------------------------------

def _linear_in_x(a, b):
    """A texture whose colour is a + b x (frame x, lenses), the same in R, G, B."""
    return lambda x, y: np.repeat((a + b * x)[:, None], 3, axis=1).astype(np.float32)


@pytest.mark.parametrize("grid", ["square", "hex"])
def test_grid_truth_follows_the_scene_frame_conventions(grid):
    # a plane of disparity d whose texture is a + b x: sample (s, t, u, v) sees
    # a + b (x_c(s, t) + d (v - v0)), x_c = t + 1/2 (+ 1/2 on odd hex rows), whatever the box filter
    from lfcl.grid.resampling import sampling_model
    from lfcl.sim.capture import render_grid
    from lfcl.sim.geometry import GridGeometry

    d, a, b = 0.3, 0.2, 0.05
    sampling = sampling_model(GridGeometry((80, 90), grid, 9.4, 0.7, (0.3, -0.2)), "GRBG")
    truth, _ = render_grid([Plane("ramp", d, _linear_in_x(a, b))], sampling)
    S, T, U, V, _ = truth.shape
    s, t, v = np.meshgrid(np.arange(S), np.arange(T), np.arange(V), indexing="ij")
    x_c = t + 0.5 + (0.5 * (s % 2) if grid == "hex" else 0.0)
    expected = a + b * (x_c + d * (v - (V - 1) / 2))
    np.testing.assert_allclose(truth[:, :, U // 2, :, 0], expected, atol=1e-5)
    np.testing.assert_allclose(truth[:, :, 0, :, 1], expected, atol=1e-5)  # no dependence on u


def test_grid_pixels_see_their_true_continuous_position():
    # no inverse crime: each pixel's value comes from its own position under its lens (brute-force
    # nearest lens centre, offset along the lens row in view steps), not from the regular samples
    from lfcl.grid.resampling import sampling_model
    from lfcl.sim.capture import render_grid
    from lfcl.sim.geometry import GridGeometry

    d, a, b = -0.25, 0.3, 0.04
    geometry = GridGeometry((70, 80), "hex", 9.4, 0.7, (0.3, -0.2))
    sampling = sampling_model(geometry, "GRBG")
    _, radiance = render_grid([Plane("ramp", d, _linear_in_x(a, b))], sampling)
    grid = geometry.lens_grid()
    ii, jj = np.meshgrid(np.arange(-2, 12), np.arange(-2, 12), indexing="ij")
    crow, ccol = grid.centre(ii.ravel(), jj.ravel())
    rng = np.random.default_rng(0)
    H, W = geometry.sensor_shape
    along = np.asarray(grid.col_step) / np.hypot(*grid.col_step)
    for row, col in zip(rng.integers(10, H - 10, 30), rng.integers(10, W - 10, 30)):
        k = np.argmin((crow - row) ** 2 + (ccol - col) ** 2)
        i, j = ii.ravel()[k] - sampling.lens_origin[0], jj.ravel()[k] - sampling.lens_origin[1]
        dv = ((row - crow[k]) * along[0] + (col - ccol[k]) * along[1]) / (9.4 / sampling.views[1])
        x = j + 0.5 + 0.5 * (i % 2) + d * dv
        assert radiance[row * W + col, 0] == pytest.approx(a + b * x, abs=1e-5)


def test_simulate_grid_capture():
    from lfcl.sim.capture import simulate_grid

    cap = simulate_grid("deadleaves", "hex", 9.4, 0.7, (0.3, -0.2), lenses=(20, 18), lux=12, seed=2)
    S, T = cap.sampling.lenses
    assert cap.truth.shape == (S, T, 9, 9, 3) and cap.truth.dtype == np.float32
    assert cap.raw.shape == cap.white.shape == cap.geometry.sensor_shape == (round(20 * 9.4 * np.sqrt(3) / 2), 169)
    meta = cap.meta
    assert meta["mode"] == "grid" and meta["grid"] == "hex" and meta["lenses"] == [S, T] and meta["views"] == [9, 9]
    assert meta["lightfield"]["lens_origin"] == list(cap.sampling.lens_origin)
    # the mean illuminance of the truth is the requested lux
    mean_y = float(luminance(cap.truth).mean()) / SensorModel().lux_to_normalised(1.0)
    assert mean_y == pytest.approx(12.0, rel=0.01)
    # the white: 80 % of full well at the micro-image centres, dark between them
    white = (cap.white.astype(np.float64) - 64) / 4031
    _, _, rows, cols = cap.geometry.centres()
    at_centres = white[np.rint(rows).astype(int), np.rint(cols).astype(int)]
    assert np.median(at_centres) == pytest.approx(0.8, abs=0.02)
    assert np.median(white[cap.sampling.response < 0.01]) < 0.01
    again = simulate_grid("deadleaves", "hex", 9.4, 0.7, (0.3, -0.2), lenses=(20, 18), lux=12, seed=2)
    np.testing.assert_array_equal(again.raw, cap.raw)


def test_grid_raw_is_the_rendered_scene_times_the_micro_image():
    # a nearly noiseless sensor: the raw must equal CFA(radiance at each pixel) x response
    from lfcl.layout import channel_map
    from lfcl.sim.capture import render_grid, simulate_grid
    from lfcl.sim.geometry import scene_frame
    from lfcl.sim.scenes import scene_planes

    sensor = SensorModel(full_well_e=1e8, read_noise_e=0.0, dark_current_e_per_s=0.0, adc_bits=16,
                         exposure_s=1.0e5 / 90)
    cap = simulate_grid("charts", "square", 9.4, 0.7, (0.3, -0.2), lenses=(12, 12), lux=2, seed=0,
                        sensor=sensor, vignetting=True)
    planes = scene_planes("charts", scene_frame("square", cap.sampling.lenses), 0, cap.sampling.views)
    _, radiance = render_grid(planes, cap.sampling)
    H, W = cap.geometry.sensor_shape
    scale = cap.meta["exposure"]["lux_per_scene_unit"] * sensor.electrons_per_lux / sensor.full_well_e
    picked = radiance[np.arange(H * W), channel_map((H, W), "GRBG").ravel()].reshape(H, W)
    expected = picked * scale * cap.geometry.response(vignetting=True)
    np.testing.assert_allclose(cap.normalised_raw(), expected, atol=1e-3)


@pytest.mark.parametrize("args, words", [
    (["--pitch", "9.4"], "--grid"),
    (["--white-only"], "--grid"),
    (["--grid", "hex", "--lightfield", "lf.npy"], "--lightfield"),
    (["--grid", "hex", "--scene", "teapot"], "scene"),
    (["--grid", "square", "--lux", "0"], "lux"),
])
def test_cli_grid_bad_input(tmp_path, cli, args, words):
    out = tmp_path / "never" / "out"
    result = CliRunner().invoke(cli, ["simulate", "--lenses", "8x8", *args, "-o", str(out)])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lfcl: error:") and words in lines[0], result.output
    assert not (tmp_path / "never").exists()


def test_simulate_refuses_a_raw_libraw_cannot_read(tmp_path):
    # LibRaw reads no raw narrower than 22 pixels (lfcl.sim.dng.MIN_DNG_SIDE): 2x3 lenses of 9 pixels would be a
    # DNG that lfcl process refuses, so simulate refuses it; 3x3 lenses (27 pixels) read back.
    from lfcl.cli import cli

    result = CliRunner().invoke(cli, ["simulate", "--lenses", "2x3", "-o", str(tmp_path / "small")])
    assert result.exit_code == 1 and "cannot read: it needs 22 pixels a side" in result.output, result.output
    assert not (tmp_path / "small").exists()
    result = CliRunner().invoke(cli, ["simulate", "--lenses", "3x3", "-o", str(tmp_path / "three")])
    assert result.exit_code == 0, result.output
    assert rawpy.imread(str(tmp_path / "three" / "raw.dng")).raw_image.shape == (27, 27)

"""LinearRaw DNG outputs (lfcl.io.linear_dng, ``--format dng``): pixels, tags, and raw editors that open them.

darktable-cli and rawtherapee-cli come from Debian (`apt-get install darktable rawtherapee`,
.ci/run installs them): a test that cannot find one fails with the command that installs it, so
that no run passes without rendering.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess

import numpy as np
import pytest
import tifffile

from lfcl.evaluation.metrics import centre_view, mean_image
from lfcl.io.linear_dng import COLOUR_TAGS, WHITE_LEVEL, DngCamera, write_linear_dng
from lfcl.outputs.files import plan_outputs, write_outputs
from lfcl.pipeline.stages import Decode, Demosaic, Grid, Outputs

# Canon EOS 5D Mark II, dcraw's adobe_coeff (XYZ D65 -> camera, / 10000): a real matrix, far from sRGB.
CANON_XYZ_TO_CAMERA = np.array([4716, 603, -830, -7798, 15474, 2480, -1496, 1937, 6651]).reshape(3, 3) / 10000
CANON_WB = (2.0, 1.0, 1.5)  # as-shot multipliers, G = 1


def tags_of(path) -> dict:
    with tifffile.TiffFile(str(path)) as tif:
        assert len(tif.pages) == 1
        page = tif.pages[0]
        tags = {t.code: t.value for t in page.tags.values()}
        tags["_page"] = {"tiled": page.is_tiled, "shape": page.shape, "dtype": page.dtype, "data": page.asarray()}
    return tags


def floats(value) -> np.ndarray:
    """Flat numerator, denominator pairs (tifffile's rationals) -> floats."""
    v = np.asarray(value, np.float64).ravel()
    return v[0::2] / v[1::2]


def patches(camera: DngCamera, shape=(200, 240)) -> np.ndarray:
    """Left half: a grey that the camera's as-shot neutral makes neutral; right half: a green."""
    neutral = np.asarray(camera.colour[50728])
    image = np.zeros((*shape, 3), np.float32)
    image[:, : shape[1] // 2] = 0.18 * neutral / neutral.max()
    image[:, shape[1] // 2:] = (0.05, 0.2, 0.05)
    return image


@pytest.fixture(scope="module")
def canon():
    return DngCamera.from_matrix(CANON_XYZ_TO_CAMERA, CANON_WB, make="Canon", model="EOS 5D Mark II")


@pytest.fixture(scope="module")
def demosaiced(tmp_path_factory):
    """A simulated capture (24x24 lenses of 9x9 px), Malvar-demosaiced once for the module."""
    from lfcl.sim import simulate, write_capture

    cap = tmp_path_factory.mktemp("cap")
    write_capture(simulate("charts", lenses=(24, 24), seed=5), cap)
    raw = cap / "raw.dng"
    return raw, Demosaic("malvar")(Grid(pitch=9)(Decode()(raw)))


# --------------------------------------------------------------------------- the file

def test_pixels_equal_the_exr(demosaiced, tmp_path):
    """The DNG's codes are round(65535 x the EXR's values), clipped to [0, 65535]."""
    from lfcl.io.images import read_image

    _, dem = demosaiced
    Outputs("center,mean,refocus", refocus="0.5", fmt="exr", previews=False)(dem, tmp_path / "exr")
    dng = Outputs("center,mean,refocus", refocus="0.5", fmt="dng", previews=False)(dem, tmp_path / "dng")
    assert sorted(p.name for p in dng.paths) == ["center.dng", "mean.dng", "refocus_+0.5.dng"]
    for name in ("center", "mean", "refocus_+0.5"):
        values = read_image(tmp_path / "exr" / f"{name}.exr").astype(np.float64)
        codes = tags_of(tmp_path / "dng" / f"{name}.dng")["_page"]["data"]
        assert codes.dtype == np.uint16 and codes.shape == values.shape
        expected = np.clip(values * WHITE_LEVEL, 0, WHITE_LEVEL)
        assert np.abs(codes - expected).max() <= 0.5 + 1e-6, name
        assert 0 < codes.mean() < WHITE_LEVEL  # not all clipped: the test would mean nothing
    np.testing.assert_allclose(read_image(tmp_path / "exr" / "center.exr"), centre_view(dem.lightfield), atol=0)


def test_layout_and_tags_round_trip(demosaiced, tmp_path):
    """The layout raw editors read, and the input DNG's names and colour tags carried as they were."""
    raw, dem = demosaiced
    Outputs("center", fmt="dng", previews=False, metadata={"generator": "test"})(dem, tmp_path)
    tags = tags_of(tmp_path / "center.dng")
    page = tags["_page"]
    assert not page["tiled"] and page["shape"] == (24, 24, 3) and page["dtype"] == np.uint16
    assert tags[254] == 0 and tags[262] == 34892 and tags[277] == 3 and tags[258] == (16, 16, 16)
    assert tags[259] == 1 and tags[284] == 1  # uncompressed, interleaved
    assert tags[50706] == b"\x01\x04\x00\x00" and 50707 in tags
    assert tuple(tags[50714]) == (0, 0, 0) and tuple(tags[50717]) == (WHITE_LEVEL,) * 3
    with tifffile.TiffFile(str(raw)) as tif:  # the simulator's DNG: what the output must carry
        source = {t.code: t.value for t in tif.pages[0].tags.values()}
    for code in (271, 272, 50708, 274):
        assert tags[code] == source[code], code
    for code in (50721, 50728):
        np.testing.assert_allclose(floats(tags[code]), floats(source[code]), rtol=0, atol=1e-6)
    assert tags[50778] == source[50778] == 21
    meta = json.loads(tags[270])["lfcl"]
    assert meta["method"] == "malvar" and meta["output"] == "center" and meta["generator"] == "test"
    assert meta["source"] == str(raw) and "parameters" in meta
    assert meta["dng"]["colour_tags"] == "the input DNG's colour tags, as they were"


def test_carries_a_dngs_second_matrix_and_forward_matrices(tmp_path):
    """An input DNG's ColorMatrix2, ForwardMatrix1/2, illuminants and BaselineExposure come through unchanged."""
    from lfcl.io.linear_dng import rationals
    from lfcl.io.raw import read_mosaic
    from lfcl.sim.dng import dng_tags

    mosaic = (np.random.default_rng(0).random((48, 64)) * 3000 + 64).astype(np.uint16)
    base = [t for t in dng_tags("RGGB", 64, 4095) if t[0] not in (271, 272, 50708, 50721, 50728, 50778)]
    cm2 = (CANON_XYZ_TO_CAMERA * 1.1).ravel()
    fm1 = np.array([0.7, 0.1, 0.15, 0.3, 0.6, 0.1, 0.0, 0.05, 0.8])
    extra = [(271, 2, 0, "Canon", True), (272, 2, 0, "Canon EOS 5D Mark II", True),
             (50708, 2, 0, "Canon EOS 5D Mark II test", True),
             (50721, 10, 9, rationals(CANON_XYZ_TO_CAMERA.ravel(), True), True),
             (50722, 10, 9, rationals(cm2, True), True),
             (50778, 3, 1, 17, True), (50779, 3, 1, 21, True),
             (50964, 10, 9, rationals(fm1, True), True), (50965, 10, 9, rationals(fm1 * 0.9, True), True),
             (50730, 10, 1, rationals([0.35], True), True),
             (50728, 5, 3, rationals([0.5, 1, 0.625], False), True)]
    path = tmp_path / "cam.dng"
    tifffile.imwrite(str(path), mosaic, photometric=32803, metadata=None, subfiletype=0, extratags=base + extra)
    camera = DngCamera.from_mosaic(read_mosaic(path))
    assert (camera.make, camera.model, camera.unique_model) == ("Canon", "Canon EOS 5D Mark II",
                                                               "Canon EOS 5D Mark II test")
    write_linear_dng(tmp_path / "out.dng", np.full((30, 40, 3), 0.25, np.float32), camera)
    tags = tags_of(tmp_path / "out.dng")
    for code, want in ((50721, CANON_XYZ_TO_CAMERA.ravel()), (50722, cm2), (50964, fm1), (50965, fm1 * 0.9),
                       (50730, [0.35]), (50728, [0.5, 1, 0.625])):
        np.testing.assert_allclose(floats(tags[code]), want, atol=1e-4, err_msg=COLOUR_TAGS[code][0])
    assert tags[50778] == 17 and tags[50779] == 21
    assert tags[271] == "Canon" and tags[50708] == "Canon EOS 5D Mark II test"
    # a BaselineExposure of 0/0 (as a real DNG of ../shared holds) drops that tag alone, not the camera's names
    extra[-2] = (50730, 10, 1, (0, 0), True)
    tifffile.imwrite(str(path), mosaic, photometric=32803, metadata=None, subfiletype=0, extratags=base + extra)
    camera = DngCamera.from_mosaic(read_mosaic(path))
    assert camera.make == "Canon" and 50730 not in camera.colour
    np.testing.assert_allclose(camera.colour[50722], cm2, atol=1e-4)


def test_camera_from_libraw_metadata_and_without_any():
    """A raw without DNG colour tags: LibRaw's cam_xyz as ColorMatrix1 (D65), neutral = 1 / the multipliers."""
    from lfcl.io.raw import Mosaic

    mosaic = Mosaic(data=np.zeros((4, 4), np.float32), pattern="RGGB", as_shot_wb=CANON_WB,
                    xyz_to_camera=CANON_XYZ_TO_CAMERA.astype(np.float32), camera="Canon EOS 5D Mark II")
    camera = DngCamera.from_mosaic(mosaic)
    np.testing.assert_allclose(camera.colour[50721], CANON_XYZ_TO_CAMERA.ravel(), atol=1e-6)
    np.testing.assert_allclose(camera.colour[50728], [0.5, 1.0, 1 / 1.5])
    assert camera.colour[50778] == (21,) and camera.model == "Canon EOS 5D Mark II"
    bare = DngCamera.from_mosaic(Mosaic(data=np.zeros((4, 4), np.float32), pattern="RGGB"))
    assert "declared linear sRGB" in bare.source
    srgb_d65 = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]])
    np.testing.assert_allclose(bare.colour[50721], srgb_d65.ravel())
    np.testing.assert_allclose(bare.colour[50728], [1, 1, 1], atol=2e-3)  # sRGB's response to D65: neutral


def test_bad_input_is_one_line(tmp_path):
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        write_linear_dng(tmp_path / "x.dng", np.zeros((4, 4), np.float32))
    with pytest.raises(ValueError, match="AsShotNeutral"):
        DngCamera("a", "b", "a b", {50721: (1.0,) * 9, 50778: (21,), 50728: (0.0, 1.0, 1.0)}, "test")
    with pytest.raises(ValueError, match="not finite"):
        DngCamera("a", "b", "a b", {50721: (np.nan,) * 9, 50778: (21,), 50728: (1.0,) * 3}, "test")
    assert not (tmp_path / "x.dng").exists()


def test_plan_views_each_and_cli_choices(tmp_path):
    """Every image output becomes a DNG (views-each included); process and batch take --format dng."""
    from lfcl.cli.commands import batch, process

    lightfield = (np.random.default_rng(1).random((22, 24, 3, 3, 3)) * 0.5).astype(np.float32)  # LibRaw's least
    plan = plan_outputs(lightfield, ["center", "mean", "views", "views-each", "refocus"], slopes=[0.5], fmt="dng",
                        previews=False)
    names = [f.name for f in plan.files]
    assert names[:3] == ["center.dng", "mean.dng", "views.dng"] and "view_02_01.dng" in names
    assert "refocus_+0.5.dng" in names and all(f.writer == "dng" for f in plan.files)
    written = write_outputs(tmp_path, plan.files)
    codes = tags_of(tmp_path / "mean.dng")["_page"]["data"]
    expected = np.rint(np.clip(mean_image(lightfield), 0, 1) * WHITE_LEVEL)  # up to one code: float32 rounding ties
    np.testing.assert_allclose(codes, expected, rtol=0, atol=1)
    assert len(written) == len(names)
    for module in (process, batch):
        choices = {p.name: p for p in module.command.params}["fmt"].type.choices
        assert "dng" in choices, module.__name__


# --------------------------------------------------------------------------- raw editors

def test_rawpy_opens_and_renders_it(canon, tmp_path):
    import rawpy  # a dependency of lfcl
    path = write_linear_dng(tmp_path / "p.dng", patches(canon), canon, {"method": "test"})
    with rawpy.imread(str(path)) as raw:
        np.testing.assert_allclose(raw.rgb_xyz_matrix[:3], CANON_XYZ_TO_CAMERA, atol=1e-4)
        np.testing.assert_allclose(raw.camera_whitebalance[:3], CANON_WB, atol=1e-4)
        rgb = raw.postprocess(use_camera_wb=True, output_bps=16).astype(np.float64)
    grey, green = rgb[100, 60], rgb[100, 180]
    assert grey.max() - grey.min() <= 2e-3 * grey.max()  # the as-shot neutral renders neutral
    assert green[1] > 2 * green[0] and green[1] > 2 * green[2]


def editor(name: str) -> str:
    """The path of a raw editor's command line tool; the test fails, naming the install, when it is missing."""
    path = shutil.which(name)
    if path is None:
        pytest.fail(f"{name} is not installed: `apt-get install darktable rawtherapee` (Debian) to run this test; "
                    ".ci/run installs them")
    return path


def read_png(path) -> np.ndarray:
    import OpenImageIO as oiio

    image = oiio.ImageBuf(str(path))
    assert not image.has_error, image.geterror()
    return image.get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


def check_render(rgb: np.ndarray, what: str):
    assert rgb.shape[:2] == (200, 240), what
    grey, green = rgb[100, 60], rgb[100, 180]
    assert grey.max() - grey.min() <= 1.5 / 255, (what, grey * 255)  # neutral within 8-bit rounding
    assert 0.2 < grey.mean() < 0.9, (what, grey)
    assert green[1] > 2 * green[0] and green[1] > 1.5 * green[2], (what, green * 255)


def test_darktable_renders_it(canon, tmp_path):
    cli = editor("darktable-cli")
    path = write_linear_dng(tmp_path / "p.dng", patches(canon), canon, {"method": "test"})
    out = tmp_path / "dt.png"
    # workflow=none: plain sRGB, without the scene-referred default's +0.7 EV and tone mapping
    run = subprocess.run([cli, str(path), str(out), "--core", "--configdir", str(tmp_path / "dtconf"),
                          "--conf", "plugins/darkroom/workflow=none"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and out.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    check_render(read_png(out), "darktable")


def test_rawtherapee_renders_it(canon, tmp_path):
    cli = editor("rawtherapee-cli")
    path = write_linear_dng(tmp_path / "p.dng", patches(canon), canon, {"method": "test"})
    out = tmp_path / "rt.png"
    run = subprocess.run([cli, "-o", str(out), "-n", "-Y", "-c", str(path)], capture_output=True, text=True,
                         timeout=120, env={**os.environ, "HOME": str(tmp_path)})
    assert run.returncode == 0 and out.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    check_render(read_png(out), "RawTherapee")


def test_a_real_dng_keeps_its_camera_names_and_colour_tags():
    """tinydng's colorchart.dng holds a BaselineExposure of 0/0: its Make, UniqueCameraModel, ColorMatrix1 and
    AnalogBalance still reach the LinearRaw DNG (they were all replaced by LibRaw's before)."""
    from conftest import shared_path

    from lfcl.io.raw import read_mosaic

    camera = DngCamera.from_mosaic(read_mosaic(shared_path("realdata", "tinydng", "colorchart.dng")))
    assert (camera.make, camera.unique_model) == ("Canon", "Canon EOS Kiss X4")
    assert {50721, 50727, 50728} <= set(camera.colour) and "as they were" in camera.source

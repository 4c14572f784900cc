"""``lfcl demosaic`` through click's CliRunner (the command itself, not the whole group)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.cli.commands.demosaic import command

SHARED = Path(os.environ.get("LFCL_SHARED", Path(__file__).resolve().parents[2] / "shared"))
LIGHTHOUSE_CFA = SHARED / "data" / "lighthouse" / "Lighthouse_CFA_GRBG.exr"
COLORCHART = SHARED / "realdata" / "tinydng" / "colorchart.dng"


def shared_file(path: Path) -> Path:
    if not SHARED.is_dir():
        pytest.skip(f"shared test data folder {SHARED} is absent (set LFCL_SHARED to point at it)")
    assert path.is_file(), f"{path} is missing from the shared data"
    return path


def run(*args):
    return CliRunner().invoke(command, [str(a) for a in args])


def header(path) -> dict:
    import OpenImageIO as oiio

    spec = oiio.ImageInput.open(str(path)).spec()
    return {a.name[5:]: a.value for a in spec.extra_attribs if a.name.startswith("lfcl:")}


def assert_failed_cleanly(result, folder: Path, expected: str):
    """Non-zero exit, exactly one line on stderr naming the problem, nothing left in ``folder``."""
    assert result.exit_code != 0, result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("lfcl: error: ")
    assert expected in lines[0], lines[0]
    assert sorted(p.name for p in folder.iterdir()) == [], "output or temporary files were left behind"


def test_lighthouse_exr_equals_malvar(tmp_path):
    from lfcl.io.images import read_image
    from lfcl.ops.malvar import malvar, malvar_np

    source = shared_file(LIGHTHOUSE_CFA)
    out = tmp_path / "lighthouse.exr"
    result = run(source, "--pattern", "GRBG", "--method", "malvar", "-o", out)
    assert result.exit_code == 0, result.output
    assert out.is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["lighthouse.exr"]

    written = read_image(out)
    mosaic = read_image(source)[:, :, 0]
    expected = malvar(mosaic, "GRBG")
    assert written.shape == (768, 512, 3)
    np.testing.assert_allclose(written, expected, rtol=0, atol=1e-6)
    np.testing.assert_allclose(written, malvar_np(mosaic, "GRBG").transpose(1, 2, 0), rtol=0, atol=1e-5)
    # Malvar overshoots at edges: values outside [0, 1] must survive in the EXR
    outside = (expected < 0) | (expected > 1)
    if outside.any():
        assert ((written < 0) | (written > 1)).sum() == outside.sum()
        np.testing.assert_array_equal(written[outside], expected[outside])

    meta = header(out)
    assert meta["method"] == "malvar"
    assert meta["pattern"] == "GRBG"
    assert meta["source"] == str(source)
    assert json.loads(meta["black"]) == [0.0] * 4 and json.loads(meta["white"]) == 1.0


def test_dng_without_pattern(tmp_path):
    from lfcl.io.images import read_image
    from lfcl.io.raw import read_mosaic
    from lfcl.ops.malvar import malvar

    source = shared_file(COLORCHART)
    out = tmp_path / "colorchart.exr"
    result = run(source, "-o", out)
    assert result.exit_code == 0, result.output
    written = read_image(out)
    assert written.shape == (1156, 1734, 3)
    expected = malvar(read_mosaic(source).data, "RGGB")
    np.testing.assert_allclose(written, expected, rtol=0, atol=1e-6)
    assert written.min() < 0  # below-black noise is not clipped
    meta = header(out)
    assert meta["pattern"] == "RGGB"
    assert json.loads(meta["black"]) == [2056.0] * 4 and json.loads(meta["white"]) == 15000.0

    # the matching pattern may be given; 16-bit TIFF output clips to [0, 1]
    tif = tmp_path / "colorchart.tif"
    result = run(source, "--pattern", "rggb", "-o", tif)
    assert result.exit_code == 0, result.output
    as_tif = read_image(tif)
    np.testing.assert_allclose(as_tif, np.clip(expected, 0, 1), atol=1 / 65535)


def test_png_output(tmp_path):
    from lfcl.io.images import read_image

    out = tmp_path / "chart.png"
    result = run(shared_file(COLORCHART), "-o", out)
    assert result.exit_code == 0, result.output
    assert read_image(out).shape == (1156, 1734, 3)


def test_bad_pattern(tmp_path):
    outdir = tmp_path / "out"
    outdir.mkdir()
    result = run(shared_file(LIGHTHOUSE_CFA), "--pattern", "XYZW", "-o", outdir / "x.exr")
    assert_failed_cleanly(result, outdir, "unknown Bayer pattern 'XYZW'")


def test_pattern_disagreeing_with_raw(tmp_path):
    outdir = tmp_path / "out"
    outdir.mkdir()
    result = run(shared_file(COLORCHART), "--pattern", "GRBG", "-o", outdir / "x.exr")
    assert_failed_cleanly(result, outdir, "disagrees")


def test_image_without_pattern(tmp_path):
    outdir = tmp_path / "out"
    outdir.mkdir()
    result = run(shared_file(LIGHTHOUSE_CFA), "-o", outdir / "x.exr")
    assert_failed_cleanly(result, outdir, "pattern")


def test_unreadable_input(tmp_path):
    indir, outdir = tmp_path / "in", tmp_path / "out"
    indir.mkdir()
    outdir.mkdir()
    junk = indir / "junk.dng"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    assert_failed_cleanly(run(junk, "-o", outdir / "x.exr"), outdir, "junk.dng")
    truncated = indir / "cut.dng"
    truncated.write_bytes(shared_file(COLORCHART).read_bytes()[:10 * 1024])
    assert_failed_cleanly(run(truncated, "-o", outdir / "x.exr"), outdir, "cut.dng")
    assert_failed_cleanly(run(indir / "missing.exr", "--pattern", "RGGB", "-o", outdir / "x.exr"), outdir, "missing.exr")


def test_not_bayer_input(tmp_path):
    outdir = tmp_path / "out"
    outdir.mkdir()
    nef = shared_file(SHARED / "realdata" / "imageio_test_images" / "Nikon_uncompressed.nef")
    assert_failed_cleanly(run(nef, "-o", outdir / "x.exr"), outdir, "not a Bayer sensor")


def test_rgb_image_input(tmp_path):
    from lfcl.io.images import write_image

    indir, outdir = tmp_path / "in", tmp_path / "out"
    indir.mkdir()
    outdir.mkdir()
    rgb = indir / "rgb.exr"
    write_image(rgb, np.random.default_rng(0).uniform(0, 1, (8, 10, 3)).astype(np.float32))
    assert_failed_cleanly(run(rgb, "--pattern", "RGGB", "-o", outdir / "x.exr"), outdir, "8x10x3")


def test_wrong_output_extension(tmp_path):
    outdir = tmp_path / "out"
    outdir.mkdir()
    result = run(shared_file(LIGHTHOUSE_CFA), "--pattern", "GRBG", "-o", outdir / "x.jpg")
    assert_failed_cleanly(result, outdir, "'.jpg'")
    result = run(shared_file(LIGHTHOUSE_CFA), "--pattern", "GRBG", "-o", outdir / "noext")
    assert_failed_cleanly(result, outdir, "unsupported output extension")


def test_unknown_method(tmp_path):
    outdir = tmp_path / "out"
    outdir.mkdir()
    result = run(shared_file(LIGHTHOUSE_CFA), "--pattern", "GRBG", "--method", "ahd", "-o", outdir / "x.exr")
    assert result.exit_code != 0
    assert "ahd" in result.stderr
    assert list(outdir.iterdir()) == []


def test_bogus_device(tmp_path):
    outdir = tmp_path / "out"
    outdir.mkdir()
    result = run(shared_file(LIGHTHOUSE_CFA), "--pattern", "GRBG", "--device", "no-such-device", "-o", outdir / "x.exr")
    assert_failed_cleanly(result, outdir, "no-such-device")


def test_synthetic_mosaic_without_shared_data(tmp_path):
    """A small float mosaic written here: the command works without ../shared."""
    from lfcl.io.images import read_image, write_image
    from lfcl.ops.malvar import malvar_np

    mosaic = np.random.default_rng(3).uniform(-0.05, 1.2, (12, 16)).astype(np.float32)
    source = tmp_path / "m.exr"
    write_image(source, mosaic)
    out = tmp_path / "rgb.exr"
    result = run(source, "--pattern", "BGGR", "-o", out)
    assert result.exit_code == 0, result.output
    written = read_image(out)
    np.testing.assert_allclose(written, malvar_np(mosaic, "BGGR").transpose(1, 2, 0), atol=1e-5)
    assert written.min() < 0 and written.max() > 1


def test_libraw_messages_stay_in_the_one_line(tmp_path):
    """LibRaw prints "Unexpected end of file" on the process's real stderr (fd 2), which
    CliRunner does not see: run the command in a subprocess to check it is folded in."""
    import subprocess
    import sys

    truncated = tmp_path / "cut.dng"
    truncated.write_bytes(shared_file(COLORCHART).read_bytes()[:10 * 1024])
    outdir = tmp_path / "out"
    outdir.mkdir()
    code = "from lfcl.cli.commands.demosaic import command; command()"
    proc = subprocess.run(
        [sys.executable, "-c", code, str(truncated), "-o", str(outdir / "x.exr")],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("lfcl: error: ") and "cut.dng" in lines[0] and "Unexpected end of file" in lines[0]
    assert list(outdir.iterdir()) == []

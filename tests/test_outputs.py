"""The output stage (lfcl.outputs.files) and `lfcl process` end to end on a small simulated capture."""

from __future__ import annotations

import json

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from lfcl.cli import cli
from lfcl.evaluation.metrics import centre_view, mean_image
from lfcl.io.images import read_image
from lfcl.layout import tiled_views
from lfcl.outputs.files import KINDS, parse_outputs, plan_outputs, view_name, write_outputs
from lfcl.outputs.refocus import refocus

S, T, U, V = 12, 14, 9, 9


def header(path) -> dict:
    """The lfcl metadata of an image (ImageDescription JSON) and its spec."""
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    inp.close()
    return {"spec": spec, "lfcl": json.loads(spec.getattribute("ImageDescription"))["lfcl"]}


# --------------------------------------------------------------------------- the stage on its own

@pytest.fixture
def lightfield(rng):
    return (rng.random((5, 6, 3, 3, 3)) * 0.5).astype(np.float32)


def test_plan_computes_only_what_was_asked(lightfield):
    plan = plan_outputs(lightfield, ["center"], previews=False)
    assert [f.name for f in plan.files] == ["center.exr"]
    assert set(plan.seconds) == {"center"}
    reasons = {s["output"]: s["reason"] for s in plan.skipped}
    assert set(reasons) == set(KINDS) - {"center"} | {"previews"} and reasons["previews"] == "--no-previews"
    plan = plan_outputs(lightfield, ["lightfield"])
    assert [f.name for f in plan.files] == ["lightfield.npy"] and plan.colour is None


def test_plan_images_and_names(lightfield):
    plan = plan_outputs(lightfield, ["center", "mean", "views", "views-each", "refocus", "lightfield"],
                        slopes=[-0.5, 0, 0.25], fmt="tiff", metadata={"method": "m"})
    names = [f.name for f in plan.files]
    assert names[:6] == ["center.tif", "center.png", "mean.tif", "mean.png", "views.tif", "views.png"]
    assert "view_00_00.tif" in names and "view_02_02.png" in names and len([n for n in names if n.startswith("view_")]) == 18
    assert [r["file"] for r in plan.refocus] == ["refocus_-0.5.tif", "refocus_+0.tif", "refocus_+0.25.tif"]
    data = {f.name: f.data for f in plan.files}
    np.testing.assert_array_equal(data["center.tif"], centre_view(lightfield))
    np.testing.assert_array_equal(data["mean.tif"], mean_image(lightfield))
    np.testing.assert_array_equal(data["views.tif"], tiled_views(lightfield))
    np.testing.assert_array_equal(data["view_02_01.tif"], lightfield[:, :, 2, 1])
    np.testing.assert_array_equal(data["refocus_+0.25.tif"], refocus(lightfield, 0.25))
    assert data["center.png"].shape == (5, 6, 3)
    meta = {f.name: f.metadata for f in plan.files}
    assert meta["view_02_01.tif"]["view"] == [2, 1] and meta["refocus_-0.5.png"]["slope"] == -0.5
    assert meta["center.tif"]["method"] == "m" and "preview_colour" in meta["center.tif"]
    with pytest.raises(ValueError, match="needs slopes"):
        plan_outputs(lightfield, ["refocus"])


def test_cli_lists_the_same_kinds():
    from lfcl.cli.commands.process import OUTPUTS

    assert OUTPUTS == KINDS


def test_view_names_pad_to_the_grid():
    assert view_name(3, 4, 9, 9) == "view_03_04"
    assert view_name(3, 104, 15, 120) == "view_003_104"


@pytest.mark.parametrize("text,message", [("center,nope", "unknown outputs nope"), (" , ", "(none)")])
def test_parse_outputs_rejects(text, message):
    with pytest.raises(ValueError, match=message):
        parse_outputs(text)


def test_write_is_all_or_nothing(lightfield, tmp_path, monkeypatch):
    import lfcl.io.images

    plan = plan_outputs(lightfield, ["center", "mean", "views"], previews=True)
    calls = []
    real = lfcl.io.images.write_image

    def flaky(path, *args, **kwargs):
        calls.append(path)
        if len(calls) == 4:
            raise OSError(f"cannot write {path}: disk full")
        return real(path, *args, **kwargs)

    monkeypatch.setattr(lfcl.io.images, "write_image", flaky)
    out = tmp_path / "new" / "out"
    with pytest.raises(OSError, match="disk full"):
        write_outputs(out, plan.files)
    assert len(calls) == 4 and not (tmp_path / "new").exists()
    # into an existing folder: what this run wrote goes, what was there stays
    out.mkdir(parents=True)
    (out / "keep.txt").write_text("x")
    calls.clear()
    with pytest.raises(OSError):
        write_outputs(out, plan.files)
    assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]


@pytest.mark.parametrize("where", ["after the temporary file is made", "after the rename"])
def test_an_interrupt_anywhere_in_a_write_leaves_nothing(lightfield, tmp_path, monkeypatch, where):
    """Ctrl-C lands between any two bytecodes: between mkstemp and the guarded block, or after a file's rename
    but before write_outputs records it. Neither leaves a file behind (an audit saw both)."""
    import lfcl.io.images
    import lfcl.outputs.files

    plan = plan_outputs(lightfield, ["center", "mean", "views"], previews=True)
    count = []
    if where == "after the temporary file is made":
        real_close = lfcl.io.images.os.close

        def close(fd):
            real_close(fd)
            count.append(fd)
            if len(count) == 3:
                raise KeyboardInterrupt

        monkeypatch.setattr(lfcl.io.images.os, "close", close)
    else:
        real_one = lfcl.outputs.files._write_one

        def write_one(out_dir, f):
            path = real_one(out_dir, f)
            count.append(path)
            if len(count) == 3:
                raise KeyboardInterrupt
            return path

        monkeypatch.setattr(lfcl.outputs.files, "_write_one", write_one)
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    with pytest.raises(KeyboardInterrupt):
        write_outputs(out, plan.files)
    assert len(count) == 3 and sorted(p.name for p in out.iterdir()) == ["keep.txt"]


# --------------------------------------------------------------------------- the CLI

@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    out = tmp_path_factory.mktemp("cap") / "capture"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "deadleaves", "--lenses", f"{S}x{T}", "--lux", "8",
                                      "--seed", "4", "--vignetting", "-o", str(out)])
    assert result.exit_code == 0, result.output
    return out


def run(*args):
    return CliRunner().invoke(cli, ["process", *map(str, args)])


def test_every_output_kind_end_to_end(capture, tmp_path):
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "--method", "admm-uv", "--iterations", "3", "-o", out,
                 "--outputs", "center,mean,views,views-each,refocus,lightfield,depth", "--refocus", "-1:1:0.5",
                 "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary == json.loads((out / "summary.json").read_text())
    assert summary["method"] == "admm-uv" and summary["iterations"] == 3 and summary["parameters"]["max_iter"] == 3
    assert [r["slope"] for r in summary["refocus"]] == [-1, -0.5, 0, 0.5, 1]
    assert [r["file"] for r in summary["refocus"]][:3] == ["refocus_-1.exr", "refocus_-0.5.exr", "refocus_+0.exr"]
    assert set(summary["seconds"]) == {"decode", "demosaic", "outputs"}
    assert {s["output"] for s in summary["skipped"] if s.get("stage") != "demosaic"} == set()  # every output
    assert summary["colour"]["white_balance"]["source"] == "as shot"

    lf = np.load(out / "lightfield.npy")
    assert lf.shape == (S, T, U, V, 3) and lf.dtype == np.float32
    names = sorted(p.name for p in out.iterdir())
    expected = {"summary.json", "lightfield.npy", "depth.exr", "depth_confidence.exr", "depth.png"}
    for stem in ["center", "mean", "views"] + [f"view_{u:02d}_{v:02d}" for u in range(U) for v in range(V)] + [
            "refocus_-1", "refocus_-0.5", "refocus_+0", "refocus_+0.5", "refocus_+1"]:
        expected |= {stem + ".exr", stem + ".png"}
    assert set(names) == expected and sorted(summary["outputs"] + ["summary.json"]) == names

    np.testing.assert_array_equal(read_image(out / "center.exr"), centre_view(lf))
    np.testing.assert_allclose(read_image(out / "mean.exr"), mean_image(lf), atol=1e-6)
    np.testing.assert_array_equal(read_image(out / "views.exr"), tiled_views(lf))
    np.testing.assert_array_equal(read_image(out / "view_02_07.exr"), lf[:, :, 2, 7])
    np.testing.assert_allclose(read_image(out / "refocus_+0.5.exr"), refocus(lf, 0.5), atol=1e-6)
    assert read_image(out / "views.exr").shape == (U * S, V * T, 3)

    for name, kind in [("center.exr", "center"), ("views.png", "views"), ("view_02_07.exr", "views-each"),
                       ("refocus_-0.5.png", "refocus")]:
        h = header(out / name)
        meta = h["lfcl"]
        assert meta["method"] == "admm-uv" and meta["parameters"]["max_iter"] == 3 and meta["output"] == kind
        assert meta["geometry"]["pitch"] == [9, 9]
        assert h["spec"].getattribute("lfcl:method") == "admm-uv"
    assert header(out / "view_02_07.exr")["lfcl"]["view"] == [2, 7]
    assert header(out / "refocus_-0.5.exr")["lfcl"]["slope"] == -0.5
    png = header(out / "center.png")
    assert png["spec"].format == oiio.UINT8 and (png["spec"].height, png["spec"].width) == (S, T)
    assert png["lfcl"]["colour"]["white_balance"]["gains"] == [1.0, 1.0, 1.0]
    views_png = header(out / "views.png")["spec"]
    assert (views_png.height, views_png.width, views_png.nchannels) == (U * S, V * T, 3)
    assert header(out / "center.exr")["spec"].format == oiio.FLOAT


def test_preview_is_the_srgb_encoding_of_the_scaled_centre_view(capture, tmp_path):
    import colour

    out = tmp_path / "out"
    result = run(capture / "raw.dng", "--method", "malvar", "-o", out, "--outputs", "center", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    scale = summary["colour"]["scale"]
    linear = read_image(out / "center.exr")
    # the simulator's camera RGB is linear sRGB (rawpy's rgb_cam is the identity), AsShotNeutral 1, 1, 1
    expected = colour.cctf_encoding(np.clip(linear * scale, 0, 1), function="sRGB")
    png = read_image(out / "center.png")
    assert np.max(np.abs(png - expected)) <= 1 / 255 + 1e-3
    assert sorted(p.name for p in out.iterdir()) == ["center.exr", "center.png", "summary.json"]
    assert {s["output"] for s in summary["skipped"]} == {"mean", "views", "views-each", "refocus", "lightfield",
                                                         "depth"}


def test_tiff_and_no_previews(capture, tmp_path):
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "--method", "malvar", "-o", out, "--outputs", "mean,lightfield",
                 "--format", "tiff", "--no-previews")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["lightfield.npy", "mean.tif", "summary.json"]
    h = header(out / "mean.tif")
    assert h["spec"].format == oiio.UINT16 and h["lfcl"]["method"] == "malvar"
    lf = np.load(out / "lightfield.npy")
    np.testing.assert_allclose(read_image(out / "mean.tif"), np.clip(mean_image(lf), 0, 1), atol=1 / 65535 + 1e-7)
    assert "skipped:" in result.output and "previews (--no-previews)" in result.output
    assert "time: decode" in result.output and "demosaic" in result.output
    # where it ran: the device that `lfcl devices` marks, in the file and the summary
    from lfcl.device import get_runtime

    ran = get_runtime().device
    assert h["lfcl"]["device"]["name"] == ran.name.strip() and h["lfcl"]["device"]["platform"] == ran.platform.name.strip()
    assert f"device: {ran.name.strip()} (" in result.output


def test_calibration_from_pitch(capture, tmp_path):
    cal = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", "--pitch", "9", "--sensor-shape", f"{S * 9}x{T * 9}", "-o", cal])
    assert result.exit_code == 0, result.output
    ref, out = tmp_path / "ref", tmp_path / "out"
    assert run(capture / "raw.dng", "--method", "malvar", "-o", ref, "--outputs", "lightfield").exit_code == 0
    result = run(capture / "raw.dng", "--method", "malvar", "-o", out, "--outputs", "lightfield,center",
                 "--calibration", cal, "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["calibration"]["file"] == str(cal) and summary["calibration"]["pitch_px"] == 9
    assert summary["geometry"]["first_lens_pixel"] == [0, 0]
    np.testing.assert_array_equal(np.load(out / "lightfield.npy"), np.load(ref / "lightfield.npy"))
    assert header(out / "center.exr")["lfcl"]["calibration"]["packing"] == "square"


def test_calibration_with_an_offset_crops_to_the_first_lens(capture, tmp_path):
    cal = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", "--pitch", "9", "--sensor-shape", f"{S * 9}x{T * 9}",
                                      "--offset=-4,2", "-o", cal])
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "--method", "malvar", "-o", out, "--outputs", "lightfield", "--calibration",
                 cal, "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["geometry"]["first_lens_pixel"] == [5, 2]
    assert np.load(out / "lightfield.npy").shape == (S - 1, T - 1, U, V, 3)


def test_white_image_calibrates_first(capture, tmp_path):
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "--method", "malvar", "-o", out, "--outputs", "lightfield",
                 "--white", capture / "white.dng", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["calibration"]["how"] == "--white" and "calibrate" in summary["seconds"]
    assert summary["geometry"]["pitch"] == [9, 9] and summary["lenses"] == [S, T]
    # the white image's lens response flat-fields the raw (lfcl/grid/vignetting.py)
    response = np.asarray(summary["flat_field"]["lens_response"])
    assert response.shape == (9, 9) and response.max() == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("args,features", [
    (["--rotation", "0.5"], ["rotated"]),
    (["--pitch", "9.4"], ["non-integer-pitch"]),
    (["--packing", "hex", "--pitch", "10"], ["hexagonal"]),
])
def test_other_grids_are_resampled(capture, tmp_path, args, features):
    """Any grid but an aligned square one of integer pitch takes the resampling path (tests/test_process_grids.py)."""
    cal = tmp_path / "cal.json"
    result = CliRunner().invoke(cli, ["calibrate", "--sensor-shape", f"{S * 9}x{T * 9}", "-o", cal,
                                      *(["--pitch", "9"] if "--pitch" not in args else []), *args])
    assert result.exit_code == 0, result.output
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "--method", "malvar", "-o", out, "--outputs", "lightfield", "--calibration",
                 cal, "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["geometry"]["grid"] == "resampled" and summary["geometry"]["features"] == features
    assert np.load(out / "lightfield.npy").shape == (*summary["lenses"], *summary["sampling"]["views"], 3)


def test_calibration_for_another_sensor(capture, tmp_path):
    cal = tmp_path / "cal.json"
    assert CliRunner().invoke(cli, ["calibrate", "--pitch", "9", "--sensor-shape", "99x99", "-o", cal]).exit_code == 0
    result = run(capture / "raw.dng", "-o", tmp_path / "out", "--calibration", cal)
    assert result.exit_code == 1 and "99x99 sensor" in result.output and not (tmp_path / "out").exists()


@pytest.mark.parametrize("args,message", [
    (["--refocus", "0:1"], "start:stop:step"),
    (["--refocus", "1:0:0.5"], "never gets"),
    (["--refocus", "x"], "not a number"),
    (["--outputs", "center,bogus"], "unknown outputs bogus"),
    (["--pitch", "9", "--calibration", "cal.json"], "give the lens grid once"),
    (["--calibration", "missing.json"], "does not exist"),
])
def test_bad_options_are_one_line_and_write_nothing(capture, tmp_path, args, message):
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "-o", out, *args)
    assert result.exit_code == 1
    assert len(result.output.strip().splitlines()) == 1 and message in result.output, result.output
    assert not out.exists()




def test_a_folder_in_an_output_s_place_stops_the_run_before_any_file_is_replaced(capture, tmp_path):
    out = tmp_path / "out"
    assert run(capture / "raw.dng", "-o", out, "--method", "malvar", "--outputs", "center").exit_code == 0
    before = (out / "center.exr").stat()
    (out / "mean.exr").mkdir()
    result = run(capture / "raw.dng", "-o", out, "--method", "malvar", "--outputs", "center,mean")
    assert result.exit_code == 1 and "something other than a file" in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1
    after = (out / "center.exr").stat()  # the same file, untouched (a replacement is a new inode)
    assert (after.st_ino, after.st_mtime_ns) == (before.st_ino, before.st_mtime_ns) and (out / "mean.exr").is_dir()

@pytest.mark.parametrize("fmt", ["dng", "exr"])
def test_an_output_never_replaces_its_input(capture, tmp_path, fmt):
    # The raw sits in the output folder under an output's name (a DNG, or an EXR mosaic): refused, nothing written.
    folder = tmp_path / "folder"
    folder.mkdir()
    raw = folder / f"center.{fmt}"
    if fmt == "dng":  # 22x22 lenses: a DNG view narrower than LibRaw reads is refused before (next test)
        result = CliRunner().invoke(cli, ["simulate", "--lenses", "22x22", "--lux", "8", "-o", str(tmp_path / "c22")])
        assert result.exit_code == 0, result.output
        raw.write_bytes((tmp_path / "c22" / "raw.dng").read_bytes())
        args = []
    else:
        from lfcl.io.images import write_image
        from lfcl.io.raw import read_mosaic

        write_image(raw, read_mosaic(capture / "raw.dng").data)
        args = ["--pattern", "GRBG", "--pitch", "9"]
    before = raw.read_bytes()
    result = run(raw, "-o", folder, "--method", "malvar", "--outputs", "center", "--format", fmt, *args)
    assert result.exit_code == 1
    assert len(result.output.strip().splitlines()) == 1 and "would replace the input" in result.output, result.output
    assert raw.read_bytes() == before
    assert sorted(p.name for p in folder.iterdir()) == [raw.name]


def test_dng_views_narrower_than_raw_editors_read_are_refused_before_the_demosaic(capture, tmp_path):
    # 12x14 lenses: DNGs of 12x14 pixels, which LibRaw (rawpy, darktable, RawTherapee) does not open
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "-o", out, "--method", "malvar", "--outputs", "center", "--format", "dng")
    assert result.exit_code == 1 and "would be DNGs that raw editors cannot open" in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1 and not out.exists()

def test_refocus_alone_implies_the_output(capture, tmp_path):
    out = tmp_path / "out"
    result = run(capture / "raw.dng", "--method", "malvar", "-o", out, "--outputs", "center", "--refocus", "0.5",
                 "--no-previews")
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in out.iterdir()) == ["center.exr", "refocus_+0.5.exr", "summary.json"]
    result = run(capture / "raw.dng", "--method", "malvar", "-o", tmp_path / "o2", "--outputs", "refocus",
                 "--no-previews", "--json")
    assert [r["slope"] for r in json.loads(result.output)["refocus"]] == pytest.approx(np.arange(-1, 1.01, 0.25))


def test_a_full_disk_is_named_with_the_file(lightfield, tmp_path, monkeypatch):
    """numpy reports a full disk as "N requested and M written", without errno: the error names the file and the
    free space, and nothing is left."""
    import collections
    import errno

    import lfcl.io.images
    import lfcl.outputs.files

    plan = plan_outputs(lightfield, ["center", "lightfield"], previews=False)

    def full(path, array):
        raise OSError("248832 requested and 141280 written")

    monkeypatch.setattr(lfcl.io.images, "write_npy", full)
    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(lfcl.outputs.files.shutil, "disk_usage", lambda path: usage(2**20, 2**19, 2**19))
    with pytest.raises(OSError, match=r"lightfield.npy: the disk is full \(0.5 MiB free; 248832 requested") as info:
        write_outputs(tmp_path / "out", plan.files)
    assert info.value.errno == errno.ENOSPC and not (tmp_path / "out").exists()

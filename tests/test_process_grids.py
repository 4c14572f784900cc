"""`lfcl process` (and `lfcl batch`) on calibrated lens grids of every kind, through the CLI (docs/geometry.md,
"Processing these grids with lfcl process"): simulate -> calibrate the white image -> process -> PSNR.

Floors: the charts scene at 1 lux through 16x16 simulated lenses of pitch 9.4 at 0.7 degrees, offset 0.3,-0.2
(the regular block is 15x15 square, 15x14 hex). The floors are those of tests/test_geometry_e2e.py, where
they are justified at 24x24 lenses: centre view 53 dB, mean image 60 dB, inner 5x5 views 53.5 dB (flipped
or swapped views drop the inner views to about 48.8 dB, a grid half a pixel off to about 52.7 dB and the
mean image below 60 dB, a lens index off by one costs 10 dB on the centre view). At 16x16 lenses these runs
measured (centre / mean / inner, dB) rotated malvar 54.67 / 62.17 / 54.22, admm-uv 54.77 / 62.14 / 54.72;
hex malvar 54.18 / 61.92 / 53.77, admm-uv 54.61 / 61.64 / 54.72. The aligned capture (`--grid square
--pitch 9`, disc micro-images) is sliced, not resampled: its mean image is limited by the calibration's
weight model at the rims (docs/geometry.md: 53.4 dB with malvar here), so its floors are 53 dB on the
centre view (the same lens-index argument) and 50 dB on the mean image.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.cli import cli
from lfcl.evaluation.metrics import centre_view, lightfield_scores, mean_image, psnr
from lfcl.io.images import read_image
from lfcl.layout import tiled_views
from lfcl.outputs.refocus import refocus

CENTRE_FLOOR, MEAN_FLOOR, INNER_FLOOR = 53.0, 60.0, 53.5
ALIGNED_MEAN_FLOOR = 50.0
GRIDS = {
    "rotated": ["--grid", "square", "--pitch", "9.4", "--rotation", "0.7", "--offset=0.3,-0.2"],
    "hex": ["--grid", "hex", "--pitch", "9.4", "--rotation", "0.7", "--offset=0.3,-0.2"],
    "aligned": ["--grid", "square", "--pitch", "9"],
}


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def inner_views_psnr(lightfield, truth) -> float:
    """PSNR over the views within 2 view steps of the centre (inside every micro-image)."""
    U, V = truth.shape[2:4]
    u, v = slice(U // 2 - 2, U // 2 + 3), slice(V // 2 - 2, V // 2 + 3)
    return psnr(lightfield[:, :, u, v], truth[:, :, u, v])


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """Each grid simulated (16x16 lenses, 1 lux) and calibrated from its white image by the CLI."""
    root = tmp_path_factory.mktemp("grids")
    for name, args in GRIDS.items():
        result = invoke("simulate", *args, "--lenses", "16x16", "--lux", "1", "-o", root / name)
        assert result.exit_code == 0, result.output
        result = invoke("calibrate", root / name / "white.dng", "-o", root / name / "cal.json")
        assert result.exit_code == 0, result.output
    return root


@pytest.fixture
def any_frame(monkeypatch):
    """These 16x16-lens captures are narrower than auto's smallest frame for a prior (lfcl.demosaic.auto.min_lenses,
    tested in tests/test_auto.py and below): the tests of the rule's mechanics take them with that guard off."""
    import lfcl.demosaic.auto

    monkeypatch.setattr(lfcl.demosaic.auto, "small_frame", lambda lenses, pitch: None)


@pytest.fixture(scope="module")
def processed(captures, tmp_path_factory):
    """``run(grid, method, *options)`` -> (out folder, summary, text): `lfcl process --calibration`, once per set."""
    root, done = tmp_path_factory.mktemp("processed"), {}

    def run(grid, method, *options):
        key = (grid, method, *options)
        if key not in done:
            out = root / f"{len(done)}"
            result = invoke("process", captures / grid / "raw.dng", "--calibration", captures / grid / "cal.json",
                            "--method", method, "-o", out, *options)
            assert result.exit_code == 0, result.output
            done[key] = (out, json.loads((out / "summary.json").read_text()), result.output)
        return done[key]

    return run


def truth(captures, grid):
    return np.load(captures / grid / "truth.npy")


@pytest.mark.parametrize("grid", ["rotated", "hex"])
@pytest.mark.parametrize("method", ["malvar", "admm-uv"])
def test_resampled_grids_reach_the_floors(grid, method, captures, processed):
    out, summary, text = processed(grid, method, "--outputs", "lightfield", "--no-previews")
    lightfield, expected = np.load(out / "lightfield.npy"), truth(captures, grid)
    assert lightfield.shape == expected.shape and lightfield.dtype == np.float32
    scores = lightfield_scores(lightfield, expected)
    scores["inner"] = inner_views_psnr(lightfield, expected)
    assert scores["psnr_center"] >= CENTRE_FLOOR and scores["psnr_mean"] >= MEAN_FLOOR, scores
    assert scores["inner"] >= INNER_FLOOR, scores
    geometry = summary["geometry"]
    assert geometry["grid"] == "resampled" and geometry["lenses"] == list(expected.shape[:2])
    assert geometry["features"] == (["hexagonal"] if grid == "hex" else ["rotated", "non-integer-pitch"])
    sampling = summary["sampling"]  # SamplingModel.as_meta(): the simulator's truth is on the same regular grid
    meta = json.loads((captures / grid / "meta.json").read_text())["lightfield"]
    assert sampling["lens_origin"] == meta["lens_origin"] and sampling["lenses"] == list(expected.shape[:2])
    assert sampling["views"] == list(expected.shape[2:4]) == geometry["pitch"]
    assert summary["method"] == method and "path: resampled" in text and "sliced" not in text


def test_every_output_kind_from_a_resampled_light_field(processed):
    out, summary, _ = processed("hex", "admm-uv", "--outputs", "center,mean,views,refocus,lightfield",
                                "--refocus", "-0.5,0.5")
    lightfield = np.load(out / "lightfield.npy")
    np.testing.assert_array_equal(read_image(out / "center.exr"), centre_view(lightfield))
    np.testing.assert_array_equal(read_image(out / "mean.exr"), mean_image(lightfield))
    np.testing.assert_array_equal(read_image(out / "views.exr"), tiled_views(lightfield))
    np.testing.assert_allclose(read_image(out / "refocus_+0.5.exr"), refocus(lightfield, 0.5), atol=1e-7)
    assert (out / "center.png").is_file() and (out / "refocus_-0.5.png").is_file()
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(out / "center.exr"))
    recorded = json.loads(inp.spec().getattribute("ImageDescription"))["lfcl"]
    inp.close()
    assert recorded["geometry"]["grid"] == "resampled" and recorded["sampling"] == summary["sampling"]
    assert recorded["calibration"]["packing"] == "hex" and recorded["calibration"]["aligned_max_deviation_px"] is None


def test_white_image_path_matches_the_calibration_file(captures, processed, tmp_path):
    out = tmp_path / "white"
    result = invoke("process", captures / "hex" / "raw.dng", "--white", captures / "hex" / "white.dng",
                    "--method", "malvar", "-o", out, "--outputs", "lightfield", "--no-previews", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    assert summary["calibration"]["how"] == "--white" and "calibrate" in summary["seconds"]
    assert summary["geometry"]["grid"] == "resampled" and summary["geometry"]["from"] == "--white"
    reference, reference_summary, _ = processed("hex", "malvar", "--outputs", "lightfield", "--no-previews")
    # the same estimate; cal.json stores the weight model rounded, hence not the same bytes
    np.testing.assert_allclose(np.load(out / "lightfield.npy"), np.load(reference / "lightfield.npy"), atol=1e-4)
    assert summary["sampling"] == reference_summary["sampling"]


def test_an_aligned_calibration_keeps_the_exact_slicing(captures, processed):
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid import load_calibration
    from lfcl.grid.model import AlignedGrid
    from lfcl.grid.vignetting import lens_response_from_calibration
    from lfcl.io.raw import read_mosaic
    from lfcl.layout import LightFieldShape, planes_to_exchange

    out, summary, text = processed("aligned", "malvar", "--outputs", "lightfield", "--no-previews")
    geometry = summary["geometry"]
    assert geometry["grid"] == "aligned-square" and "sampling" not in summary and "path: aligned" in text
    mosaic = read_mosaic(captures / "aligned" / "raw.dng")
    cal = load_calibration(captures / "aligned" / "cal.json", mosaic.data.shape, mosaic.pattern)
    (r0, c0), (S, T) = geometry["first_lens_pixel"], geometry["lenses"]
    grid = AlignedGrid((9, 9), origin=(r0, c0), lens_response=lens_response_from_calibration(cal, (9, 9)))
    planes = demosaic_grid(mosaic.data[r0:r0 + S * 9, c0:c0 + T * 9], mosaic.pattern, grid, "malvar").planes
    lightfield = np.load(out / "lightfield.npy")
    np.testing.assert_array_equal(lightfield, planes_to_exchange(planes, LightFieldShape(S, T, 9, 9)))
    scores = lightfield_scores(lightfield, truth(captures, "aligned"))
    assert scores["psnr_center"] >= CENTRE_FLOOR and scores["psnr_mean"] >= ALIGNED_MEAN_FLOOR, scores


def test_batch_writes_the_same_bytes_as_process(captures, processed, tmp_path):
    out = tmp_path / "batch"
    result = invoke("batch", captures / "rotated" / "raw.dng", "--calibration", captures / "rotated" / "cal.json",
                    "--method", "admm-uv", "-o", out, "--outputs", "lightfield", "--no-previews", "--workers", "1",
                    "--json")
    assert result.exit_code == 0, result.output
    reference, reference_summary, _ = processed("rotated", "admm-uv", "--outputs", "lightfield", "--no-previews")
    assert (out / "raw" / "lightfield.npy").read_bytes() == (reference / "lightfield.npy").read_bytes()
    ours = json.loads((out / "raw" / "summary.json").read_text())

    def same_run(summary):  # timings differ; batch hands the workers resolved paths
        return {k: v for k, v in summary.items() if k not in ("seconds", "output_seconds", "source", "options")}

    assert same_run(ours) == same_run(reference_summary) and ours["sampling"] == reference_summary["sampling"]


@pytest.mark.parametrize("grid", ["rotated", "aligned"])
def test_auto_names_and_runs_its_choice(any_frame, grid, processed):
    from lfcl.demosaic.auto import choose

    out, summary, text = processed(grid, "auto", "--outputs", "lightfield", "--no-previews")
    auto = summary["parameters"]["auto"]
    if grid == "aligned":
        choice = choose(auto["sigma"])
        method, strength, start, reason = choice.method, choice.strength, choice.start, choice.reason
    else:  # the resampled path's priors lose to Malvar on most training captures (docs/auto.md, "Resampled grids")
        method, strength, start, reason = "malvar", 1.0, None, "a rotated, non-integer-pitch square lens grid: every"
        assert auto["sigma"] is None and summary["iterations"] == 0
    assert (auto["method"], auto["strength"], auto["start"]) == (method, strength, start)
    assert summary["method"] == "auto" and f"auto -> {method}" in text and reason[:40] in text
    # auto is its choice run at its strength and start: the same bytes as asking for that method
    spec = method if start is None else f"{method}:{start}"  # None: the method's own start (admm-epi's schedule's)
    chosen, _, _ = processed(grid, spec, "--strength", f"{strength:g}", "--outputs", "lightfield", "--no-previews")
    assert (out / "lightfield.npy").read_bytes() == (chosen / "lightfield.npy").read_bytes()


def _rule(candidate, worst, median=None):
    """A one-band auto rule over every sigma (the shape of lfcl/data/auto_rule.json): worst-case and median
    gains over Malvar per candidate."""
    median = median or worst
    return ({"sigma_from": 0.0, "sigma_to": 1.0, "candidate": candidate, "tie_db": 0.1, "captures": 4,
             "worst_gain_db": worst[candidate], "median_gain_db": median[candidate], "worst_gains_db": worst,
             "median_gains_db": median, "median_seconds": {name: 0.01 if name == "malvar" else 0.2 for name in worst}},)


def _rules(both, **views):
    """A rule file's contents (lfcl.demosaic.auto.load_rules) holding ``both`` for every view but those given."""
    return {"rules": {"both": both, "center": views.get("center", both), "mean": views.get("mean", both)}}


def test_auto_cheap_takes_the_rule_fitted_without_the_costly_methods(any_frame, captures, monkeypatch, tmp_path):
    import lfcl.demosaic.auto

    rules = {**_rules(_rule("admm-st@1", {"malvar": 0.0, "admm-st@1": 0.2})),
             "cheap_rules": _rules(_rule("admm-uv@1", {"malvar": 0.0, "admm-uv@1": 0.1}))["rules"]}
    monkeypatch.setattr(lfcl.demosaic.auto, "load_rules", lambda: rules)
    runs = {}
    for flag in ("--auto-costly", "--auto-cheap"):
        out = tmp_path / flag
        result = invoke("process", captures / "aligned" / "raw.dng", "--calibration", captures / "aligned" / "cal.json",
                        flag, "-o", out, "--outputs", "center", "--no-previews", "--json")
        assert result.exit_code == 0, result.output
        runs[flag] = json.loads(result.output)
    assert runs["--auto-costly"]["parameters"]["auto"]["method"] == "admm-st"
    cheap = runs["--auto-cheap"]
    assert cheap["parameters"]["auto"]["method"] == "admm-uv" and cheap["parameters"]["auto"]["costly"] is False
    assert cheap["parameters"]["auto"]["reason"].startswith("without the costly methods (admm-epi): ")
    assert cheap["options"]["auto_costly"] is False and runs["--auto-costly"]["options"]["auto_costly"] is True
    # a method other than auto does not record the switch
    out = tmp_path / "uv"
    result = invoke("process", captures / "aligned" / "raw.dng", "--calibration", captures / "aligned" / "cal.json",
                    "--method", "admm-uv", "--auto-cheap", "-o", out, "--outputs", "center", "--no-previews", "--json")
    assert result.exit_code == 0 and "auto_costly" not in json.loads(result.output)["options"]


def test_auto_lists_what_it_skipped_for_a_safer_method(any_frame, captures, monkeypatch, tmp_path):
    import lfcl.demosaic.auto

    # admm-uv gains more in the middle but loses 0.5 dB to Malvar somewhere: Malvar is the pick
    monkeypatch.setattr(lfcl.demosaic.auto, "load_rules", lambda: _rules(_rule("malvar", {"malvar": 0.0, "admm-uv@1": -0.5},
                                                                      {"malvar": 0.0, "admm-uv@1": 1.5})))
    out = tmp_path / "out"
    result = invoke("process", captures / "aligned" / "raw.dng", "--calibration", captures / "aligned" / "cal.json",
                    "--method", "auto", "-o", out, "--outputs", "lightfield", "--no-previews")
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["parameters"]["auto"]["method"] == "malvar" and summary["iterations"] == 0
    skipped = [s for s in summary["skipped"] if s.get("stage") == "demosaic"]
    assert [s["output"] for s in skipped] == ["admm-uv@1"]
    assert "auto chose malvar: worst-case gain over Malvar +0.00 dB against -0.50 dB" in skipped[0]["reason"]
    assert "median +0.00 dB against +1.50 dB" in skipped[0]["reason"]
    assert "skipped:" in result.output and "admm-uv@1 (auto chose malvar" in result.output


@pytest.mark.parametrize("grid", ["rotated", "hex"])
def test_auto_runs_malvar_on_a_resampled_grid_whatever_the_rule_says(any_frame, captures, monkeypatch, tmp_path, grid):
    import lfcl.demosaic.auto

    # a rule that would pick admm-uv, a method the resampled solver has: the resampled path still runs Malvar
    monkeypatch.setattr(lfcl.demosaic.auto, "load_rules", lambda: _rules(_rule("admm-uv@1", {"malvar": 0.0,
                                                                                                 "admm-uv@1": 0.5})))
    out = tmp_path / "out"
    result = invoke("process", captures / grid / "raw.dng", "--calibration", captures / grid / "cal.json",
                    "--method", "auto", "-o", out, "--outputs", "lightfield", "--no-previews", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    auto = summary["parameters"]["auto"]
    assert (auto["method"], auto["start"], auto["sigma"]) == ("malvar", None, None) and "replaced" not in auto
    assert "every prior of the resampled solver (admm-uv, admm-uvst, admm-st) lost to Malvar" in auto["reason"]
    assert summary["iterations"] == 0


@pytest.mark.parametrize("grid", ["rotated", "aligned"])
def test_tolerance_db_sets_the_stop(grid, processed):
    tolerance = 0.5  # dB: a change of 0.056 sigma, below both defaults (0.1 sigma aligned, 0.8 sigma resampled)
    _, default, _ = processed(grid, "admm-uv", "--outputs", "lightfield", "--no-previews")
    _, summary, text = processed(grid, "admm-uv", "--tolerance-db", str(tolerance), "--outputs", "lightfield",
                                 "--no-previews")
    assert summary["options"]["tolerance_db"] == tolerance and default["options"]["tolerance_db"] is None
    # the resampled path takes sigma at the measured pixels' level and records it; the aligned one at the mosaic's
    sigma = summary["parameters"]["sigma"] if grid == "rotated" else summary["noise_sigma"]
    assert summary["parameters"]["change_tol"] == pytest.approx((1 - 10 ** (-tolerance / 20)) * sigma, rel=1e-9)
    assert summary["parameters"]["change_tol"] < default["parameters"]["change_tol"]
    assert default["iterations"] < summary["iterations"] < summary["parameters"]["max_iter"]
    assert "change_tol" in summary["stop_reason"] and f"tolerance {tolerance:g} dB" in text


def test_a_method_the_grid_does_not_take_is_one_line(captures, tmp_path):
    from lfcl.demosaic.names import METHODS
    from lfcl.grid.model import ResampledGrid

    others = [m for m in METHODS if m not in ResampledGrid.methods]
    assert others, "every method runs on resampled grids: test another refusal"
    hexagonal = captures / "hex"
    for grid in (["--calibration", hexagonal / "cal.json"], ["--white", hexagonal / "white.dng"]):
        out = tmp_path / "out"
        result = invoke("process", hexagonal / "raw.dng", *grid, "--method", others[0], "-o", out)
        assert result.exit_code == 1
        lines = result.output.strip().splitlines()
        assert len(lines) == 1 and f"method {others[0]!r} does not run on the hexagonal lens grid" in lines[0], lines
        assert ", ".join(ResampledGrid.methods) in lines[0] and not out.exists()
    out = tmp_path / "batch"  # the batch refuses it once, before starting a cluster
    result = invoke("batch", hexagonal / "raw.dng", "--calibration", hexagonal / "cal.json", "--method", others[0],
                    "-o", out)
    assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1 and not out.exists()


def test_stage_contracts_of_the_resampled_kind(captures):
    from lfcl.pipeline.stages import Decode, Demosaic, Grid

    gridded = Grid(calibration=captures / "rotated" / "cal.json")(Decode()(captures / "rotated" / "raw.dng"))
    assert gridded.metadata["geometry"]["grid"] == "resampled" and gridded.lens_response is None
    assert gridded.data.shape == gridded.mosaic.data.shape and gridded.lenses == gridded.sampling.lenses
    with pytest.raises(ValueError, match="needs its sampling model"):
        Demosaic("malvar")(gridded._replace(sampling=None))
    for bad in (0, -1.0, float("nan"), True, "1"):
        with pytest.raises(ValueError, match="tolerance_db"):
            Demosaic("admm-uv", tolerance_db=bad)


def test_a_linear4d_start_on_a_resampled_grid_is_one_line_before_any_work(captures, tmp_path):
    out = tmp_path / "out"
    result = invoke("process", captures / "rotated" / "raw.dng", "--calibration", captures / "rotated" / "cal.json",
                    "--method", "admm-uv:linear4d", "-o", out)
    assert result.exit_code != 0 and "--method admm-uv:linear4d needs an aligned square lens grid" in result.output
    assert "Traceback" not in result.output and not out.exists()


@pytest.mark.parametrize("outputs, view, method", [("center", "center", "malvar"), ("mean,refocus", "mean", "admm-uv"),
                                                   ("center,lightfield", "both", "admm-st")])
def test_auto_takes_the_rule_judged_on_the_outputs_asked_for(any_frame, captures, monkeypatch, tmp_path, outputs, view,
                                                             method):
    import lfcl.demosaic.auto

    rules = _rules(_rule("admm-st@1", {"malvar": 0.0, "admm-uv@1": -0.3, "admm-st@1": 0.2}),
                   center=_rule("malvar", {"malvar": 0.0, "admm-uv@1": -0.3}),
                   mean=_rule("admm-uv@1", {"malvar": 0.0, "admm-uv@1": 0.4}))
    monkeypatch.setattr(lfcl.demosaic.auto, "load_rules", lambda: rules)
    out = tmp_path / "out"
    result = invoke("process", captures / "aligned" / "raw.dng", "--calibration", captures / "aligned" / "cal.json",
                    "--method", "auto", "-o", out,
                    "--outputs", outputs, "--no-previews", "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.output)
    auto = summary["parameters"]["auto"]
    assert (auto["view"], auto["method"]) == (view, method)
    assert lfcl.demosaic.auto.VIEW_WORDS[view] in auto["reason"]
    assert summary["options"]["auto_view"] == view


@pytest.mark.parametrize("grid", ["hex", "aligned"])
def test_auto_runs_malvar_on_a_frame_too_small_for_the_priors(grid, processed):
    # 16x16 simulated lenses (15x14 regular ones on the hex grid): narrower than 24 (lfcl.demosaic.auto.min_lenses at
    # pitch 9), so auto runs Malvar and says why, on the resampled path as on the aligned one
    _, summary, text = processed(grid, "auto", "--outputs", "center", "--no-previews")
    auto = summary["parameters"]["auto"]
    assert (auto["method"], auto["sigma"]) == ("malvar", None) and "fewer than 24 on a side" in auto["reason"]
    assert "auto -> malvar (a frame of" in text and summary["iterations"] == 0

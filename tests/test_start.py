"""The ADMM methods' first estimate: ``start="malvar"`` (the paper's), ``"linear4d"``, ``"lens-malvar"``
or ``"guarded"``."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.cli import cli
from lfcl.demosaic.driver import demosaic_grid
from lfcl.grid.model import AlignedGrid
from lfcl.noise.model import NoiseEstimate, from_noise_profile
from lfcl.ops.linear4d import linear4d
from lfcl.ops.malvar import malvar_np
from lfcl.pipeline.stages import Decode, Grid
from lfcl.solvers.params import AdmmParams
from lfcl.solvers.reference import admm_reference

NOISE = NoiseEstimate(gain=0.0, floor=0.01**2, sigma=0.01, source="test")


@pytest.fixture(scope="module")
def textured_mosaic():
    """A 4x5-lens GRBG mosaic of a textured scene with noise (the starts differ on it)."""
    from lfcl.sim import simulate

    sim = simulate("deadleaves", lenses=(4, 5), lux=4, seed=5)
    return sim.normalised_raw()


def test_linear4d_start_is_admm_from_the_linear4d_planes(runtime, textured_mosaic):
    """With a fixed budget, start="linear4d" is the float64 reference ADMM run from linear4d's output."""
    b = textured_mosaic
    got = demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=6, start="linear4d",
                        safety_net=False)  # every lens solved, no net: as the reference does
    x0 = linear4d(runtime, b, "GRBG", (9, 9), (0, 0), NOISE).astype(np.float64)
    # the device's x-update is the exact per-lens solve: the reference gets CG run to convergence
    reference_params = dataclasses.replace(
        AdmmParams(**{k: got.parameters[k] for k in AdmmParams.__dataclass_fields__}), cg_steps=200, cg_tol=1e-12)
    expected = admm_reference(b.astype(np.float64), "GRBG", (9, 9), "uv", reference_params, x0)
    relative = np.linalg.norm(got.planes - expected.x) / np.linalg.norm(expected.x)
    assert relative <= 1e-4, relative
    assert got.parameters["start"] == "linear4d"
    # and it is a different start: from Malvar the same budget ends elsewhere
    from_malvar = admm_reference(b.astype(np.float64), "GRBG", (9, 9), "uv", reference_params,
                                 malvar_np(b, "GRBG").astype(np.float64))
    assert np.linalg.norm(from_malvar.x - expected.x) > 10 * np.linalg.norm(got.planes - expected.x)


def test_lens_malvar_start_is_admm_from_the_lens_bounded_malvar_planes(textured_mosaic):
    """start="lens-malvar" is the float64 reference ADMM run from Malvar bounded to each lens."""
    b = textured_mosaic
    got = demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=6, start="lens-malvar",
                        safety_net=False)
    reference_params = dataclasses.replace(
        AdmmParams(**{k: got.parameters[k] for k in AdmmParams.__dataclass_fields__}), cg_steps=200, cg_tol=1e-12)
    x0 = malvar_np(b, "GRBG", lens=(9, 9)).astype(np.float64)
    expected = admm_reference(b.astype(np.float64), "GRBG", (9, 9), "uv", reference_params, x0)
    assert np.linalg.norm(got.planes - expected.x) / np.linalg.norm(expected.x) <= 1e-4
    assert got.parameters["start"] == "lens-malvar"
    from_malvar = admm_reference(b.astype(np.float64), "GRBG", (9, 9), "uv", reference_params,
                                 malvar_np(b, "GRBG").astype(np.float64))
    assert np.linalg.norm(from_malvar.x - expected.x) > 10 * np.linalg.norm(got.planes - expected.x)


def test_guarded_lenses_are_the_frames_outliers_and_their_neighbours():
    from lfcl.demosaic.guarded_start import malvar_lenses

    d = np.full((6, 7), 2.0)
    d[3, 5] = 7.0  # above 3 x the median 2
    d[0, 0] = 5.5  # below it
    chosen = malvar_lenses(d, factor=3.0)
    expected = np.zeros((6, 7), bool)
    expected[2:5, 4:7] = True
    np.testing.assert_array_equal(chosen, expected)
    # on a frame where the starts agree within the noise nothing moves: the threshold is at least 3 sigmas
    assert not malvar_lenses(np.full((4, 4), 0.1) + np.eye(4) * 2.5, factor=3.0).any()


def test_guarded_start_is_admm_from_linear4d_with_malvar_in_the_outlier_lenses(runtime, textured_mosaic):
    from lfcl.demosaic.guarded_start import malvar_lenses
    from lfcl.ops.lensguard import lens_disagreement_np

    b = textured_mosaic.copy()
    b[9:18, 18:27] = 1.0  # a clipped highlight filling one lens: a sharp lens-to-lens break
    got = demosaic_grid(b, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=6, start="guarded",
                        safety_net=False)
    linear = linear4d(runtime, b, "GRBG", (9, 9), (0, 0), NOISE).astype(np.float64)
    malvar = malvar_np(b, "GRBG").astype(np.float64)
    chosen = malvar_lenses(lens_disagreement_np(linear, malvar, b, (9, 9), gain=NOISE.gain, floor=NOISE.floor))
    assert 0 < chosen.sum() < chosen.size  # the break's lenses and ordinary ones
    x0 = np.where(np.repeat(np.repeat(chosen, 9, 0), 9, 1)[None], malvar, linear)
    reference_params = dataclasses.replace(
        AdmmParams(**{k: got.parameters[k] for k in AdmmParams.__dataclass_fields__}), cg_steps=200, cg_tol=1e-12)
    expected = admm_reference(b.astype(np.float64), "GRBG", (9, 9), "uv", reference_params, x0)
    assert np.linalg.norm(got.planes - expected.x) / np.linalg.norm(expected.x) <= 1e-4
    assert got.parameters["start"] == "guarded"
    assert got.parameters["start_guard"]["lenses_from_malvar"] == chosen.sum()
    assert got.parameters["start_guard"]["lenses"] == chosen.size


def test_default_start_is_malvar(textured_mosaic):
    default = demosaic_grid(textured_mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv-xc", noise=NOISE, iterations=3)
    malvar = demosaic_grid(textured_mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv-xc", noise=NOISE, iterations=3,
                           start="malvar")
    assert default.parameters["start"] == "malvar"
    np.testing.assert_array_equal(default.planes, malvar.planes)


def test_a_bad_start_is_one_line(textured_mosaic):
    with pytest.raises(ValueError, match="start must be one of malvar, linear4d"):
        demosaic_grid(textured_mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", start="bilinear")


def test_process_method_with_its_start_reaches_the_solver_and_the_summary(tmp_path):
    """`lfcl process --method METHOD:START` (no --start): the start reaches the solver; summary.json records the
    method's name as ``method`` and the start as ``parameters.start`` and ``options.start``."""
    capture = tmp_path / "cap"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "deadleaves", "--lenses", "8x8", "--lux", "4",
                                      "--seed", "2", "-o", str(capture)])
    assert result.exit_code == 0, result.output
    summaries = {}
    for method in ("admm-uv:malvar", "admm-uv:linear4d", "admm-uv:lens-malvar", "admm-uv:guarded",
                   "admm-uv-xc:guarded"):
        out = tmp_path / method.replace(":", "_")
        result = CliRunner().invoke(cli, ["process", str(capture / "raw.dng"), "--pitch", "9", "--method", method,
                                          "--outputs", "center,lightfield", "--no-previews", "-o", str(out), "--json"])
        assert result.exit_code == 0, result.output
        summaries[method] = json.loads(result.output)
    # the same light field as demosaic_grid's start= keyword gives, from the stages' decoded and gridded raw
    gridded = Grid(pitch=9)(Decode()(capture / "raw.dng"))
    noise = from_noise_profile(gridded.mosaic.noise_profile, gridded.data)
    for method, start in (("admm-uv-xc", "guarded"), ("admm-uv", "linear4d")):
        direct = demosaic_grid(gridded.data, gridded.mosaic.pattern, gridded.grid, method, noise=noise, start=start)
        cli_lightfield = np.load(tmp_path / f"{method}_{start}" / "lightfield.npy")
        np.testing.assert_array_equal(cli_lightfield, direct.lightfield)
    assert summaries["admm-uv:linear4d"]["parameters"]["start"] == "linear4d"
    assert summaries["admm-uv:malvar"]["parameters"]["start"] == "malvar"
    assert summaries["admm-uv:lens-malvar"]["parameters"]["start"] == "lens-malvar"
    assert summaries["admm-uv:guarded"]["parameters"]["start_guard"]["lenses"] == 64
    guarded = summaries["admm-uv-xc:guarded"]
    assert guarded["method"] == "admm-uv-xc" and guarded["parameters"]["start"] == "guarded"
    assert guarded["options"]["method"] == "admm-uv-xc" and guarded["options"]["start"] == "guarded"
    assert guarded["parameters"]["start_guard"]["lenses"] == 64
    malvar = summaries["admm-uv:malvar"]
    assert malvar["method"] == "admm-uv" and malvar["options"]["start"] == "malvar"
    result = CliRunner().invoke(cli, ["process", str(capture / "raw.dng"), "--method", "admm-uv:nearest", "-o",
                                      str(tmp_path / "bad")])
    assert result.exit_code != 0 and "unknown start 'nearest'" in result.output and "lens-malvar" in result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "bad").exists()
    result = CliRunner().invoke(cli, ["process", str(capture / "raw.dng"), "--method", "admm-uv", "--start", "guarded",
                                      "-o", str(tmp_path / "gone")])
    assert result.exit_code == 2 and "No such option '--start'" in result.output and not (tmp_path / "gone").exists()


def test_parse_method_spec_is_the_one_spelling():
    from lfcl.demosaic.names import method_spec, parse_method_spec

    assert parse_method_spec("admm-uv-xc:guarded") == ("admm-uv-xc", "guarded")
    assert parse_method_spec("auto:lens-malvar") == ("auto", "lens-malvar")
    assert parse_method_spec("malvar") == ("malvar", None)
    assert method_spec("admm-uv-xc", "guarded") == "admm-uv-xc:guarded" and method_spec("admm-uv") == "admm-uv"
    for bad, words in (("bilinear", "unknown method 'bilinear': expected one of auto, malvar, admm-uv, "),
                       ("admm-uv:nearest", "unknown start 'nearest' in method 'admm-uv:nearest': expected "
                                           "METHOD:START with START one of malvar, linear4d, lens-malvar, guarded"),
                       ("admm-uv:", "unknown start ''"), ("admm-uv:guarded:x", "unknown start 'guarded:x'"),
                       ("admm-uv guarded", "unknown method 'admm-uv guarded'"), (None, "METHOD[:START], got None"),
                       ("malvar:guarded", "malvar takes no start"), ("linear4d:malvar", "linear4d takes no start")):
        with pytest.raises(ValueError) as info:
            parse_method_spec(bad)
        assert words in str(info.value) and "\n" not in str(info.value), bad
    with pytest.raises(ValueError, match="unknown start 'nearest'"):
        method_spec("admm-uv", "nearest")


def test_evaluate_takes_a_method_with_its_start(tmp_path):
    from lfcl.evaluation.evaluate import check_methods

    assert check_methods(["admm-uv-xc:linear4d", "malvar"]) == ["admm-uv-xc:linear4d", "malvar"]
    with pytest.raises(ValueError, match="malvar takes no start"):
        check_methods(["malvar:linear4d"])
    with pytest.raises(ValueError, match="goes with an ADMM method only"):
        check_methods(["auto:linear4d"])
    with pytest.raises(ValueError, match="unknown start 'nearest' .* lens-malvar, guarded$"):
        check_methods(["admm-uv:nearest"])
    capture = tmp_path / "cap"
    assert CliRunner().invoke(cli, ["simulate", "--lenses", "6x6", "--lux", "8", "-o", str(capture)]).exit_code == 0
    result = CliRunner().invoke(cli, ["evaluate", str(capture), "--methods", "admm-uv,admm-uv:linear4d", "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)["results"]
    assert [r["method"] for r in rows] == ["admm-uv", "admm-uv:linear4d"]
    assert rows[0]["psnr_center"] != rows[1]["psnr_center"]

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


def _linked_colours(disparity: float, pitch, lenses=(9, 9)):
    """The CFA colours of the two ends of every interior difference of D_epi at one constant disparity (taps of
    weight 0 left out): a set of (own colour, neighbour colour) pairs."""
    from lfcl.layout import channel_map
    from lfcl.ops.epi import epi_matrix_np

    U, V = pitch
    S, T = lenses
    matrix = epi_matrix_np(np.full(lenses, disparity, np.float32), pitch).tocoo()
    H, W = S * U, T * V
    colours = channel_map((H, W), "GRBG").ravel()
    own = matrix.row % (H * W)
    s, t = own // W // U, own % W // V
    interior = (s >= 3) & (s < S - 3) & (t >= 3) & (t < T - 3) & (matrix.data != 0)
    return set(zip(colours[own[interior]].tolist(), colours[matrix.col[interior]].tolist()))


@pytest.mark.parametrize("pitch", [(9, 9), (10, 10), (9, 10), (7, 11)])
@pytest.mark.parametrize("disparity", [-3.0, -2.0, -1.0, -0.5, 0.0, 1.0, 1.5, 2.0, 3.0])
def test_one_colour_lenses_are_those_whose_epipolar_lines_link_one_colour(pitch, disparity):
    """The premise of the rule, from the operator itself: at an odd disparity and an odd pitch every difference
    of the prior along the lines joins two samples of the same Bayer colour (so the line says nothing about its
    other two colours); elsewhere some join two colours. one_colour_lenses says which."""
    from lfcl.demosaic.guarded_start import one_colour_lenses

    one_colour = all(a == b for a, b in _linked_colours(disparity, pitch))
    assert one_colour == (disparity in (-3.0, -1.0, 1.0, 3.0) and pitch[0] % 2 == 1 and pitch[1] % 2 == 1)
    assert one_colour_lenses(np.full((2, 3), disparity), pitch).all() == one_colour


def test_one_colour_lenses_within_a_margin():
    from lfcl.demosaic.guarded_start import one_colour_lenses

    d = np.array([[1.05, 0.95, 1.15, -1.08], [0.5, 2.02, -2.9, 0.0]])
    np.testing.assert_array_equal(one_colour_lenses(d, (9, 9), within=0.1),
                                  [[True, True, False, True], [False, False, False, False]])
    np.testing.assert_array_equal(one_colour_lenses(d, (9, 9), within=0.2),
                                  [[True, True, True, True], [False, False, True, False]])
    assert not one_colour_lenses(d, (10, 10), within=0.2).any()  # an even pitch has no one-colour disparity


def test_guarded_start_takes_malvar_in_confident_one_colour_lenses_and_their_neighbours(runtime, textured_mosaic):
    """With admm-epi's disparity map, the lenses of one-colour lines whose disparity is confident (and their 8
    neighbours) start from Malvar too."""
    from types import SimpleNamespace

    from lfcl.demosaic.guarded_start import CONFIDENT, guarded_start, malvar_lenses, with_neighbours
    from lfcl.ops.lensguard import lens_disagreement_np
    from lfcl.ops.malvar import Malvar

    b = textured_mosaic
    S, T = b.shape[0] // 9, b.shape[1] // 9
    disparity, confidence = np.full((S, T), 0.4), np.ones((S, T))
    disparity[0, 0] = 1.04  # one colour along its lines: it and its neighbours take Malvar's start
    disparity[3, 4] = 1.3  # not within 0.1 of an odd disparity
    disparity[3, 0], confidence[3, 0] = -0.97, CONFIDENT * 0.9  # one colour, but not confident
    linear = linear4d(runtime, b, "GRBG", (9, 9), (0, 0), NOISE).astype(np.float64)
    malvar = malvar_np(b, "GRBG").astype(np.float64)
    outliers = malvar_lenses(lens_disagreement_np(linear, malvar, b, (9, 9), gain=NOISE.gain, floor=NOISE.floor))
    one_colour = np.zeros((S, T), bool)
    one_colour[0, 0] = True
    chosen = outliers | with_neighbours(one_colour)
    assert not chosen.all() and chosen[1, 1] and not outliers[0, 0] and not chosen[3, 0]
    device_b = runtime.to_device(b.astype(np.float32))

    def start(**depth):
        return guarded_start(runtime, runtime.to_device(linear.astype(np.float32)),
                             Malvar(runtime, b.shape, "GRBG").forward(device_b), device_b, (9, 9), NOISE, **depth)

    got, report = start(depth=SimpleNamespace(disparity=disparity, confidence=confidence, dmax=2.0, step=0.1),
                        one_colour_within=0.1)
    expected = np.where(np.repeat(np.repeat(chosen, 9, 0), 9, 1)[None], malvar, linear)
    np.testing.assert_allclose(got.get(), expected, atol=1e-5)
    assert report["one_colour_lenses"] == 1 and report["range_edge_lenses"] == 0
    assert report["lenses_from_malvar"] == chosen.sum()
    # without the disparity (the methods that do not follow the lines) only the outliers move
    _, report = start()
    assert report["lenses_from_malvar"] == outliers.sum() and "one_colour_lenses" not in report


def test_range_edge_lenses_are_a_majority_at_the_search_ranges_end_and_not_confident():
    """Lenses whose best candidate is an end of the search range, whose confidence is below CONFIDENT and whose
    micro-image is not flat, where most of their 3x3 neighbourhood is so too: not a lone one, not a confident region,
    not one a step inside the range, not flat ones."""
    from types import SimpleNamespace

    from lfcl.demosaic.guarded_start import CONFIDENT, range_edge_lenses

    d, w = np.full((8, 9), 0.3), np.full((8, 9), 0.9)
    d[1:4, 1:4], w[1:4, 1:4] = -2.0, 0.05  # a 3x3 block beyond the range: its centre and its middle-edge lenses
    d[6, 7], w[6, 7] = 2.0, 0.0  # a lone one
    d[5:8, 0:3], w[5:8, 0:3] = 2.0, CONFIDENT  # confident: a plane at the range's end
    d[0:3, 5:8], w[0:3, 5:8] = 1.9, 0.0  # one step inside the range (step 0.1)
    got = range_edge_lenses(SimpleNamespace(disparity=d, confidence=w, dmax=2.0, step=0.1))
    expected = np.zeros((8, 9), bool)
    expected[1:4, 1:4] = True  # each of the 9 has at least 5 of its 3x3 at the end (the corners have 4: not)
    expected[1, 1] = expected[1, 3] = expected[3, 1] = expected[3, 3] = False
    np.testing.assert_array_equal(got, expected)
    assert range_edge_lenses(SimpleNamespace(disparity=d, confidence=w, dmax=2.0, step=0.1), majority=1)[6, 7]
    # lenses flat within the noise have no lines to get wrong: with the block's centre and middle-edge lenses flat,
    # its four corners are left, none next to another, and nothing counts
    flat = np.zeros((8, 9), bool)
    flat[2, 1:4] = flat[1:4, 2] = True
    assert not range_edge_lenses(SimpleNamespace(disparity=d, confidence=w, dmax=2.0, step=0.1), flat).any()


def test_known_one_colour_lenses_are_confident_or_shared_by_most_of_their_neighbourhood():
    """A one-colour lens counts where its disparity is confident or where at least ONE_COLOUR_MAJORITY of its 3x3
    neighbourhood are one-colour lenses too (clipping lowers a right disparity's confidence); a lone unsure one is
    the noise's and does not count."""
    from types import SimpleNamespace

    from lfcl.demosaic.guarded_start import CONFIDENT, ONE_COLOUR_MAJORITY, known_one_colour_lenses

    d, w = np.full((9, 10), 0.4), np.full((9, 10), 0.9)
    d[1:6, 1:6], w[1:6, 1:6] = 1.01, 0.3 * CONFIDENT  # a clipped grating's block: right, but unsure
    d[7, 8], w[7, 8] = -0.99, 0.3 * CONFIDENT  # a lone unsure one
    d[7, 1], w[7, 1] = 0.98, CONFIDENT  # a lone confident one
    depth = SimpleNamespace(disparity=d, confidence=w)
    got = known_one_colour_lenses(depth, (9, 9), within=0.05)
    block = np.zeros((9, 10), bool)
    block[1:6, 1:6] = True
    counts = sum(np.pad(block, 1)[i:i + 9, j:j + 10].astype(int) for i in range(3) for j in range(3))
    expected = block & (counts >= ONE_COLOUR_MAJORITY)  # 7 or more: the block's inside, not its edges
    expected[7, 1] = True
    np.testing.assert_array_equal(got, expected)
    assert expected[2:5, 2:5].all() and not expected[1, 1] and not got[7, 8]
    # with a majority of 1 every one-colour lens counts; with 10 (more than a neighbourhood holds) confident ones only
    assert known_one_colour_lenses(depth, (9, 9), within=0.05, majority=1).sum() == 25 + 2
    assert known_one_colour_lenses(depth, (9, 9), within=0.05, majority=10).sum() == 1
    assert not known_one_colour_lenses(depth, (10, 10), within=0.05, majority=1).any()  # an even pitch: none


def test_admm_epi_on_a_clipped_one_colour_grating_is_not_below_malvar():
    """A grey sine grating of period 4 lenses at disparity 1 (one colour along the lines at pitch 9) at 100 lux,
    where half its samples clip: the disparity is right but its confidence low, and before the one-colour lenses
    counted by their neighbourhood too, admm-epi took linear4d's start there and fell 2.9 dB below Malvar's centre
    view (docs/auto.md, "Periodic content")."""
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    capture = simulation_capture(simulate(planes=[Plane("grating", 1.0, SineGrating(4.0, 0.7))], lenses=(24, 24),
                                          lux=100, seed=3))
    assert (capture.mosaic >= 0.999).mean() > 0.4  # it clips
    malvar, got = run_method(capture, "malvar"), run_method(capture, "admm-epi")
    assert got["psnr_center"] >= malvar["psnr_center"], (got["psnr_center"], malvar["psnr_center"])
    assert got["psnr_mean"] >= malvar["psnr_mean"], (got["psnr_mean"], malvar["psnr_mean"])
    assert got["parameters"]["start_guard"]["one_colour_lenses"] > 400


def test_admm_epi_on_content_beyond_the_search_range_is_not_below_malvar():
    """A grey grating of period 10 lenses at disparity -3 (beyond the search range of +-2) filling a 24x24-lens
    frame: admm-epi as `lfcl process` runs it was 2.65 dB below Malvar's centre view at 12 lux before its range-edge
    lenses took Malvar's start (docs/auto.md, "Periodic content")."""
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    for lux in (2, 12):
        capture = simulation_capture(simulate(planes=[Plane("far grating", -3.0, SineGrating(10.0, 1.1))],
                                              lenses=(24, 24), lux=lux, seed=3))
        malvar, got = run_method(capture, "malvar"), run_method(capture, "admm-epi")
        assert got["psnr_center"] >= malvar["psnr_center"], (lux, got["psnr_center"], malvar["psnr_center"])
        assert got["psnr_mean"] >= malvar["psnr_mean"], (lux, got["psnr_mean"], malvar["psnr_mean"])
        assert got["parameters"]["start_guard"]["range_edge_lenses"] > 100


def test_a_texture_less_wall_has_no_range_edge_lenses():
    """A flat grey wall: its disparity estimate drifts to the search range's ends where nothing tells the candidates
    apart (64 lenses of 576 counted before the flat lenses were left out), but it has no lines to get wrong."""
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.planes import Plane

    def grey(x, y):
        return np.full(np.shape(x) + (3,), 0.4, np.float32)

    capture = simulation_capture(simulate(planes=[Plane("wall", 0.3, grey)], lenses=(24, 24), lux=2, seed=3))
    assert run_method(capture, "admm-epi")["parameters"]["start_guard"]["range_edge_lenses"] == 0


def test_admm_epi_on_a_grey_grating_at_disparity_one_is_not_below_malvar():
    """A grey sine grating of period 4 lenses at disparity +1 (each micro-image a grating of about 4 pixels, where
    linear4d breaks; its lines carry one colour each): admm-epi as `lfcl process` runs it was 6.0 dB below Malvar's
    centre view at 2 lux and 8.6 dB at 12 before the one-colour lenses took Malvar's start (docs/auto.md,
    "Periodic content")."""
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    for lux in (2, 12):
        capture = simulation_capture(simulate(planes=[Plane("grating", 1.0, SineGrating(4.0, 0.3))], lenses=(16, 16),
                                              lux=lux, seed=3))
        malvar, got = run_method(capture, "malvar"), run_method(capture, "admm-epi")
        assert got["psnr_center"] >= malvar["psnr_center"], (lux, got["psnr_center"], malvar["psnr_center"])
        assert got["psnr_mean"] >= malvar["psnr_mean"] + 1.0, (lux, got["psnr_mean"], malvar["psnr_mean"])
        assert got["parameters"]["start_guard"]["one_colour_lenses"] > 200


def test_admm_epi_on_an_in_focus_grey_checker_is_not_below_malvar():
    """A grey checkerboard of 2-lens squares in focus (24x24 lenses): its disparity tied at d = 0 and +-2 until the
    cost's colour penalty (lfcl/depth/cost.py), and admm-epi painted the colour of the +-2 explanation, 7.71 / 15.34
    dB below Malvar at 2 lux (centre view / mean image); now +9.80 / +2.65 (docs/auto.md, "Periodic content")."""
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import Checker
    from lfcl.sim.planes import Plane

    capture = simulation_capture(simulate(planes=[Plane("checker", 0.0, Checker(2.0, (0.05,) * 3, (0.95,) * 3,
                                                                                (0.3, 0.7)))],
                                          lenses=(24, 24), lux=2, seed=3))
    malvar, got = run_method(capture, "malvar"), run_method(capture, "admm-epi")
    assert got["psnr_center"] >= malvar["psnr_center"] + 3.0, (got["psnr_center"], malvar["psnr_center"])
    assert got["psnr_mean"] >= malvar["psnr_mean"], (got["psnr_mean"], malvar["psnr_mean"])

"""The safety net (lfcl/demosaic/safety_net.py) on the default path: never worse than Malvar, on the fine-texture family too."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lfcl.demosaic.driver import demosaic_grid
from lfcl.demosaic.flat_lenses import flat_lenses
from lfcl.demosaic.names import DEFAULT_METHOD
from lfcl.demosaic.safety_net import FLAT_J, NET_K, net_k
from lfcl.grid.model import AlignedGrid
from lfcl.noise.model import NoiseEstimate
from lfcl.ops.lensguard import guard_lens_means_np
from lfcl.ops.malvar import malvar_np


@pytest.fixture(scope="module")
def finetexture():
    """Fine texture off the focal plane (issue 18's failure), in the dark and in good light."""
    from lfcl.evaluation.evaluate import simulated_capture

    return {lux: simulated_capture(24, lux, 3, "finetexture") for lux in (0.5, 12)}


def _gains(capture, method, **options):
    from lfcl.evaluation.evaluate import run_method

    malvar, result = run_method(capture, "malvar"), run_method(capture, method, **options)
    return result["psnr_center"] - malvar["psnr_center"], result["psnr_mean"] - malvar["psnr_mean"], result


@pytest.mark.parametrize("lux", [0.5, 12])
def test_without_the_net_admm_uv_loses_the_mean_image_of_fine_texture(finetexture, lux):
    _, mean, _ = _gains(finetexture[lux], "admm-uv", safety_net=False)
    assert mean < -0.1  # what issue 18 reported: below Malvar on the mean image


@pytest.mark.parametrize("lux", [0.5, 12])
@pytest.mark.parametrize("method", [DEFAULT_METHOD, "admm-uv", "admm-uv-xc"])
def test_with_the_net_no_view_is_worse_than_malvar(finetexture, lux, method):
    centre, mean, result = _gains(finetexture[lux], method)
    assert centre >= -0.1 and mean >= -0.1, (centre, mean)
    net = result["parameters"]["safety_net"]
    ran = result["parameters"].get("auto", {}).get("method", method)
    assert net["k"] == (None if math.isinf(net_k(ran)) else net_k(ran))  # JSON has no Infinity
    if ran == "admm-epi":  # auto's pick in low light keeps its own lens means (docs/auto.md), but for flat lenses
        assert net["k"] is None and net["lenses_from_malvar"] == 0 and "no soft threshold" in net["why"]
        assert net["lenses_kept"] + net["lenses_filled_flat"] == net["lenses"] == 24 * 24
    else:
        assert net["k"] == NET_K and 0 < net["lenses_from_malvar"] <= net["lenses"] == 24 * 24


def test_the_net_is_the_lens_mean_guard_against_malvar_of_the_same_mosaic(rng):
    mosaic = (0.3 + 0.05 * rng.standard_normal((27, 36))).astype(np.float32)
    mosaic[:9, :9] = np.where(np.arange(9)[:, None] % 2 == np.arange(9) % 2, 0.2, 0.6)  # a flat lens, GRBG
    mosaic[:9, 9:18] = 0.9  # beside a bright one: its Malvar means read this lens
    noise = NoiseEstimate(gain=1e-3, floor=1e-5, sigma=0.018, source="test")
    plain = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=noise, iterations=3, safety_net=False)
    netted = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=noise, iterations=3)
    flat = flat_lenses(mosaic, "GRBG", (9, 9), noise)
    expected, replaced = guard_lens_means_np(plain.planes, malvar_np(mosaic, "GRBG"), mosaic, (9, 9),
                                             gain=noise.gain, floor=noise.floor, k=NET_K, flat=flat.flat,
                                             flat_means=flat.means, j=FLAT_J)
    np.testing.assert_allclose(netted.planes, expected, atol=2e-5)
    report = netted.parameters["safety_net"]
    assert report["lenses"] == 12 and report["colour_means_from_malvar"] == int(replaced[replaced > 0].sum())
    assert report["lenses_from_malvar"] == int((replaced == 3).sum()) and "Malvar" in report["why"]
    assert report["lenses_filled_flat"] == int((replaced < 0).sum()) >= 1 and replaced[0, 0] == -1
    np.testing.assert_allclose(netted.planes[:, :9, :9].reshape(3, -1).T, [[0.6, 0.2, 0.6]] * 81, atol=1e-6)
    assert "safety_net" not in plain.parameters


def test_the_net_keeps_an_in_focus_lens_scale_grating_above_malvar():
    """A grey grating of period 2.5 lenses in focus at 50 lux: its lenses are flat and their colour alternates at the
    lens scale, so Malvar's lens means read the neighbours'. Pulled towards them (the net before flat lenses were
    filled, j = inf) the default's centre view was below Malvar's; filled with their own means, it is above."""
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.evaluation.metrics import centre_view, psnr
    from lfcl.layout import LightFieldShape, planes_to_exchange
    from lfcl.noise.model import from_noise_profile
    from lfcl.sim import simulate
    from lfcl.sim.periodic import SineGrating
    from lfcl.sim.planes import Plane

    capture = simulation_capture(simulate(planes=[Plane("grating", 0.0, SineGrating(2.5, 0.7))], lenses=(24, 24),
                                          lux=50, seed=3))
    malvar, default = run_method(capture, "malvar"), run_method(capture, DEFAULT_METHOD)
    assert default["parameters"]["auto"]["method"] == "admm-uv-xc"  # the cheaper band, where the net runs
    assert default["parameters"]["safety_net"]["lenses_filled_flat"] > 24 * 24 // 2
    assert default["psnr_center"] > malvar["psnr_center"] + 3 and default["psnr_mean"] > malvar["psnr_mean"] + 3
    noise = from_noise_profile(capture.noise_profile, capture.mosaic)
    grid = AlignedGrid(capture.pitch)
    own = demosaic_grid(capture.mosaic, capture.pattern, grid, "admm-uv-xc", noise=noise,
                        safety_net=False).planes
    pulled, _ = guard_lens_means_np(own, malvar_np(capture.mosaic, capture.pattern), capture.mosaic, capture.pitch,
                                    gain=noise.gain, floor=noise.floor, k=NET_K)
    lightfield = planes_to_exchange(pulled.astype(np.float32), LightFieldShape.from_exchange(capture.truth))
    assert psnr(centre_view(lightfield), centre_view(capture.truth)) < malvar["psnr_center"]


def test_malvar_needs_no_net_and_auto_records_it_once(rng):
    mosaic = (0.3 + 0.05 * rng.standard_normal((27, 36))).astype(np.float32)
    assert "safety_net" not in demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "malvar").parameters


def test_admm_epi_keeps_its_own_lens_means_but_flat_lenses_whose_malvar_means_read_another_lens():
    """Checkers of pure red and pure blue lenses in focus at 2 lux, where the default runs admm-epi: its lens means are
    its own (no soft threshold), but its in-focus lenses are not one colour (their borders keep some of the
    neighbours'), 3.3 dB below Malvar's centre view. Filled with their own samples' means they are far above it."""
    from lfcl.demosaic.safety_net import NET_K_BY_METHOD, net_k
    from lfcl.evaluation.evaluate import run_method, simulation_capture
    from lfcl.sim import simulate
    from lfcl.sim.periodic import Checker
    from lfcl.sim.planes import Plane

    assert net_k("admm-epi") == NET_K_BY_METHOD["admm-epi"] == float("inf") and net_k("admm-uv") == NET_K
    capture = simulation_capture(simulate(planes=[Plane("checker", 0.0, Checker(1.0, (0.95, 0, 0), (0, 0, 0.95)))],
                                          lenses=(24, 24), lux=2, seed=0))
    malvar, default = run_method(capture, "malvar"), run_method(capture, DEFAULT_METHOD)
    off = run_method(capture, DEFAULT_METHOD, safety_net=False)
    assert default["parameters"]["auto"]["method"] == "admm-epi"
    assert off["psnr_center"] < malvar["psnr_center"] - 1  # what the fill mends
    assert default["psnr_center"] > malvar["psnr_center"] + 3 and default["psnr_mean"] > malvar["psnr_mean"] + 3
    report = default["parameters"]["safety_net"]
    assert report["k"] is None and report["lenses_from_malvar"] == 0 and report["lenses_filled_flat"] > 24 * 24 // 2
    assert report["lenses_kept"] + report["lenses_filled_flat"] == report["lenses"] == 24 * 24
    # the lenses not filled are admm-epi's own, unmoved; the filled ones one colour each
    changed = (default["lightfield"] != off["lightfield"]).any(axis=(2, 3, 4))  # [S, T]
    assert changed.sum() == report["lenses_filled_flat"]
    filled = default["lightfield"][changed]  # [n, U, V, 3]
    np.testing.assert_array_equal(filled, np.broadcast_to(filled[:, :1, :1], filled.shape))


def test_without_a_noise_model_the_net_says_it_did_not_act():
    one_lens = np.full((9, 9), 0.3, np.float32)  # too small to estimate the noise from
    result = demosaic_grid(one_lens, "GRBG", AlignedGrid((9, 9)), "admm-uv", lam=0.01, iterations=2)
    assert result.parameters["safety_net"]["lenses"] == 0
    assert result.parameters["safety_net"]["why"].startswith("not applied: no noise model")


def test_process_summary_says_what_the_net_did(tmp_path):
    import json

    from click.testing import CliRunner

    from lfcl.cli import cli

    capture = tmp_path / "cap"
    assert CliRunner().invoke(cli, ["simulate", "--scene", "finetexture", "--lenses", "24x24", "--seed", "1",
                                    "-o", str(capture)]).exit_code == 0
    base = ["process", str(capture / "raw.dng"), "--pitch", "9", "--outputs", "center", "--no-previews"]
    text = CliRunner().invoke(cli, [*base, "--method", "admm-uv-xc", "-o", str(tmp_path / "text")])
    assert text.exit_code == 0, text.output
    assert "safety net: " in text.output and "lenses took Malvar's colour means" in text.output
    summary = json.loads((tmp_path / "text" / "summary.json").read_text())
    assert summary["method"] == "admm-uv-xc" and summary["parameters"]["safety_net"]["lenses"] == 24 * 24
    # the default writing only the centre view at 12 lux runs admm-epi, which keeps its own lens means, and says so
    default = CliRunner().invoke(cli, [*base, "-o", str(tmp_path / "default")])
    assert default.exit_code == 0, default.output
    assert "method auto -> admm-epi" in default.output and "safety net: 576 of 576 lenses kept the method's own" \
        in default.output
    assert "disparity" in json.loads((tmp_path / "default" / "summary.json").read_text())["seconds"]
    # where the noise model came from (docs/noise.md): the simulated DNG carries a NoiseProfile
    assert "noise: sigma " in text.output and "(the DNG's noise profile)" in text.output
    assert summary["noise"]["source"] == "dng-noise-profile" and summary["noise"]["sigma"] == summary["noise_sigma"]
    off = CliRunner().invoke(cli, [*base, "--no-safety-net", "-o", str(tmp_path / "off"), "--json"])
    assert off.exit_code == 0 and "safety_net" not in json.loads(off.stdout)["parameters"]

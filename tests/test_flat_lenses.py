"""Skipping flat lenses (lfcl/demosaic/flat_lenses.py): the test, the packing, and the solve around them."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.cli import cli
from lfcl.demosaic.driver import demosaic_grid
from lfcl.demosaic.flat_lenses import LADDER_STEPS, fill_flat, flat_lenses, pack_lenses
from lfcl.grid.model import AlignedGrid
from lfcl.layout import channel_map
from lfcl.noise.model import NoiseEstimate
from lfcl.ops.malvar import malvar_np
from lfcl.solvers.params import AdmmParams
from lfcl.solvers.reference import admm_reference

GAIN, FLOOR = 2e-4, 1e-5  # the Poisson-Gaussian model of the test mosaics (normalised units)
NOISE = NoiseEstimate(gain=GAIN, floor=FLOOR, sigma=math.sqrt(GAIN * 0.4 + FLOOR), source="test")


def noisy(clean: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return (clean + np.sqrt(GAIN * np.maximum(clean, 0) + FLOOR) * rng.standard_normal(clean.shape)).astype(np.float32)


def lens_mosaic(lenses, pattern="GRBG", pitch=(9, 9), edge_every=2, seed=0, contrast=0.2, edged=None):
    """A mosaic of lenses that are constant per colour (random levels), every ``edge_every``-th lens
    (or those of the [S, T] mask ``edged``) with a vertical edge of ``contrast`` through it;
    returns (noisy mosaic, [S, T] bool: has an edge)."""
    S, T = lenses
    U, V = pitch
    rng = np.random.default_rng(seed)
    levels = rng.uniform(0.1, 0.7, (S, T, 3))
    channels = channel_map((S * U, T * V), pattern)
    clean = np.take_along_axis(np.repeat(np.repeat(levels, U, 0), V, 1), channels[..., None], axis=-1)[..., 0]
    if edged is None:
        edged = (np.arange(S * T).reshape(S, T) % edge_every) == 0 if edge_every else np.zeros((S, T), bool)
    step = np.zeros((U, V))
    step[:, V // 2:] = contrast
    clean = clean + np.kron(edged, step)
    return noisy(clean, seed + 1), edged


# --- the packing ------------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(7, 5), (16, 16), (3, 1), (10, 13)])
def test_packing_keeps_bayer_phase_and_round_trips(shape):
    rng = np.random.default_rng(sum(shape))
    active = rng.random(shape) < 0.4
    packing = pack_lenses(active)
    S, T = shape
    s, t = np.divmod(packing.source, T)
    s2, t2 = np.divmod(packing.target, T)
    assert sorted(packing.source.tolist()) == np.flatnonzero(active).tolist()
    assert len(set(packing.target.tolist())) == len(packing.target)
    assert np.all(s % 2 == s2 % 2) and np.all(t % 2 == t2 % 2)  # odd pitch: the same Bayer phase
    # the smallest ladder size that has a slot of each parity for every active lens
    rows = packing.grid[0]
    ladder = sorted({max(1, math.ceil(S * k / LADDER_STEPS)) for k in range(1, LADDER_STEPS + 1)})
    assert rows in ladder

    def fits(r):
        return all(((np.arange(r)[:, None] % 2 == a) & (np.arange(T) % 2 == b)).sum()
                   >= (active & (np.arange(S)[:, None] % 2 == a) & (np.arange(T) % 2 == b)).sum()
                   for a in range(2) for b in range(2))

    assert fits(rows) and not any(fits(r) for r in ladder if r < rows)
    planes = rng.random((3, S * 3, T * 3)).astype(np.float32)  # 3x3 lenses
    packed = packing.pack(planes, (3, 3))
    assert packed.shape == (3, rows * 3, T * 3)
    assert np.all(packed.reshape(3, rows, 3, T, 3).transpose(0, 1, 3, 2, 4)[:, ~packing.real] == 0)  # padding: zero
    back = packing.unpack(packed, np.full_like(planes, -1.0), (3, 3))
    mask = np.kron(active, np.ones((3, 3), bool))
    np.testing.assert_array_equal(back[:, mask], planes[:, mask])
    assert np.all(back[:, ~mask] == -1.0)


# --- the test for flatness --------------------------------------------------------------


def test_packed_lenses_go_back_on_the_device_as_on_the_host(runtime, rng):
    from lfcl.ops.lenscopy import LensCopy

    active = rng.random((6, 5)) < 0.4
    packing = pack_lenses(active)
    assert packing.grid[0] < 6
    packed = rng.random((3, packing.grid[0] * 9, 5 * 9)).astype(np.float32)
    on_host = packing.unpack(packed, np.zeros((3, 54, 45), np.float32), (9, 9))
    copy = LensCopy(runtime, (9, 9))
    on_device = copy(runtime.to_device(packed), runtime.to_device(np.zeros((3, 54, 45), np.float32)),
                     packing.unpack_pairs())
    np.testing.assert_array_equal(on_device.get(), on_host)


def test_flat_lenses_are_found_at_the_stated_false_alarm_rate():
    mosaic, edged = lens_mosaic((40, 40), edge_every=2, contrast=0.05)
    found = flat_lenses(mosaic, "GRBG", (9, 9), NOISE, threshold=0.01)
    missed = 1 - found.flat[~edged].mean()  # flat lenses called structured: about the threshold
    assert missed <= 0.03, missed
    assert found.flat[edged].mean() <= 0.02  # an edge of ~3 sigma is never called flat
    # the fill values: each colour's mean over its samples in the lens
    s, t = 3, 5
    lens = mosaic[s * 9:(s + 1) * 9, t * 9:(t + 1) * 9]
    colours = channel_map(mosaic.shape, "GRBG")[s * 9:(s + 1) * 9, t * 9:(t + 1) * 9]
    np.testing.assert_allclose(found.means[s, t], [lens[colours == c].mean() for c in range(3)], rtol=1e-6)


def test_a_lens_with_one_sample_of_a_colour_is_never_flat():
    weights = np.zeros((9, 9))
    weights[4, 3:6] = 1.0  # GRBG at (4, 3..5): R? one or two samples per colour only
    mosaic, _ = lens_mosaic((2, 2), edge_every=0)
    found = flat_lenses(mosaic, "GRBG", (9, 9), NOISE, lens_weights=weights)
    assert not found.flat.any()


def test_fill_flat_sets_every_pixel_of_a_flat_lens():
    mosaic, _ = lens_mosaic((4, 4), edge_every=3)
    found = flat_lenses(mosaic, "GRBG", (9, 9), NOISE)
    planes = np.zeros((3, 36, 36), np.float32)
    fill_flat(planes, found, (9, 9))
    lenses = planes.reshape(3, 4, 9, 4, 9).transpose(1, 3, 0, 2, 4)  # [S, T, 3, U, V]
    for s, t in zip(*np.nonzero(found.flat)):
        np.testing.assert_allclose(lenses[s, t], np.broadcast_to(found.means[s, t][:, None, None], (3, 9, 9)),
                                   rtol=1e-6)
    assert np.all(lenses[~found.flat] == 0)


# --- the solve around them --------------------------------------------------------------


@pytest.fixture(scope="module")
def mixed():
    """4x6 lenses: lens rows 0 and 1 with edges in every other lens, the rest flat (so that the
    busy lenses fit in fewer lens rows)."""
    edged = np.zeros((4, 6), bool)
    edged[:2, ::2] = edged[1, 3] = True
    return lens_mosaic((4, 6), seed=3, edged=edged)


def test_fixed_budget_solve_is_the_reference_on_the_busy_lenses(mixed):
    mosaic, edged = mixed
    got = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=5, skip_flat=True,
                        safety_net=False)
    found = flat_lenses(mosaic, "GRBG", (9, 9), NOISE)
    assert got.parameters["flat_lenses"]["flat_lenses"] == found.flat.sum() > 0
    assert not found.flat[edged].any()
    params = dataclasses.replace(AdmmParams(**{k: got.parameters[k] for k in AdmmParams.__dataclass_fields__}),
                                 cg_steps=200, cg_tol=1e-12)
    # the start is Malvar on the whole mosaic (it reads the neighbouring lenses), then the busy lenses alone
    expected = admm_reference(mosaic.astype(np.float64), "GRBG", (9, 9), "uv", params,
                              malvar_np(mosaic, "GRBG").astype(np.float64)).x
    def by_lens(planes):  # [S, T, 3, U, V]
        return planes.reshape(3, 4, 9, 6, 9).transpose(1, 3, 0, 2, 4)

    got_lenses, busy = by_lens(got.planes), ~found.flat
    want = by_lens(expected)[busy]
    error = np.linalg.norm(got_lenses[busy] - want) / np.linalg.norm(want)
    assert error <= 1e-4, error
    for s, t in zip(*np.nonzero(found.flat)):
        np.testing.assert_allclose(got_lenses[s, t].reshape(3, -1).T, np.broadcast_to(found.means[s, t], (81, 3)),
                                   rtol=1e-6)
    # and off, every lens is solved: the busy ones as above
    plain = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=5, safety_net=False)
    np.testing.assert_allclose(by_lens(plain.planes)[busy], got_lenses[busy], atol=1e-5)
    assert plain.parameters["flat_lenses"]["flat_lenses"] == 0


def test_the_stop_rule_is_over_the_solved_lenses(mixed):
    mosaic, _ = mixed
    seen = []
    result = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv-xc", noise=NOISE, skip_flat=True,
                           callback=lambda record, x: seen.append((record.rms_change, x.get())))
    solved = result.parameters["flat_lenses"]["lenses"] - result.parameters["flat_lenses"]["flat_lenses"]
    assert result.iterations == len(seen) >= 2
    for (rms, x), (_, previous) in zip(seen[1:], seen):
        change = np.sum((x.astype(np.float64) - previous) ** 2)  # the padding lenses stay zero
        assert rms == pytest.approx(math.sqrt(change / (solved * 3 * 81)), rel=1e-3)


def test_bands_of_the_packed_mosaic_give_the_same_result(mixed):
    mosaic, _ = mixed
    whole = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=4, skip_flat=True)
    banded = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=4,
                           max_memory=120_000, skip_flat=True)
    assert "bands" in banded.stop_reason
    np.testing.assert_allclose(banded.planes, whole.planes, atol=1e-5)


def test_vignetted_lenses_fill_their_dark_pixels_too(mixed):
    from lfcl.grid.vignetting import DEFAULT_THRESHOLD

    mosaic, _ = mixed
    v, u = np.meshgrid(np.arange(9) - 4, np.arange(9) - 4)
    response = np.clip(1.2 - 0.06 * (u**2 + v**2), 0, 1)
    assert (response < DEFAULT_THRESHOLD).any()
    raw = mosaic * np.tile(response, (4, 6)).astype(np.float32)
    result = demosaic_grid(raw, "GRBG", AlignedGrid((9, 9), lens_response=response), "admm-uv", noise=NOISE,
                           skip_flat=True, safety_net=False)
    assert np.all(np.isfinite(result.planes))
    flat = result.parameters["flat_lenses"]
    assert flat["flat_lenses"] > 0
    lenses = result.planes.reshape(3, 4, 9, 6, 9).transpose(1, 3, 0, 2, 4).reshape(24, 3, 81)
    constant = np.ptp(lenses, axis=-1).max(axis=-1) == 0
    assert constant.sum() == flat["flat_lenses"]  # the flat lenses, dark corners included, hold one value


@pytest.mark.parametrize("shape", [(27, 36), (9, 36)])  # one lens row: nothing to shrink, still nothing to solve
def test_a_flat_image_needs_no_iterations(shape):
    mosaic = noisy(np.full(shape, 0.3), seed=9)
    result = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, skip_flat=True,
                           safety_net=False)
    assert result.iterations == 0 and "flat" in result.stop_reason
    assert result.parameters["flat_lenses"]["share"] == 1.0
    np.testing.assert_allclose(result.planes, 0.3, atol=4 * math.sqrt(GAIN * 0.3 + FLOOR) / math.sqrt(20))


@pytest.mark.parametrize("method, skip_flat, message", [
    ("malvar", True, "couples no two lenses"),
    ("admm-st", 0.05, "couples no two lenses"),
    ("admm-uv", 1.5, "p threshold in \\(0, 1\\)"),
    ("admm-uv", "yes", "p threshold in \\(0, 1\\)"),
])
def test_bad_skip_flat_is_one_line(mixed, method, skip_flat, message):
    with pytest.raises(ValueError, match=message):
        demosaic_grid(mixed[0], "GRBG", AlignedGrid((9, 9)), method, noise=NOISE, skip_flat=skip_flat)


def test_the_coupled_priors_solve_every_lens_by_default(mixed):
    result = demosaic_grid(mixed[0], "GRBG", AlignedGrid((9, 9)), "admm-st", noise=NOISE, iterations=2)
    assert "flat_lenses" not in result.parameters


def test_process_reports_the_skipped_lenses(tmp_path):
    capture = tmp_path / "cap"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "charts", "--lenses", "16x16", "--lux", "12",
                                      "--seed", "1", "-o", str(capture)])
    assert result.exit_code == 0, result.output
    base = ["process", str(capture / "raw.dng"), "--pitch", "9", "--method", "admm-uv", "--outputs", "center",
            "--no-previews"]
    summaries = {}
    for name, extra in (("skip", ["--skip-flat"]), ("solve", []), ("strict", ["--flat-p", "0.5"])):
        result = CliRunner().invoke(cli, [*base, *extra, "-o", str(tmp_path / name), "--json"])
        assert result.exit_code == 0, result.output
        summaries[name] = json.loads(result.output)
    skip = summaries["skip"]
    assert skip["parameters"]["flat_lenses"]["flat_lenses"] > 0
    assert any(s["output"].startswith("ADMM on") and "chi-square" in s["reason"] for s in skip["skipped"])
    assert summaries["solve"]["parameters"]["flat_lenses"]["flat_lenses"] == 0
    assert not any(s["output"].startswith("ADMM on") for s in summaries["solve"]["skipped"])
    assert summaries["strict"]["parameters"]["flat_lenses"]["p_threshold"] == 0.5
    assert summaries["strict"]["parameters"]["flat_lenses"]["flat_lenses"] <= skip["parameters"]["flat_lenses"][
        "flat_lenses"]
    for extra, message in ((["--solve-flat", "--flat-p", "0.1"], "does not go with --solve-flat"),
                           (["--method", "malvar", "--skip-flat"], "couples no two lenses")):
        result = CliRunner().invoke(cli, [*base, *extra, "-o", str(tmp_path / "bad")])
        assert result.exit_code != 0 and message in result.output
        assert not (tmp_path / "bad").exists()


def test_the_skip_is_off_by_default_and_needs_a_noise_model_when_asked_for(mixed):
    result = demosaic_grid(mixed[0], "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, iterations=2)
    assert result.parameters["flat_lenses"] == {"flat_lenses": 0, "why": "not tested (skip_flat off)"}
    one_lens = noisy(np.full((9, 9), 0.3), seed=2)  # too small to estimate the noise from
    with pytest.raises(ValueError, match="skipping flat lenses: no noise model"):  # asked for: an error
        demosaic_grid(one_lens, "GRBG", AlignedGrid((9, 9)), "admm-uv", lam=0.01, iterations=2, skip_flat=True)



def test_auto_says_when_its_pick_ignores_skip_flat(rng):
    # auto at low light picks admm-epi, which solves every lens: the asked --skip-flat is recorded as not applied
    from lfcl.demosaic.flat_lenses import skipped_flat_lenses
    from lfcl.noise.model import NoiseEstimate

    mosaic = (0.3 + 0.0015 * rng.standard_normal((216, 216))).astype(np.float32)  # 24x24 lenses
    noise = NoiseEstimate(gain=0.0, floor=0.0015**2, sigma=0.0015, source="test")
    result = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "auto", noise=noise, skip_flat=True, iterations=1)
    record = result.parameters["flat_lenses"]
    assert result.method == "admm-epi" and record["ignored"] and "auto picked admm-epi" in record["why"]
    (entry,) = skipped_flat_lenses(record)
    assert entry["output"] == "--skip-flat" and entry["reason"] == record["why"]

def test_the_benchmark_writes_one_row_per_capture_and_method(tmp_path):
    import flat  # research/flat.py

    out = tmp_path / "flat.json"
    flat.main(["--lenses", "8", "--scenes", "charts", "--lux", "12", "--methods", "admm-uv,admm-uv-xc:linear4d",
               "--repeats", "1", "-o", str(out)])
    rows = json.loads(out.read_text())
    assert [(r["scene"], r["method"]) for r in rows] == [("charts", "admm-uv"), ("charts", "admm-uv-xc:linear4d")]
    for row in rows:
        assert row["seconds_solve"] > 0 and row["seconds_skip"] > 0 and 0 < row["flat_share"] < 1
        assert row["speedup"] == pytest.approx(row["seconds_solve"] / row["seconds_skip"])
        assert row["gain_center"] == pytest.approx(row["psnr_center_skip"] - row["psnr_center_solve"])
        assert 1 <= row["solved_lens_rows"] <= row["lens_rows"] == 8


def test_flat_lenses_too_few_to_shrink_the_solve_are_solved():
    mosaic, edged = lens_mosaic((4, 6), edge_every=2, seed=3)  # every lens row keeps busy lenses of both parities
    result = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE, skip_flat=True)
    record = result.parameters["flat_lenses"]
    assert record["found"] == (~edged).sum() and record["flat_lenses"] == 0
    assert "too few to shrink the solve" in record["why"] and record["solved_lens_rows"] == 4
    plain = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=NOISE)
    np.testing.assert_array_equal(result.planes, plain.planes)

"""`--method auto`: the rule table, its fit, and the demosaic it runs (lfcl/demosaic/auto.py)."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from lfcl.demosaic.auto import choose, fit_rule, fit_rules, load_rule, parse_candidate, row_gain, row_merit
from lfcl.demosaic.driver import demosaic_grid
from lfcl.grid.model import AlignedGrid
from lfcl.noise.model import NoiseEstimate

ROWS_FILE = Path(__file__).resolve().parents[1] / "research" / "auto_rows.json"


def _band(lo, hi, candidate):
    return {"sigma_from": lo, "sigma_to": hi, "candidate": candidate, "worst_gain_db": 0.0, "median_gain_db": 0.0,
            "tie_db": 0.1, "captures": 2}


RULE = (_band(0.001, 0.01, "malvar"), _band(0.01, 0.1, "admm-uv@2"))


def _row(sigma, gains, ratio=5.0, capture="charts 1"):
    """A training row of research/fit_auto.py: {candidate: (centre gain, mean gain)} over Malvar."""
    return {"capture": capture, "lux": 12, "sigma": sigma, "lens_ratio": ratio,
            "malvar": {"center": 30.0, "mean": 35.0, "seconds": 0.01},
            "gains": {c: {"center": g[0], "mean": g[1], "seconds": 0.1} for c, g in gains.items()}}


def test_choose_takes_the_band_holding_sigma():
    assert (choose(0.005, RULE).method, choose(0.005, RULE).strength) == ("malvar", 1.0)
    assert (choose(0.05, RULE).method, choose(0.05, RULE).strength) == ("admm-uv", 2.0)
    assert "in 0.001-0.01" in choose(0.005, RULE).reason


def test_choose_outside_the_trained_range_takes_the_nearest_band_and_says_so():
    low, high = choose(1e-5, RULE), choose(0.5, RULE)
    assert low.method == "malvar" and "below the trained range" in low.reason
    assert high.method == "admm-uv" and "above the trained range" in high.reason


@pytest.mark.parametrize("sigma", [float("nan"), float("inf"), -1.0, "0.1"])
def test_choose_rejects_a_bad_noise_level(sigma):
    with pytest.raises(ValueError, match="noise level"):
        choose(sigma, RULE)


def test_parse_candidate():
    assert parse_candidate("admm-uv@0.5") == ("admm-uv", 0.5, "malvar")
    assert parse_candidate("malvar") == ("malvar", 1.0, "malvar")
    assert parse_candidate("admm-uv-xc@2:linear4d") == ("admm-uv-xc", 2.0, "linear4d")
    assert parse_candidate("admm-epi@1") == ("admm-epi", 1.0, None)  # its schedule's start, as the rows ran it
    assert parse_candidate("admm-epi@1:malvar") == ("admm-epi", 1.0, "malvar")
    assert parse_candidate("admm-uv-xc:guarded") == ("admm-uv-xc", 1.0, "guarded")
    # the method and its start are lfcl.demosaic.names.parse_method_spec's METHOD[:START]; @strength a number > 0
    for bad, words in (("admm-uv@1:nearest", "unknown start 'nearest' in method 'admm-uv:nearest': expected "
                                             "METHOD:START with START one of malvar, linear4d, lens-malvar, guarded"),
                       ("bilinear@1", "unknown method 'bilinear': expected one of auto, malvar, "),
                       ("admm-uv@x", "candidate 'admm-uv@x': the strength after @ must be a number > 0, got 'x'"),
                       ("admm-uv@0:linear4d", "must be a number > 0, got '0'")):
        with pytest.raises(ValueError) as info:
            parse_candidate(bad)
        assert words in str(info.value), bad


def test_fit_rule_takes_the_best_worst_case_and_breaks_ties_by_the_median():
    rows = [_row(0.005, {"admm-uv@1": (3.0, -0.5), "admm-uvst@1": (0.5, 0.0), "admm-uv-xc@1": (2.0, -0.05)}),
            _row(0.0051, {"admm-uv@1": (4.0, 0.5), "admm-uvst@1": (0.6, 0.1), "admm-uv-xc@1": (2.5, 0.3)})]
    (band,) = fit_rule(rows, "both")
    # worst cases: uv -0.5, uvst 0.0, uv-xc -0.05, Malvar 0: uvst, uv-xc and Malvar tie within 0.1 dB and
    # uv-xc has the largest median of those (of the mean of its two views' gains)
    assert band["worst_gains_db"] == pytest.approx({"malvar": 0.0, "admm-uv@1": -0.5, "admm-uvst@1": 0.0,
                                                    "admm-uv-xc@1": -0.05})
    assert band["candidate"] == "admm-uv-xc@1" and band["worst_gain_db"] == pytest.approx(-0.05)
    assert band["captures"] == 2 and band["lens_ratio_range"] == [5.0, 5.0]
    # judged on the centre view alone, admm-uv never loses and gains most
    assert fit_rule(rows, "center")[0]["candidate"] == "admm-uv@1"
    # where every candidate loses more than the tie margin, Malvar is the pick
    losing = [_row(0.005, {"admm-uv@1": (-1.0, 0.2), "admm-uvst@1": (0.4, -0.3)})]
    assert fit_rule(losing, "both")[0]["candidate"] == "malvar"


@pytest.mark.parametrize("epi_worst, taken", [(1.49, False), (1.51, True)])
def test_a_costly_candidate_takes_a_band_only_by_the_margin_over_the_cheap_pick(epi_worst, taken):
    rows = [_row(0.005, {"admm-uv@1": (2.0, 0.5), "admm-epi@1": (epi_worst + 1.0, epi_worst)}),
            _row(0.0051, {"admm-uv@1": (3.0, 0.6), "admm-epi@1": (epi_worst + 2.0, epi_worst + 0.5)})]
    (band,) = fit_rule(rows, "both")  # worst cases: admm-uv +0.5, admm-epi epi_worst; the margin is 1 dB
    assert band["candidate"] == ("admm-epi@1" if taken else "admm-uv@1")
    assert band["cheap_pick"] == {"candidate": "admm-uv@1", "worst_gain_db": pytest.approx(0.5),
                                  "median_gain_db": pytest.approx(1.525)}  # (1.25 + 1.8) / 2
    assert band["costly_margin_db"] == 1.0
    # without the margin the costly candidate wins on its worst case, as any other would
    assert fit_rule(rows, "both", margin_db=0.0)[0]["candidate"] == "admm-epi@1"
    # rows without a costly candidate fit as before, with no cheap pick recorded
    cheap = [{**r, "gains": {"admm-uv@1": r["gains"]["admm-uv@1"]}} for r in rows]
    assert "cheap_pick" not in fit_rule(cheap, "both")[0]


@pytest.mark.parametrize("dark_worst, taken", [(0.45, False), (0.55, True), (1.45, True)])
def test_a_costly_candidate_keeps_the_darker_bands_where_it_is_no_worse(dark_worst, taken):
    # two bands a quarter decade apart; the cheap pick's worst case is +0.5 dB in both, and the costly
    # candidate's in the dark band beats it by less than the 1 dB margin in every case
    dark = [_row(0.0011, {"admm-uv@1": (2.0, 0.5), "admm-epi@1": (5.0, dark_worst)})]
    bright = [_row(0.0025, {"admm-uv@1": (2.0, 0.5), "admm-epi@1": (4.0, 1.6)})]  # beats it by 1.1 dB: it pays
    bands = fit_rule(dark + bright, "both")
    # the dark band goes with the paying band above it unless the costly worst case is below the cheap pick's
    assert [b["candidate"] for b in bands] == (["admm-epi@1"] if taken else ["admm-uv@1", "admm-epi@1"])
    if taken:
        assert bands[0]["captures"] == 2 and bands[0]["worst_gain_db"] == pytest.approx(dark_worst)
        assert bands[0]["cheap_pick"]["candidate"] == "admm-uv@1"
        assert "in darker bands where it is no worse" in choose(0.0011, bands).reason
    # without a paying band above it, the dark band stays with the cheap pick
    flat = [_row(0.0025, {"admm-uv@1": (2.0, 0.5), "admm-epi@1": (4.0, 1.4)})]
    assert [b["candidate"] for b in fit_rule(dark + flat, "both")] == ["admm-uv@1"]


def test_a_paying_dark_band_does_not_take_a_brighter_one():
    dark = [_row(0.0011, {"admm-uv@1": (2.0, 0.5), "admm-epi@1": (5.0, 1.6)})]  # pays: +1.1 dB over admm-uv
    bright = [_row(0.0025, {"admm-uv@1": (2.0, 0.5), "admm-epi@1": (4.0, 1.4)})]  # no worse, does not pay
    assert [b["candidate"] for b in fit_rule(dark + bright, "both")] == ["admm-epi@1", "admm-uv@1"]


def test_fit_rule_bands_are_contiguous_and_merge_equal_neighbours():
    rows = [_row(s, {"admm-uv@1": (1.0, 0.2), "admm-uvst@1": (0.5, 0.1)}) for s in (0.0011, 0.002, 0.0035)]
    rows.append(_row(0.009, {"admm-uv@1": (-1.0, 0.2), "admm-uvst@1": (0.5, 0.1)}))
    bands = fit_rule(rows, "both")
    assert [b["candidate"] for b in bands] == ["admm-uv@1", "admm-uvst@1"]
    assert all(a["sigma_to"] == b["sigma_from"] for a, b in itertools.pairwise(bands))
    assert bands[0]["sigma_from"] <= 0.0011 and bands[-1]["sigma_to"] > 0.009
    assert bands[0]["captures"] == 3 and choose(0.0025, bands).method == "admm-uv"


def test_fit_rules_fits_every_view_on_every_capture():
    rows = [_row(0.005, {"admm-uv@1": (2.0, 0.3), "admm-uvst@1": (0.5, 0.0)}),
            _row(0.005, {"admm-uv@1": (1.5, 0.2), "admm-uvst@1": (0.3, 0.0)}, ratio=1.1, capture="finetexture 1")]
    rules = fit_rules(rows)
    assert {view: [b["candidate"] for b in bands] for view, bands in rules["rules"].items()} == \
        {"both": ["admm-uv@1"], "center": ["admm-uv@1"], "mean": ["admm-uv@1"]}
    assert rules["rules"]["both"][0]["captures"] == 2 and rules["rules"]["both"][0]["lens_ratio_range"] == [1.1, 5.0]
    assert rules["captures"] == ["charts 1", "finetexture 1"]
    assert choose(0.005, lens_ratio=1.1, rules=rules).method == "admm-uv"


def test_row_gain_of_both_views_is_the_lower():
    row = _row(0.005, {"admm-uv@1": (2.0, -0.3)})
    assert (row_gain(row, "admm-uv@1", "both"), row_gain(row, "admm-uv@1", "center"),
            row_gain(row, "admm-uv@1", "mean"), row_gain(row, "malvar", "both")) == (-0.3, 2.0, -0.3, 0.0)
    assert (row_merit(row, "admm-uv@1", "both"), row_merit(row, "admm-uv@1", "center")) == (0.85, 2.0)


def test_shipped_rule_is_what_the_fit_gives_on_its_training_rows():
    from importlib import resources

    if not ROWS_FILE.is_file():
        pytest.fail(f"{ROWS_FILE} (the rows research/fit_auto.py fitted the shipped rule on) is missing")
    rows = json.loads(ROWS_FILE.read_text())["rows"]
    shipped = json.loads(resources.files("lfcl.data").joinpath("auto_rule.json").read_text())
    dropped = set(shipped.get("dropped", []))
    for row in rows:  # what the shipped rule was fitted without (research/fit_auto.py rule --drop)
        row["gains"] = {c: g for c, g in row["gains"].items() if c not in dropped}
    refit = fit_rules(rows)
    for rules in ("rules", "cheap_rules"):
        assert {v: [b["candidate"] for b in bands] for v, bands in refit[rules].items()} == \
            {v: [b["candidate"] for b in bands] for v, bands in shipped[rules].items()}, rules
    for view in ("both", "center", "mean"):
        bands = load_rule(view)
        assert all(b["view"] == view for b in bands)
        assert all(b["worst_gain_db"] >= -b["tie_db"] for b in bands)  # never worse than Malvar on training
    # every training capture family is there, the real light fields are not (they are held out)
    captures = {r["capture"].split()[0] for r in rows}
    assert {"charts", "deadleaves", "finetexture"} <= captures and not captures & {"antinous", "lytro"}


@pytest.mark.parametrize("outputs, view", [
    (["center"], "center"), (["mean"], "mean"), (["refocus"], "mean"), (["mean", "refocus"], "mean"),
    (["center", "mean"], "both"), (["lightfield"], "both"), (["views"], "both"), (["center", "views-each"], "both"),
])
def test_view_for_outputs(outputs, view):
    from lfcl.demosaic.auto import view_for_outputs

    assert view_for_outputs(outputs) == view


def test_choose_records_the_view_and_refuses_an_unknown_one():
    center = choose(0.004, view="center")
    assert center.view == "center" and "(centre view)" in center.reason
    assert center.as_dict()["view"] == "center"
    assert choose(0.004).view == "both" and "whichever is worse" in choose(0.004).reason
    with pytest.raises(ValueError, match="view must be one of both, center, mean"):
        choose(0.004, view="views")
    from lfcl.pipeline.stages import Demosaic

    with pytest.raises(ValueError, match="^Demosaic: auto's view must be one of"):
        Demosaic("auto", auto_view="centre")


def test_auto_runs_the_chosen_method_and_records_why(rng):
    mosaic = (0.3 + 0.02 * rng.standard_normal((216, 216))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=0.008**2, sigma=0.008, source="test")  # a cheap pick's band
    auto = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "auto", noise=noise)
    choice = choose(0.008, lens_ratio=auto.parameters["auto"]["lens_ratio"])
    assert choice.method != "admm-epi" and choice.start is not None
    direct = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), choice.method, noise=noise, strength=choice.strength,
                           start=choice.start)
    assert auto.method == choice.method and auto.parameters["start"] == choice.start
    assert auto.parameters["auto"]["method"] == choice.method and "sigma 0.008" in auto.parameters["auto"]["reason"]
    np.testing.assert_array_equal(auto.planes, direct.planes)


def test_auto_at_low_light_runs_admm_epi_from_its_own_start(rng):
    """The shipped rule's low-light bands hold admm-epi (docs/auto.md); it runs as it ran for the rule's rows:
    from its schedule's start (guarded), not from Malvar."""
    from lfcl.solvers.epi import epi_start

    mosaic = (0.3 + 0.02 * rng.standard_normal((216, 216))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=0.0015**2, sigma=0.0015, source="test")
    choice = choose(0.0015)
    assert (choice.method, choice.start) == ("admm-epi", None)
    auto = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "auto", noise=noise)
    direct = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-epi", noise=noise)
    assert auto.method == "admm-epi" and auto.parameters["start"] == epi_start(0.0015, (9, 9))[0] == "guarded"
    np.testing.assert_array_equal(auto.planes, direct.planes)
    # where admm-epi costs more than it gains over the cheap pick, the cheap pick stays
    assert choose(0.009).method != "admm-epi" and choose(0.009, view="center").method != "admm-epi"



def test_auto_cheap_never_picks_a_costly_method_and_stays_safe():
    from lfcl.demosaic.auto import COSTLY_METHODS, VIEWS

    for view in VIEWS:
        cheap = load_rule(view, costly=False)
        assert all(b["worst_gain_db"] >= -b["tie_db"] for b in cheap)  # never worse than Malvar on training
        assert not any(parse_candidate(b["candidate"])[0] in COSTLY_METHODS for b in cheap)
        for sigma in np.geomspace(2e-4, 5e-2, 25):
            choice = choose(float(sigma), view=view, costly=False)
            assert choice.method not in COSTLY_METHODS and choice.costly is False
            assert choice.reason.startswith("without the costly methods (admm-epi): ")
            assert choose(float(sigma), view=view).costly is True
    # where the shipped rule runs admm-epi, the cheap rule runs what it would have run without it, and the
    # reason names it
    assert choose(0.0015).method == "admm-epi" and choose(0.0015, costly=False).method == "admm-uv-xc"
    cheap_band = next(b for b in load_rule("both", costly=False) if b["sigma_from"] <= 0.0015 < b["sigma_to"])
    assert cheap_band["candidate"].startswith("admm-uv-xc@")
    assert f"; --auto-cheap runs {cheap_band['candidate']} here" in choose(0.0015).reason
    assert "--auto-cheap" not in choose(0.009).reason  # a cheap pick already


def test_auto_cheap_runs_the_cheap_rule_s_pick(rng):
    mosaic = (0.3 + 0.02 * rng.standard_normal((216, 216))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=0.0015**2, sigma=0.0015, source="test")
    auto = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "auto", noise=noise, auto_costly=False)
    choice = choose(0.0015, lens_ratio=auto.parameters["auto"]["lens_ratio"], costly=False)
    direct = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), choice.method, noise=noise, strength=choice.strength,
                           start=choice.start)
    assert auto.method == choice.method != "admm-epi" and auto.parameters["auto"]["costly"] is False
    np.testing.assert_array_equal(auto.planes, direct.planes)


def test_bands_of_lens_rows_each_stop_on_their_own_rule(rng):
    mosaic = (0.3 + 0.02 * rng.standard_normal((27, 18))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=0.004**2, sigma=0.004, source="test")
    banded = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-uv", noise=noise, max_memory=30_000)
    assert banded.stop_reason.startswith("3 bands of lens rows") and np.all(np.isfinite(banded.planes))
    assert {h["band"] for h in banded.history} == {0, 1, 2}


@pytest.mark.parametrize("db", [0.05, 0.5, 2.0])
def test_tolerance_db_round_trips_and_bounds_the_change(db):
    from lfcl.demosaic.methods import admm_params, change_for_tolerance_db, tolerance_db_for_change

    assert tolerance_db_for_change(change_for_tolerance_db(db)) == pytest.approx(db)
    # a change c of an image with rms error e >= sigma moves PSNR by at most db
    sigma, e = 0.01, 0.01
    c = change_for_tolerance_db(db) * sigma
    assert -20 * np.log10((e - c) / e) <= db + 1e-9
    assert admm_params("admm-uv", sigma, tolerance_db=db).change_tol == pytest.approx(c)


def test_tolerance_db_must_be_positive():
    from lfcl.demosaic.methods import change_for_tolerance_db

    with pytest.raises(ValueError, match="dB > 0"):
        change_for_tolerance_db(0.0)


@pytest.mark.parametrize("candidate, ran", [("admm-uv-xc@2:linear4d", ("admm-uv-xc", 2.0)),
                                            ("admm-uv-xc@1:guarded", ("admm-uv-xc", 1.0)),
                                            ("linear4d", ("admm-uv", 1.0))])
def test_auto_without_linear4d_coefficients_for_the_pitch_runs_from_malvar(rng, monkeypatch, candidate, ran):
    import lfcl.demosaic.auto

    band = {"sigma_from": 0.0, "sigma_to": 1.0, "candidate": candidate, "worst_gain_db": 0.0, "median_gain_db": 0.0,
            "tie_db": 0.1, "captures": 1}
    monkeypatch.setattr(lfcl.demosaic.auto, "load_rules", lambda: {"rules": {"both": [band]}})
    mosaic = (0.3 + 0.02 * rng.standard_normal((80, 80))).astype(np.float32)  # 16x16 lenses of 5x5 pixels
    noise = NoiseEstimate(gain=0.0, floor=0.004**2, sigma=0.004, source="test")
    auto = demosaic_grid(mosaic, "GRBG", AlignedGrid((5, 5)), "auto", noise=noise)
    record = auto.parameters["auto"]
    assert (record["method"], record["strength"], record["start"]) == (*ran, "malvar")
    assert record["replaced"]["start" if candidate != "linear4d" else "method"] == candidate.rpartition(":")[2]
    assert "coefficients for 9x9 lenses only, not 5x5" in record["reason"]
    direct = demosaic_grid(mosaic, "GRBG", AlignedGrid((5, 5)), ran[0], noise=noise, strength=ran[1])
    np.testing.assert_array_equal(auto.planes, direct.planes)


@pytest.mark.parametrize("shape", [(1, 1), (3, 40), (23, 30)])
def test_auto_runs_malvar_on_a_frame_too_small_for_the_priors(rng, shape):
    # Fewer lenses on a side than twice admm-epi's halo: most lenses lie at the frame's edge, where the priors lost to
    # Malvar (docs/auto.md, "Small frames"). Decided before any noise estimate (a 1x1-lens raw allows none).
    from lfcl.demosaic.auto import min_lenses, prior_dmax
    from lfcl.solvers.epi import epi_halo

    assert min_lenses((9, 9)) == 2 * epi_halo([prior_dmax()], (9, 9)) == 24
    S, T = shape
    mosaic = (0.3 + 0.02 * rng.standard_normal((9 * S, 9 * T))).astype(np.float32)
    auto = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "auto")
    record = auto.parameters["auto"]
    assert auto.method == record["method"] == "malvar" and record["sigma"] is None
    assert f"a frame of {S}x{T} lenses, fewer than 24 on a side" in record["reason"]
    np.testing.assert_array_equal(auto.planes, demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "malvar").planes)


def test_a_skipped_costly_candidate_is_told_by_the_margin_rule():
    # admm-epi gains more than the pick, but by less than the costly margin: the reason names that rule, not a tie
    from lfcl.demosaic.auto_report import skipped_by_auto

    rule = [{"sigma_from": 0.0, "sigma_to": 1.0, "candidate": "admm-uv-xc@1", "tie_db": 0.1, "captures": 30,
             "costly_margin_db": 1.0,
             "worst_gains_db": {"malvar": 0.0, "admm-uv-xc@1": 0.01, "admm-epi@1": 0.35, "admm-uv@1": 0.02},
             "median_gains_db": {"malvar": 0.0, "admm-uv-xc@1": 1.29, "admm-epi@1": 2.75, "admm-uv@1": 1.0}}]
    skipped = {s["output"]: s["reason"] for s in skipped_by_auto({"method": "admm-uv-xc", "sigma": 0.01}, rule)}
    assert "beats the cheap pick's by 1 dB" in skipped["admm-epi@1"] and "ties" not in skipped["admm-epi@1"]
    assert "ties within 0.1 dB go to the larger median" in skipped["admm-uv@1"]

"""`--method auto`: the rule table, its fit, and the demosaic it runs (lfcl/auto.py)."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.auto import choose, load_rule, parse_candidate
from lfcl.bench.auto_rule import band_of, fit_rule, held_out_losses, parse_seeds
from lfcl.methods import demosaic_lightfield
from lfcl.noise import NoiseEstimate

RULE = (
    {"sigma_from": 0.001, "sigma_to": 0.01, "candidate": "malvar", "worst_loss_db": 0.05, "within_db": 0.1,
     "captures": 2},
    {"sigma_from": 0.01, "sigma_to": 0.1, "candidate": "admm-uv@2", "worst_loss_db": 0.0, "within_db": 0.1,
     "captures": 2},
)


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


def test_a_candidate_with_another_start_is_a_fixed_method_and_its_loss_counts():
    # the linear4d start at strength 1 is a fixed method (`--start linear4d`), so the loss of the
    # Malvar start is measured against it too; strength 2 is not fixed and does not set the bar
    rows = [_row(0.005, {"admm-uv-xc@1": (40.0, 45.0, 1.0), "admm-uv-xc@1:linear4d": (39.5, 46.0, 1.0),
                         "admm-uv-xc@2": (41.0, 47.0, 1.0)})]
    rule = fit_rule(rows, within=0.1)
    assert rule[0]["losses_db"] == pytest.approx({"admm-uv-xc@1": 1.0, "admm-uv-xc@1:linear4d": 0.5,
                                                  "admm-uv-xc@2": -1.0})
    assert rule[0]["candidate"] == "admm-uv-xc@2"
    assert choose(0.005, rule).start == "malvar"
    held_out = held_out_losses([dict(rows[0], scene="charts", seed=0, lux=12)], rule)
    # no fixed method is best in both views: the one with the smaller worse-view loss (linear4d's
    # 0.5 dB on the centre view, against Malvar-start's 1 dB on the mean image) is what a choice
    # among them with the ground truth would lose
    assert held_out == [{"scene": "charts", "seed": 0, "lux": 12, "candidate": "admm-uv-xc@2",
                         "loss_db": pytest.approx(-1.0), "oracle_loss_db": pytest.approx(0.5),
                         "oracle": "admm-uv-xc@1:linear4d"}]


def test_parse_seeds():
    assert parse_seeds("1,2") == [1, 2]
    assert parse_seeds("2000-2002,7") == [2000, 2001, 2002, 7]
    assert parse_seeds("") == []


def _row(sigma, results):
    return {"sigma": sigma, "results": {n: {"psnr_center": c, "psnr_mean": m, "seconds": t}
                                        for n, (c, m, t) in results.items()}}


def test_fit_rule_takes_the_cheapest_candidate_close_enough_to_the_best():
    # band of sigma 0.002: malvar loses 0.05 dB at most and is cheapest -> malvar;
    # band of sigma 0.02: malvar loses 1 dB -> the ADMM candidate.
    rows = [
        _row(0.002, {"malvar": (40.0, 45.0, 0.01), "admm-uv@1": (40.05, 45.0, 1.0), "admm-uv@2": (40.0, 44.9, 1.0)}),
        _row(0.02, {"malvar": (30.0, 35.0, 0.01), "admm-uv@1": (31.0, 36.0, 1.0), "admm-uv@2": (30.5, 36.2, 1.0)}),
    ]
    rule = fit_rule(rows, within=0.1)
    assert [b["candidate"] for b in rule] == ["malvar", "admm-uv@1"]
    assert rule[0]["worst_loss_db"] == pytest.approx(0.05)
    # admm-uv@2 is not a fixed method: it beats admm-uv@1 on the mean but loses 0.5 dB on the centre
    assert rule[1]["losses_db"]["admm-uv@2"] == pytest.approx(0.5)
    assert band_of(0.002) != band_of(0.02)


def test_band_ceiling_counts_the_best_single_candidate_of_each_band_and_class():
    from lfcl.bench.auto_rule import band_ceiling

    # one band, two kinds of content: each method wins one kind by 1 dB, so one pick reaches 2 of 3
    rows = [_row(0.002, {"admm-uv@1": (40.0, 45.0, 0.1), "admm-uv-xc@1": (39.0, 45.0, 0.1)}),
            _row(0.0021, {"admm-uv@1": (41.0, 45.0, 0.1), "admm-uv-xc@1": (40.15, 45.0, 0.1)}),
            _row(0.0022, {"admm-uv@1": (39.0, 45.0, 0.1), "admm-uv-xc@1": (40.0, 45.0, 0.1)})]
    ceiling = band_ceiling(rows, "center")
    assert (ceiling["within"], ceiling["captures"]) == (2, 3)
    assert [b["candidate"] for b in ceiling["bands"]] == ["admm-uv@1"]
    assert ceiling["bands"][0]["worst_loss_db"] == pytest.approx(1.0)
    # the same content split into classes by the cross-lens ratio: each class may take its own pick
    rows[2]["lens_ratio"] = 1.5
    split = band_ceiling(rows, "center")
    assert split["within"] == 3
    assert [(b["content"], b["candidate"]) for b in split["bands"]] == [("default", "admm-uv@1"),
                                                                        ("low-ratio", "admm-uv-xc@1")]
    # no rule that picks one candidate per band does better on these captures: the fitted one neither
    fitted = held_out_losses([dict(r, scene="s", seed=0, lux=1) for r in rows], fit_rule(rows, 0.1, "center"),
                             "center")
    assert sum(r["loss_db"] <= 0.2 for r in fitted) <= ceiling["within"]


def test_auto_check_names_the_pick_the_best_fixed_method_per_view_and_the_loss():
    from lfcl.bench.auto_check import check_rows, format_check

    rule = fit_rule([_row(0.002, {"malvar": (40.0, 45.0, 0.01), "admm-uv@1": (40.05, 45.0, 1.0)})], within=0.1)
    # a new capture in that band: the rule's pick (malvar) now trails admm-uv@1 on the centre view,
    # and the best mean image is the unfixed admm-uv@2's, which is not a peer
    held = dict(_row(0.0021, {"malvar": (38.0, 44.0, 0.01), "admm-uv@1": (39.5, 43.0, 1.0),
                              "admm-uv@2": (41.0, 46.0, 1.0)}), scene="antinous", seed=0, lux=12)
    (checked,) = check_rows([held], rule)
    assert checked["auto"] == "malvar"
    assert checked["best_center"] == ["admm-uv@1", 39.5] and checked["best_mean"] == ["malvar", 44.0]
    assert checked["loss_db"] == pytest.approx(1.5)
    assert checked["malvar_psnr"] == [38.0, 44.0]
    assert "| antinous |" in format_check([checked])


def test_auto_check_refuses_candidates_without_the_rules_picks(capsys):
    from lfcl.bench.auto_check import main

    with pytest.raises(SystemExit) as exit_info:
        main(["--scenes", "charts", "--lenses", "8", "--lux", "12", "--methods", "malvar,admm-uv@1"])
    assert exit_info.value.code == 2
    assert "missing" in capsys.readouterr().err


@pytest.mark.parametrize("view", ["both", "mean"])
def test_auto_check_scores_the_shipped_rule_on_a_capture(tmp_path, capsys, view):
    import json

    from lfcl.bench.auto_check import main
    from lfcl.bench.auto_rule import candidate_name, capture_loss, oracle_loss

    main(["--scenes", "charts", "--lenses", "16", "--lux", "12", "--json", str(tmp_path / "check.json"),
          "--view", view])
    saved = json.loads((tmp_path / "check.json").read_text())
    (row,), (checked,) = saved["rows"], saved["checked"]
    picked = choose(row["sigma"], lens_ratio=row["lens_ratio"], view=view)
    assert checked["auto"] == candidate_name(picked.method, picked.strength, picked.start)
    assert checked["loss_db"] == pytest.approx(capture_loss(row, checked["auto"], view))
    assert (checked["oracle_loss_db"], checked["oracle"]) == pytest.approx(oracle_loss(row, view))
    assert checked["auto_psnr"][0] == pytest.approx(row["results"][checked["auto"]]["psnr_center"])
    assert checked["lens_ratio"] == row["lens_ratio"]
    assert checked["seen_content"] == choose(row["sigma"], lens_ratio=row["lens_ratio"], view=view).seen_content
    assert "within 0.2 dB at" in capsys.readouterr().out


def test_training_captures_take_light_fields_at_every_seed(tmp_path):
    from lfcl.bench.auto_rule import training_captures

    data = np.random.default_rng(3).random((6, 5, 9, 9, 3)).astype(np.float32) + 0.1
    np.save(tmp_path / "mine.npy", data)
    captures = list(training_captures([], [1, 2], [], [12.0], (4, 3), [str(tmp_path / "mine.npy")]))
    assert [(scene, seed, lux) for scene, seed, lux, _ in captures] == [("mine.npy", 1, 12.0), ("mine.npy", 2, 12.0)]
    first, second = (capture for *_, capture in captures)
    crop = data[1:5, 1:4]  # the centre 4x3 lenses
    np.testing.assert_allclose(first.truth / first.truth.mean(), crop / crop.mean(), rtol=1e-4)
    assert first.mosaic.shape == (36, 27) and not np.array_equal(first.mosaic, second.mosaic)  # new noise per seed


def test_capture_options_take_a_light_fields_full_frame(tmp_path):
    import argparse

    from lfcl.bench.auto_check import capture_label
    from lfcl.bench.timing import add_capture_arguments, captures

    data = np.random.default_rng(5).random((6, 5, 9, 9, 3)).astype(np.float32) + 0.1
    np.save(tmp_path / "mine.npy", data)
    parser = argparse.ArgumentParser()
    add_capture_arguments(parser, "malvar")
    args = parser.parse_args(["--lightfield", str(tmp_path / "mine.npy"), "--lenses", "full,4", "--lux", "12"])
    (full_lenses, scene, _, full), (crop_lenses, _, _, crop) = captures(args)
    assert (full_lenses, crop_lenses) == (None, 4)
    assert full.mosaic.shape == (54, 45) and crop.mosaic.shape == (36, 36)  # every lens, then the centre 4x4
    np.testing.assert_allclose(full.truth / full.truth.mean(), data / data.mean(), rtol=1e-4)
    assert capture_label(scene, None) == "mine.npy (full frame)" and capture_label(scene, 4) == "mine.npy"


def test_a_built_in_scene_has_no_full_frame():
    import argparse

    from lfcl.bench.timing import add_capture_arguments, captures
    from lfcl.evaluate import simulated_capture

    with pytest.raises(ValueError, match="only a light field has a full frame"):
        simulated_capture(None, 12.0, scene="charts")
    parser = argparse.ArgumentParser()
    add_capture_arguments(parser, "malvar")
    with pytest.raises(SystemExit, match="--lenses full needs --lightfield"):
        list(captures(parser.parse_args(["--scenes", "charts", "--lenses", "full"])))


def test_capture_options_texture_every_scene_with_every_image(tmp_path):
    import argparse

    from lfcl.bench.auto_check import capture_label
    from lfcl.bench.timing import add_capture_arguments, captures
    from lfcl.imageio import write_image

    for k in range(2):
        write_image(tmp_path / f"photo{k}.png", np.random.default_rng(k).random((30, 40, 3)).astype(np.float32))
    parser = argparse.ArgumentParser()
    add_capture_arguments(parser, "malvar")
    textures = f"{tmp_path / 'photo0.png'},{tmp_path / 'photo1.png'}"
    made = list(captures(parser.parse_args(["--scenes", "charts", "--texture", textures, "--lenses", "6",
                                            "--lux", "12"])))
    assert [capture.meta["scene"]["texture"] for *_, capture in made] == textures.split(",")
    assert not np.allclose(made[0][3].truth, made[1][3].truth)
    assert capture_label("charts", 6, made[1][3].meta["scene"]["texture"]) == "charts + photo1.png"
    with pytest.raises(SystemExit, match="a --lightfield has none"):
        list(captures(parser.parse_args(["--lightfield", str(tmp_path), "--texture", textures])))


def test_fit_rule_breaks_ties_of_the_worst_loss_by_the_mean_loss_before_the_cost():
    # one hard capture costs every candidate 2 dB, so the worst losses tie; on the other two the cheap
    # admm-uv@1 loses 0.5 dB and admm-uv-xc@1 nothing: the mean (0.83 against 0.67 dB) decides
    hard = _row(0.005, {"admm-uv@1": (40.0, 45.0, 0.1), "admm-uv-xc@1": (40.0, 45.0, 0.2), "malvar": (42.0, 45.0, 0.01)})
    easy = [_row(0.005, {"admm-uv@1": (39.5, 45.0, 0.1), "admm-uv-xc@1": (40.0, 45.0, 0.2), "malvar": (38.0, 44.0, 0.01)})
            for _ in range(2)]
    (band,) = fit_rule([hard, *easy], within=0.1)
    assert band["losses_db"]["admm-uv@1"] == pytest.approx(2.0) and band["losses_db"]["admm-uv-xc@1"] == pytest.approx(2.0)
    assert band["mean_losses_db"]["admm-uv@1"] == pytest.approx(1.0) and band["mean_losses_db"]["admm-uv-xc@1"] == pytest.approx(2 / 3)
    assert band["candidate"] == "admm-uv-xc@1" and band["mean_loss_db"] == pytest.approx(2 / 3)
    # within 0.5 dB on average the cheaper one is good enough again
    (loose,) = fit_rule([hard, *easy], within=0.5)
    assert loose["candidate"] == "admm-uv@1"
    # the summary lists the work skipped: candidates better in the worst case or on average
    from lfcl.auto_report import skipped_by_auto

    assert skipped_by_auto({"method": "admm-uv-xc", "sigma": 0.005}, [band]) == []
    (skipped,) = skipped_by_auto({"method": "admm-uv", "sigma": 0.005}, [loose])
    assert skipped["output"] == "admm-uv-xc@1"
    assert skipped["reason"].startswith("auto chose the cheaper admm-uv@1: ")
    assert "mean 1.00 dB against 0.67 dB" in skipped["reason"]


def test_shipped_rule_is_what_the_fit_gives_on_its_own_training_rows():
    import json
    from importlib import resources

    from lfcl.bench.auto_rule import fit_rules

    shipped = json.loads(resources.files("lfcl.data").joinpath("auto_rule.json").read_text())
    refit = fit_rules(shipped["training"], shipped["args"]["within"], shipped["args"]["low_ratio_views"].split(","),
                      shipped.get("view_training"))

    def picks(rules):
        return {key: [b["candidate"] for b in bands] for key, bands in (
            ("both", rules["rule"]), *rules["rules_by_view"].items(),
            *((f"low-ratio {view}", bands) for view, bands in rules["low_ratio"]["rules_by_view"].items()))}

    assert picks(refit) == picks(shipped)
    assert [b["candidate"] for b in load_rule()] == picks(shipped)["both"]
    assert [b["candidate"] for b in load_rule("mean", "low-ratio")] == picks(shipped)["low-ratio mean"]
    assert refit["low_ratio"]["fitted_on"] == shipped["low_ratio"]["fitted_on"] == ["antinous"]
    assert all(np.isfinite(b["worst_loss_db"]) for b in load_rule())
    for view in ("center", "mean"):
        assert all(b["view"] == view for b in load_rule(view))


@pytest.mark.parametrize("outputs, view", [
    (["center"], "center"), (["mean"], "mean"), (["refocus"], "mean"), (["mean", "refocus"], "mean"),
    (["center", "mean"], "both"), (["lightfield"], "both"), (["views"], "both"), (["center", "views-each"], "both"),
])
def test_view_for_outputs(outputs, view):
    from lfcl.auto import view_for_outputs

    assert view_for_outputs(outputs) == view


def test_fit_rule_per_view_takes_the_best_method_of_that_view():
    # admm-uv@1 has the best centre view, admm-uvst@1 the best mean image; judged on both views
    # the compromise admm-uv-xc@1 (0.3 dB behind on each) loses least
    rows = [_row(0.005, {"admm-uv@1": (41.0, 44.0, 0.1), "admm-uvst@1": (39.0, 46.0, 0.1),
                         "admm-uv-xc@1": (40.7, 45.7, 0.2)})]
    assert [fit_rule(rows, 0.1, view)[0]["candidate"] for view in ("both", "center", "mean")] == \
        ["admm-uv-xc@1", "admm-uv@1", "admm-uvst@1"]
    (both,) = fit_rule(rows, 0.1)
    assert both["worst_loss_db"] == pytest.approx(0.3) and both["view"] == "both"
    # what the best choice among the fixed methods loses: 0.3 dB judged on both views, nothing on one
    held = [dict(rows[0], scene="charts", seed=0, lux=12)]
    assert held_out_losses(held, [both])[0]["oracle_loss_db"] == pytest.approx(0.3)
    assert held_out_losses(held, fit_rule(rows, 0.1, "mean"), "mean")[0]["oracle_loss_db"] == 0.0


def test_choose_records_the_view_and_refuses_an_unknown_one():
    center = choose(0.004, view="center")
    assert center.view == "center" and "(centre view)" in center.reason
    assert center.as_dict()["view"] == "center"
    assert choose(0.004).view == "both" and "whichever is worse" in choose(0.004).reason
    with pytest.raises(ValueError, match="view must be one of both, center, mean"):
        choose(0.004, view="views")
    from lfcl.stages import Demosaic

    with pytest.raises(ValueError, match="^Demosaic: auto's view must be one of"):
        Demosaic("auto", auto_view="centre")


def test_auto_rule_refit_fits_the_scored_rows_again(tmp_path, capsys):
    import json

    from lfcl.bench.auto_rule import main

    rows = [_row(0.005, {"admm-uv@1": (41.0, 44.0, 0.1), "admm-uvst@1": (39.0, 46.0, 0.1)})]
    held = [dict(rows[0], scene="charts", seed=0, lux=12)]
    earlier = {"args": {"scenes": "charts", "within": 0.1}, "seconds": 12.5, "training": rows, "held_out": held,
               "rule": []}
    (tmp_path / "earlier.json").write_text(json.dumps(earlier))
    main(["--refit", str(tmp_path / "earlier.json"), "-o", str(tmp_path / "rule.json"), "--within", "0.2"])
    refit = json.loads((tmp_path / "rule.json").read_text())
    assert refit["training"] == rows and refit["seconds"] == 12.5
    assert refit["args"]["scenes"] == "charts" and refit["args"]["within"] == 0.2
    assert refit["args"]["refit"] == str(tmp_path / "earlier.json")
    assert [b["candidate"] for b in refit["rule"]] == ["admm-uv@1"]  # two tie at 2 dB and 0.1 s: the first
    assert [b["candidate"] for b in refit["rules_by_view"]["mean"]] == ["admm-uvst@1"]
    assert refit["held_out_losses_by_view"]["center"][0]["loss_db"] == 0.0
    printed = capsys.readouterr().out
    assert "held out (mean): charts seed 0 12 lux: admm-uvst@1 loses 0.00 dB" in printed
    assert refit["held_out_ceiling"]["both"]["within"] == 0  # each method loses 2 dB in one view
    assert "held out (mean): the rule within 0.2 dB at 1 of 1 captures" in printed


def test_auto_rule_refit_adds_and_drops_scored_rows(tmp_path):
    import json

    from lfcl.bench.auto_rule import main

    synthetic = dict(_row(0.005, {"admm-uv@1": (41.0, 44.0, 0.1), "admm-uvst@1": (39.0, 46.0, 0.2)}),
                     scene="procedural")
    earlier = {"args": {"scenes": "charts", "within": 0.1}, "seconds": 1.0, "training": [synthetic]}
    (tmp_path / "earlier.json").write_text(json.dumps(earlier))
    photo = dict(_row(0.0051, {"admm-uv@1": (38.0, 44.0, 0.1), "admm-uvst@1": (40.0, 46.0, 0.2)}),
                 scene="charts + photo.dng", seed=1, lux=12)
    (tmp_path / "photos.json").write_text(json.dumps({"rows": [photo]}))
    held = dict(photo, scene="charts + other.dng", seed=0)
    (tmp_path / "held.json").write_text(json.dumps({"rows": [held]}))

    def refit(*extra):
        main(["--refit", str(tmp_path / "earlier.json"), "-o", str(tmp_path / "rule.json"), *extra])
        return json.loads((tmp_path / "rule.json").read_text())

    assert [b["candidate"] for b in refit()["rules_by_view"]["center"]] == ["admm-uv@1"]
    both = refit("--add-training", str(tmp_path / "photos.json"))
    assert [r["scene"] for r in both["training"]] == ["procedural", "charts + photo.dng"]
    assert both["rules_by_view"]["center"][0]["captures"] == 2
    photos_only = refit("--add-training", str(tmp_path / "photos.json"), "--drop-training", "proc*",
                        "--add-held-out", str(tmp_path / "held.json"))
    assert [r["scene"] for r in photos_only["training"]] == ["charts + photo.dng"]
    assert [b["candidate"] for b in photos_only["rules_by_view"]["center"]] == ["admm-uvst@1"]
    assert photos_only["held_out_losses_by_view"]["center"][0]["scene"] == "charts + other.dng"
    assert photos_only["args"]["drop_training"] == "proc*"
    per_view = refit("--add-training", str(tmp_path / "photos.json"), "--view-training", "center=* + *")
    assert [b["candidate"] for b in per_view["rules_by_view"]["center"]] == ["admm-uvst@1"]  # the photo alone
    assert [b["candidate"] for b in both["rules_by_view"]["center"]] == ["admm-uv@1"]  # both captures: a tie
    assert per_view["view_training"] == {"center": ["* + *"]} and per_view["rules_by_view"]["center"][0]["captures"] == 1
    with pytest.raises(SystemExit, match="no training capture"):
        refit("--view-training", "mean=nothing*")
    with pytest.raises(SystemExit, match="VIEW=PATTERN"):
        refit("--view-training", "centre=*")
    other = dict(photo, results={"malvar": photo["results"]["admm-uv@1"]})
    (tmp_path / "other.json").write_text(json.dumps({"rows": [other]}))
    with pytest.raises(SystemExit, match="other candidates"):
        refit("--add-training", str(tmp_path / "other.json"))


def test_auto_runs_the_chosen_method_and_records_why(rng):
    mosaic = (0.3 + 0.02 * rng.standard_normal((36, 36))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=0.004**2, sigma=0.004, source="test")
    auto = demosaic_lightfield(mosaic, "GRBG", (9, 9), "auto", noise=noise)
    choice = choose(0.004)
    direct = demosaic_lightfield(mosaic, "GRBG", (9, 9), choice.method, noise=noise, strength=choice.strength,
                                 start=choice.start)
    assert auto.method == choice.method and auto.parameters["start"] == choice.start
    assert auto.parameters["auto"]["method"] == choice.method and "sigma 0.004" in auto.parameters["auto"]["reason"]
    np.testing.assert_array_equal(auto.planes, direct.planes)



def test_one_region_covering_every_lens_row_is_the_whole_image_solve(rng):
    mosaic = (0.3 + 0.02 * rng.standard_normal((27, 18))).astype(np.float32)
    noise = NoiseEstimate(gain=0.0, floor=0.004**2, sigma=0.004, source="test")
    whole = demosaic_lightfield(mosaic, "GRBG", (9, 9), "admm-uv", noise=noise)
    one = demosaic_lightfield(mosaic, "GRBG", (9, 9), "admm-uv", noise=noise, region_rows=3)
    np.testing.assert_array_equal(whole.planes, one.planes)
    banded = demosaic_lightfield(mosaic, "GRBG", (9, 9), "admm-uv", noise=noise, region_rows=1)
    assert banded.stop_reason.startswith("3 bands of lens rows") and np.all(np.isfinite(banded.planes))
    assert {h["band"] for h in banded.history} == {0, 1, 2}


def test_regions_need_the_uv_prior(rng):
    mosaic = (0.3 + 0.02 * rng.standard_normal((18, 18))).astype(np.float32)
    with pytest.raises(ValueError, match="region_rows needs admm-uv"):
        demosaic_lightfield(mosaic, "GRBG", (9, 9), "admm-uvst", region_rows=1)


@pytest.mark.parametrize("db", [0.05, 0.5, 2.0])
def test_tolerance_db_round_trips_and_bounds_the_change(db):
    from lfcl.methods import admm_params, change_for_tolerance_db, tolerance_db_for_change

    assert tolerance_db_for_change(change_for_tolerance_db(db)) == pytest.approx(db)
    # a change c of an image with rms error e >= sigma moves PSNR by at most db
    sigma, e = 0.01, 0.01
    c = change_for_tolerance_db(db) * sigma
    assert -20 * np.log10((e - c) / e) <= db + 1e-9
    assert admm_params("admm-uv", sigma, tolerance_db=db).change_tol == pytest.approx(c)


def test_tolerance_db_must_be_positive():
    from lfcl.methods import change_for_tolerance_db

    with pytest.raises(ValueError, match="dB > 0"):
        change_for_tolerance_db(0.0)


@pytest.mark.parametrize("candidate, ran", [("admm-uv-xc@2:linear4d", ("admm-uv-xc", 2.0)),
                                            ("admm-uv-xc@1:guarded", ("admm-uv-xc", 1.0)),
                                            ("linear4d", ("admm-uv", 1.0))])
def test_auto_without_linear4d_coefficients_for_the_pitch_runs_from_malvar(rng, monkeypatch, candidate, ran):
    import lfcl.auto

    band = {"sigma_from": 0.0, "sigma_to": 1.0, "candidate": candidate, "worst_loss_db": 0.0, "within_db": 0.1,
            "captures": 1}
    monkeypatch.setattr(lfcl.auto, "load_rules", lambda: {"rule": [band]})
    mosaic = (0.3 + 0.02 * rng.standard_normal((25, 25))).astype(np.float32)  # 5x5 lenses of 5x5 pixels
    noise = NoiseEstimate(gain=0.0, floor=0.004**2, sigma=0.004, source="test")
    auto = demosaic_lightfield(mosaic, "GRBG", (5, 5), "auto", noise=noise)
    record = auto.parameters["auto"]
    assert (record["method"], record["strength"], record["start"]) == (*ran, "malvar")
    assert record["replaced"]["start" if candidate != "linear4d" else "method"] == candidate.rpartition(":")[2]
    assert "coefficients for 9x9 lenses only, not 5x5" in record["reason"]
    direct = demosaic_lightfield(mosaic, "GRBG", (5, 5), ran[0], noise=noise, strength=ran[1])
    np.testing.assert_array_equal(auto.planes, direct.planes)

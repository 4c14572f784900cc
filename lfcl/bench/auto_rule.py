"""Fit the rule behind ``--method auto`` (lfcl/auto.py) on training captures.

For each training scene, seed and illumination, simulate a capture, read its noise
level sigma the way ``lfcl process`` does (the DNG NoiseProfile), run every
candidate (a method, a lambda strength and, for ADMM, the start) and score it
against the ground truth. The training scenes are the built-in ones at seeds other
than the evaluation seed 0 and the procedural scenes of lfcl/bench/training_scenes.py
(seeds 2000 on; linear4d was fitted on seeds 1000-1047).
Then, for each band of sigma (four per decade), pick the *cheapest* candidate
whose worst loss against the best fixed method (every method at its default
strength, either start; PSNR of the centre view and of the mean image) is within
``--within`` dB of the smallest such loss, and whose mean loss is within ``--within``
dB of the smallest mean loss among those (``fit_rule``). It fits three rules: the
losses judged on the worse of the two views (``rule``, what ``auto`` runs by default)
and on each view alone (``rules_by_view``, for runs that write only that view:
lfcl.auto.view_for_outputs). ``--held-out-seeds`` scores the same candidates on other
captures and prints what the fitted rules lose there. ``--refit JSON`` fits again on the
scored rows of an earlier output instead of scoring anew; ``--add-training`` and
``--add-held-out`` bring in rows that ``python -m lfcl.bench.auto_check --json`` scored (raws of
photographs via ``--texture``, light fields' full frames via ``--lenses full``), ``--drop-training``
leaves scenes out and ``--view-training`` fits one view's rule on some scenes only (the shipped
mean-image rule: the photographs, docs/auto.md).

The training seeds (default 1, 2) are not the evaluation seed 0 of docs/admm.md.

    python -m lfcl.bench.auto_rule -o lfcl/data/auto_rule.json
"""

from __future__ import annotations

import argparse
import fnmatch
import math
import time
from pathlib import Path

import numpy as np

from .. import __version__
from ..auto import LOW_RATIO_BELOW, VIEWS, band_for, content_class, parse_candidate, rule_bands
from ..evaluate import capture_in_memory, run_method, simulation_capture
from ..lens_ratio import cross_lens_ratio
from ..noise import from_noise_profile

DEFAULT_CANDIDATES = ("malvar,linear4d,admm-uv@1,admm-uv@1:linear4d,admm-uvst@1,admm-uv-xc@1,admm-uv-xc@2,"
                      "admm-uv-xc@1:linear4d,admm-uv-xc@2:linear4d,admm-uvst-xc@1,"
                      "admm-uvst@1:linear4d,admm-uvst-xc@1:linear4d,admm-uv@1:lens-malvar,admm-uv-xc@1:lens-malvar,"
                      "admm-uv-xc@1:guarded")
#: Band edges in log10(sigma): four bands per decade.
BANDS_PER_DECADE = 4
#: The issue's target: ``auto`` within this many dB of the best fixed method on every capture.
TARGET_DB = 0.2
#: The PSNRs each rule's losses are judged on (lfcl.auto.VIEWS).
VIEW_KEYS = {"both": ("psnr_center", "psnr_mean"), "center": ("psnr_center",), "mean": ("psnr_mean",)}


def parse_candidates(spec: str) -> list[tuple[str, float, str]]:
    """'method[@strength][:start],...' -> [(method, strength, start)]."""
    return [parse_candidate(item.strip()) for item in spec.split(",")]


def candidate_name(method: str, strength: float, start: str = "malvar") -> str:
    if method in ("malvar", "linear4d"):
        return method
    return f"{method}@{strength:g}" + ("" if start == "malvar" else f":{start}")


def training_captures(scenes, seeds, procedural_seeds, lux_levels, lenses, lightfields=()):
    """Yield ``(scene label, seed, lux, Capture)``: built-in scenes, then procedural ones, then
    raws simulated from each of ``lightfields`` (rendered or decoded light fields; the centre
    ``lenses``, at every seed of ``seeds``), labelled with the file or folder name."""
    from ..sim import render_planes, simulate
    from ..sim.lightfield import load_lightfield
    from .training_scenes import training_planes

    def capture(radiance, lux, seed):
        return simulation_capture(simulate(lightfield=radiance, lux=lux, seed=seed))

    for scene in scenes:
        for seed in seeds:
            for lux in lux_levels:
                meta = {"scene": {"kind": "scene", "name": scene}, "lenses": list(lenses), "pitch": [9, 9],
                        "pattern": "GRBG", "seed": seed}
                yield scene, seed, lux, capture_in_memory(meta, lux)
    for seed in procedural_seeds:
        radiance = render_planes(training_planes(lenses, seed, (9, 9)), lenses, (9, 9))  # once per scene
        for lux in lux_levels:
            yield "procedural", seed, lux, capture(radiance, lux, seed)
    for path in lightfields:
        radiance = load_lightfield(path, lenses)  # once per light field
        for seed in seeds:
            for lux in lux_levels:
                yield Path(path).name, seed, lux, capture(radiance, lux, seed)


def score_captures(captures, candidates, log=print) -> list[dict]:
    """Every candidate on every capture of ``captures`` (training_captures): sigma, PSNRs and seconds."""
    rows = []
    for scene, seed, lux, capture in captures:
        row = {"scene": scene, "seed": seed, "lux": lux, "results": {},
               "lens_ratio": cross_lens_ratio(capture.mosaic, capture.pitch,
                                              from_noise_profile(capture.noise_profile, capture.mosaic))}
        for method, strength, start in candidates:
            overrides = {} if method in ("malvar", "linear4d") else {"strength": strength, "start": start}
            result = run_method(capture, method, **overrides)
            if result["noise_sigma"] is not None:
                row["sigma"] = result["noise_sigma"]
            row["results"][candidate_name(method, strength, start)] = {
                k: result[k] for k in ("psnr_center", "psnr_mean", "seconds", "iterations")}
        log(f"{scene:10s} seed {seed} {lux:6g} lux sigma {row.get('sigma', float('nan')):.5f}  " + "  ".join(
            f"{name} {r['psnr_center']:.2f}/{r['psnr_mean']:.2f}" for name, r in row["results"].items()))
        rows.append(row)
    return rows


def band_of(sigma: float) -> int:
    return math.floor(math.log10(max(sigma, 1e-12)) * BANDS_PER_DECADE)


def is_fixed(name: str) -> bool:
    """A method at its default strength (either start): the peers auto is measured against."""
    return parse_candidate(name)[1] == 1.0


def capture_loss(row: dict, name: str, view: str = "both") -> float:
    """How far candidate ``name`` falls below the best fixed method on one capture (dB; on ``view``:
    the worse of the centre view and the mean image, or one of them). The best fixed method is
    the best in each view, so with ``both`` no single method need reach 0 (:func:`oracle_loss`)."""
    fixed = [n for n in row["results"] if is_fixed(n)]
    return max(max(row["results"][n][key] for n in fixed) - row["results"][name][key]
               for key in VIEW_KEYS[view])


def oracle_loss(row: dict, view: str = "both") -> tuple[float, str]:
    """The smallest :func:`capture_loss` of any fixed method on this capture, and that method: what a
    choice among the fixed methods made with the ground truth would lose (0 for one view)."""
    losses = {n: capture_loss(row, n, view) for n in row["results"] if is_fixed(n)}
    best = min(losses, key=losses.get)
    return losses[best], best


def fit_rule(rows: list[dict], within: float, view: str = "both") -> list[dict]:
    """One entry per sigma band that has training captures: the chosen candidate and why.

    A candidate's loss on a capture is how far its PSNR (``view``: centre view or mean
    image, whichever is worse, or one of them) falls below the best fixed method's (every
    method at its default strength). Over the band's captures it has a worst loss and a mean loss.
    The chosen candidate is the cheapest (median seconds) whose worst loss is within
    ``within`` dB of the smallest worst loss and whose mean loss is within ``within``
    dB of the smallest mean loss among those: robust first, then no worse on average
    than the best robust candidate, then cheap. (Cost alone broke the ties of the worst
    loss, which one hard capture can set for every candidate, at the price of 0.22 dB
    of mean loss in one band: docs/auto.md.)
    """
    names = list(rows[0]["results"])
    seconds = {n: float(np.median([r["results"][n]["seconds"] for r in rows])) for n in names}
    bands: dict[int, list[dict]] = {}
    for r in rows:
        bands.setdefault(band_of(r["sigma"]), []).append(r)
    rule = []
    for band in sorted(bands):
        members = bands[band]
        losses = {n: [capture_loss(r, n, view) for r in members] for n in names}
        worst = {n: max(v) for n, v in losses.items()}
        mean = {n: float(np.mean(v)) for n, v in losses.items()}
        robust = [n for n in names if worst[n] <= min(worst.values()) + within]
        good = [n for n in robust if mean[n] <= min(mean[m] for m in robust) + within]
        chosen = min(good, key=lambda n: seconds[n])
        ratios = [r["lens_ratio"] for r in members if r.get("lens_ratio") is not None]
        rule.append({
            "sigma_from": 10 ** (band / BANDS_PER_DECADE), "sigma_to": 10 ** ((band + 1) / BANDS_PER_DECADE),
            "candidate": chosen, "view": view, "worst_loss_db": worst[chosen], "mean_loss_db": mean[chosen],
            "within_db": within,
            "captures": len(members), "losses_db": worst, "mean_losses_db": mean,
            "median_seconds": {n: seconds[n] for n in names},
            # the content the band was fitted on (lfcl/lens_ratio.py); auto says when a raw lies outside
            "lens_ratio_range": [min(ratios), max(ratios)] if ratios else None,
        })
    return rule


def parse_seeds(spec: str) -> list[int]:
    """'1,2' or '2000-2011' (inclusive) or '' -> seeds."""
    seeds = []
    for item in filter(None, (part.strip() for part in spec.split(","))):
        first, _, last = item.partition("-")
        seeds += list(range(int(first), int(last or first) + 1))
    return seeds


def held_out_losses(rows: list[dict], rule, view: str = "both") -> list[dict]:
    """Per held-out capture: the candidate the rule picks for its sigma, its loss on ``view``
    (capture_loss) and what the best choice among the fixed methods would lose (oracle_loss).
    ``rule``: sigma bands, or a rule file's contents (:func:`fit_rules`), whose content class
    for ``view`` the capture's cross-lens ratio picks (lfcl.auto.content_class)."""
    out = []
    for r in rows:
        bands = rule
        if isinstance(rule, dict):
            bands = rule_bands(rule, view, content_class(rule, view, r.get("lens_ratio")))
        picked = band_for(r["sigma"], bands)[0]["candidate"]
        floor, best = oracle_loss(r, view)
        out.append({"scene": r["scene"], "seed": r["seed"], "lux": r["lux"], "candidate": picked,
                    "loss_db": capture_loss(r, picked, view), "oracle_loss_db": floor, "oracle": best})
    return out


def band_ceiling(rows: list[dict], view: str = "both", target: float = TARGET_DB) -> dict:
    """The most captures of ``rows`` that any rule giving one candidate to every capture of a sigma band
    (and content class) can bring within ``target`` dB of the best fixed method: per class and band, the
    candidate within ``target`` on the most of its captures (ties: the smaller worst loss), picked with
    these captures' own ground truth. A bound on the shipped rules' held-out count, not a rule.
    Returns {"within": count, "captures": count, "bands": [per class and band: the candidate and its counts]}."""
    groups: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        groups.setdefault(("low-ratio" if is_low_ratio(r) else "default", band_of(r["sigma"])), []).append(r)
    bands = []
    for (content, band), members in sorted(groups.items()):
        names = [n for n in members[0]["results"] if all(n in r["results"] for r in members)]
        losses = {n: [capture_loss(r, n, view) for r in members] for n in names}
        best = max(names, key=lambda n: (sum(v <= target for v in losses[n]), -max(losses[n])))
        bands.append({"content": content, "sigma_from": 10 ** (band / BANDS_PER_DECADE),
                      "sigma_to": 10 ** ((band + 1) / BANDS_PER_DECADE), "candidate": best,
                      "captures": len(members), "within": sum(v <= target for v in losses[best]),
                      "worst_loss_db": max(losses[best])})
    return {"target_db": target, "within": sum(b["within"] for b in bands), "captures": len(rows), "bands": bands}


def is_low_ratio(row: dict) -> bool:
    """A capture whose content is like the real light fields' (lfcl.auto.LOW_RATIO_BELOW)."""
    return row.get("lens_ratio") is not None and row["lens_ratio"] < LOW_RATIO_BELOW


def fit_rules(rows: list[dict], within: float, low_ratio_views=("mean",), view_training=None) -> dict:
    """The rule file's rules: judged on both views (``rule``) and on each view alone (``rules_by_view``),
    fitted on the captures of the default content class; and, where some training captures lie below
    LOW_RATIO_BELOW, a rule per view of ``low_ratio_views`` fitted on those (``low_ratio``).
    ``view_training`` {view: scene patterns}: that view's default rule is fitted on the captures of
    those scenes only (:func:`scenes_matching`).

    Only the mean image has a low-ratio rule by default: on it, a rule fitted on the rendered
    ``antinous`` light field came within 0.58 dB on the real Lytro ``2067`` capture at every level,
    where on the centre view it lost up to 2.95 dB there (docs/auto.md)."""
    default = [r for r in rows if not is_low_ratio(r)]
    low = [r for r in rows if is_low_ratio(r)]
    view_training = view_training or {}

    def fitted(view: str) -> list[dict]:
        chosen = scenes_matching(default, view_training[view]) if view in view_training else default
        if not chosen:
            raise SystemExit(f"no training capture of the default content class matches "
                             f"{', '.join(view_training[view])} for the {view} rule")
        return fit_rule(chosen, within, view)

    rules = {"rule": fitted("both"), "rules_by_view": {view: fitted(view) for view in VIEWS if view != "both"}}
    if view_training:
        rules["view_training"] = {view: list(patterns) for view, patterns in view_training.items()}
    if low and low_ratio_views:
        rules["low_ratio"] = {
            "below": LOW_RATIO_BELOW, "fitted_on": sorted({r["scene"] for r in low}), "captures": len(low),
            "rules_by_view": {view: fit_rule(low, within, view) for view in low_ratio_views}}
    return rules


def _views(spec: str) -> tuple[str, ...]:
    views = tuple(part.strip() for part in spec.split(",") if part.strip())
    unknown = [v for v in views if v not in VIEWS]
    if unknown:
        raise SystemExit(f"--low-ratio-views: unknown view {', '.join(unknown)}; choose from {', '.join(VIEWS)}")
    return views


def _paths(spec: str) -> list[str]:
    return [part.strip() for part in spec.split(",") if part.strip()]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--output", required=True)
    parser.add_argument("--refit", metavar="JSON", default=None,
                        help="fit on the scored training and held-out rows of an earlier output (its capture and "
                             "candidate options are kept; the options below that say what to score are ignored)")
    parser.add_argument("--scenes", default="charts,deadleaves")
    parser.add_argument("--seeds", default="1,2")
    parser.add_argument("--procedural-seeds", default="2000-2011",
                        help="seeds of lfcl/bench/training_scenes.py scenes to train on ('' for none)")
    parser.add_argument("--lightfields", default="", metavar="PATHS",
                        help="rendered or decoded light fields (comma-separated; HCI-layout or NAME_UU_VV.png folders "
                             "or .npy) whose simulated raws join the training captures, at every --seeds seed")
    parser.add_argument("--held-out-seeds", default="", help="seeds of --scenes to score the fitted rule on")
    parser.add_argument("--held-out-lightfields", default="", metavar="PATHS",
                        help="light fields to score the fitted rule on, at every --held-out-seeds seed")
    parser.add_argument("--lux", default="0.25,0.5,1,2,4,8,12,25,50,100,200")
    parser.add_argument("--lenses", default="64x64")
    parser.add_argument("--candidates", default=DEFAULT_CANDIDATES)
    parser.add_argument("--low-ratio-views", default="mean", metavar="VIEWS",
                        help="views (comma-separated; '' for none) that get a rule of their own for training captures "
                             f"whose cross-lens ratio lies below {LOW_RATIO_BELOW:g} (content like the real light "
                             "fields, e.g. from --lightfields)")
    parser.add_argument("--within", type=float, default=0.1,
                        help="dB a cheaper candidate may lose, in the worst case and on average")
    parser.add_argument("--add-training", default="", metavar="JSONS",
                        help="scored rows (comma-separated files: `auto_check --json` outputs, e.g. raws of photographs "
                             "via --texture or full frames via --lenses full) that join the training captures")
    parser.add_argument("--add-held-out", default="", metavar="JSONS",
                        help="scored rows (as --add-training) that join the held-out captures")
    parser.add_argument("--drop-training", default="", metavar="SCENES",
                        help="scene names (comma-separated shell patterns, e.g. 'procedural' or '* + *') whose "
                             "training captures the fit leaves out")
    parser.add_argument("--view-training", action="append", default=[], metavar="VIEW=SCENES",
                        help="fit VIEW's rule (both, center or mean) on the training captures of these scenes only "
                             "(shell patterns as --drop-training; repeatable); the other views take every capture")
    args = parser.parse_args(argv)
    if args.refit:
        out = _scored_rows(args.refit, args)
    else:
        out = _score(args)
    out["training"] = _dropped(out["training"] + _added_rows(_paths(args.add_training), out["training"]),
                               _paths(args.drop_training))
    held = out.get("held_out", []) + _added_rows(_paths(args.add_held_out), out["training"])
    if held:
        out["held_out"] = held
    rules = fit_rules(out["training"], args.within, _views(args.low_ratio_views), _view_training(args.view_training))
    out.update(rules)
    if out.get("held_out"):
        out["held_out_losses"] = held_out_losses(out["held_out"], rules)
        out["held_out_losses_by_view"] = {view: held_out_losses(out["held_out"], rules, view)
                                          for view in out["rules_by_view"]}
        out["held_out_ceiling"] = {view: band_ceiling(out["held_out"], view) for view in VIEWS}
    from ..imageio import write_json

    write_json(args.output, out)
    low = out.get("low_ratio", {}).get("rules_by_view", {})
    for view, rule in (("both", out["rule"]), *out["rules_by_view"].items(), *((f"{v}, low ratio", r)
                                                                            for v, r in low.items())):
        for band in rule:
            print(f"{view:6s} sigma {band['sigma_from']:.4g}-{band['sigma_to']:.4g}: {band['candidate']} "
                  f"(worst loss {band['worst_loss_db']:.2f} dB, mean {band['mean_loss_db']:.2f} dB over "
                  f"{band['captures']} captures)")
    views = {"both": out.get("held_out_losses", []), **out.get("held_out_losses_by_view", {})}
    for view, rows in views.items():
        for row in rows:
            print(f"held out ({view}): {row['scene']} seed {row['seed']} {row['lux']:g} lux: {row['candidate']} "
                  f"loses {row['loss_db']:.2f} dB to the best fixed method (the best choice among them, "
                  f"{row['oracle']}, {row['oracle_loss_db']:.2f} dB)")
    for view, rows in views.items():
        if rows:  # what the rule reached against what any rule of one candidate per band could
            ceiling = out["held_out_ceiling"][view]
            print(f"held out ({view}): the rule within {TARGET_DB:g} dB at "
                  f"{sum(r['loss_db'] <= TARGET_DB for r in rows)} of {len(rows)} captures; one candidate per "
                  f"sigma band and content class, picked on these captures' ground truth, at most {ceiling['within']}")


def _score(args) -> dict:
    """Score every candidate on the training (and held-out) captures the options name."""
    began = time.perf_counter()
    lux = [float(v) for v in args.lux.split(",")]
    lenses = tuple(int(n) for n in args.lenses.split("x"))
    candidates = parse_candidates(args.candidates)
    scenes = args.scenes.split(",")
    rows = score_captures(training_captures(scenes, parse_seeds(args.seeds), parse_seeds(args.procedural_seeds), lux,
                                            lenses, _paths(args.lightfields)), candidates)
    out = {"generator": f"lfcl {__version__} python -m lfcl.bench.auto_rule", "args": vars(args), "training": rows}
    held_out = parse_seeds(args.held_out_seeds)
    if held_out:
        out["held_out"] = score_captures(training_captures(scenes, held_out, [], lux, lenses,
                                                           _paths(args.held_out_lightfields)), candidates)
    out["seconds"] = time.perf_counter() - began
    return out


def _added_rows(paths: list[str], like: list[dict]) -> list[dict]:
    """The scored rows of ``auto_check --json`` outputs (or of auto_rule outputs: their training rows),
    refused unless they scored the same candidates as ``like``."""
    import json

    rows = []
    for path in paths:
        saved = json.loads(Path(path).read_text())
        found = saved.get("rows", saved.get("training"))
        if not found:
            raise SystemExit(f"{path} holds no scored rows (an `auto_check --json` or auto_rule output)")
        rows += found
    names = set(like[0]["results"]) if like else None
    for row in rows:
        if names is not None and set(row["results"]) != names:
            raise SystemExit(f"scored rows of {row['scene']} at {row['lux']:g} lux hold other candidates than the "
                             f"training rows: score them with the same --methods / --candidates")
    return rows


def scenes_matching(rows: list[dict], patterns) -> list[dict]:
    """The rows whose scene name matches one of the shell-style ``patterns`` (``procedural``,
    ``* + *``: the built-in scenes textured with a photograph)."""
    return [r for r in rows if any(fnmatch.fnmatchcase(r["scene"], p) for p in patterns)]


def _dropped(rows: list[dict], patterns: list[str]) -> list[dict]:
    """``rows`` without the scenes ``patterns`` match (:func:`scenes_matching`)."""
    if not patterns:
        return rows
    dropped = {id(r) for r in scenes_matching(rows, patterns)}
    return [r for r in rows if id(r) not in dropped]


def _view_training(specs: list[str]) -> dict:
    """``--view-training VIEW=PATTERN,...`` options -> {view: patterns}."""
    out = {}
    for spec in specs:
        view, _, patterns = spec.partition("=")
        if view not in VIEWS or not patterns.strip():
            raise SystemExit(f"--view-training wants VIEW=PATTERN[,PATTERN...] with a view of {', '.join(VIEWS)}, "
                             f"got {spec!r}")
        out[view] = _paths(patterns)
    return out


def _scored_rows(path: str, args) -> dict:
    """The scored rows of an earlier output, its scoring options and time (``seconds``: the scoring's),
    for fitting again with the fitting options of ``args``."""
    import json

    earlier = json.loads(Path(path).read_text())
    fitting = {"output": args.output, "within": args.within, "low_ratio_views": args.low_ratio_views, "refit": str(path),
               "add_training": args.add_training, "add_held_out": args.add_held_out,
               "drop_training": args.drop_training, "view_training": args.view_training}
    out = {"generator": f"lfcl {__version__} python -m lfcl.bench.auto_rule", "args": {**earlier["args"], **fitting},
           "training": earlier["training"], "seconds": earlier["seconds"]}
    if earlier.get("held_out"):
        out["held_out"] = earlier["held_out"]
    return out


if __name__ == "__main__":
    main()

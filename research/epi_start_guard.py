"""admm-epi's guarded start: fit ONE_COLOUR_WITHIN and ONE_COLOUR_MAJORITY and measure the rules of lfcl/demosaic/guarded_start.py, on
training captures only; report the held-out periodic scene.

The guarded start gives Malvar's start (with their neighbours) to the lenses where linear4d breaks and, with
admm-epi's disparity, to two more kinds of lens: those within W lenses per view step of a one-colour disparity (an
odd one, at an odd pitch: every sample along the epipolar line has the same CFA colour, so the line's other two
colours are the start's) with a confident disparity, and the range-edge ones (a majority of their 3x3 neighbourhood
at an end of the search range, not confident).

    python research/epi_start_guard.py within --lenses 48 --shared ../shared
    python research/epi_start_guard.py rules --lenses 48 --shared ../shared
    python research/epi_start_guard.py majority --lenses 48 --lux 0.5,2,12,50,100 --shared ../shared

``within``: for every training capture (research/fit_auto.py's: charts, deadleaves and finetexture at seeds 1 and 2,
the four training photographs at seed 1) and light level, admm-epi runs as `lfcl process` runs it (the noise from the
DNG profile; the range-edge rule off) at each W (0: no one-colour rule), and the gains over Malvar (centre view, mean
image) are tabulated against W = 0. The W with the best worst change wins (ties: the larger mean centre-view change,
then the smaller W). ``rules``: the same captures with neither rule, the one-colour rule, and both (the shipped
guard), each against neither. ``majority``: the shipped guard with one-colour lenses below CONFIDENT counted where
at least M of their 3x3 neighbourhood are one-colour lenses, for each M (10: none), against none; the M with the best
worst change wins, changes within 0.01 dB of it tie (then the larger mean centre-view change).

Regenerates: lfcl.demosaic.guarded_start.ONE_COLOUR_WITHIN and ONE_COLOUR_MAJORITY (by hand, from the printed
tables; docs/auto.md "Periodic content").
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from fit_auto import training_captures  # the same training captures as auto's rule (research/fit_auto.py)

import lfcl.demosaic.guarded_start as guarded_start
from lfcl.evaluation.evaluate import run_method, simulated_capture

WITHIN = (0.0, 0.05, 0.1, 0.15, 0.2, 0.3)
NO_RANGE_EDGE = 10  # a majority no 3x3 neighbourhood reaches: the range-edge rule off
NO_MAJORITY = 10  # the same for the one-colour lenses: confident ones only
MAJORITY = (NO_MAJORITY, 9, 7, 5)
TIE_DB = 0.01


def gains(capture, malvar: dict, within: float, majority: int, one_colour_majority: int = NO_MAJORITY
          ) -> tuple[float, float]:
    guarded_start.ONE_COLOUR_WITHIN, guarded_start.RANGE_EDGE_MAJORITY = within, majority
    guarded_start.ONE_COLOUR_MAJORITY = one_colour_majority
    result = run_method(capture, "admm-epi")
    return result["psnr_center"] - malvar["psnr_center"], result["psnr_mean"] - malvar["psnr_mean"]


def table(captures, settings: dict, lux_levels) -> dict:
    """{(label, lux): {setting: (centre gain, mean gain)}}, printed as it goes."""
    rows = {}
    for label, source in captures:
        for lux in lux_levels:
            capture = simulated_capture(ARGS.lenses, lux, **source)
            malvar = run_method(capture, "malvar")
            rows[label, lux] = {name: gains(capture, malvar, *setting) for name, setting in settings.items()}
            print(f"{label} {lux:g} lux: " + " | ".join(f"{name}: {c:+.2f}/{m:+.2f}"
                                                     for name, (c, m) in rows[label, lux].items()), flush=True)
    return rows


def summary(rows: dict, names, base) -> dict:
    print(f"\n| setting | worst change against {base} (centre or mean, dB) | mean centre change | mean mean-image change "
          "| cells changed |")
    print("|---|---|---|---|---|")
    out = {}
    for name in names:
        changes = [(cell[name][0] - cell[base][0], cell[name][1] - cell[base][1]) for cell in rows.values()]
        worst = min(min(c) for c in changes)
        centre, mean = float(np.mean([c[0] for c in changes])), float(np.mean([c[1] for c in changes]))
        moved = sum(1 for c in changes if max(abs(c[0]), abs(c[1])) >= 0.005)
        out[name] = (worst, centre)
        print(f"| {name} | {worst:+.2f} | {centre:+.3f} | {mean:+.3f} | {moved} of {len(changes)} |")
    return out


def main(argv=None):
    global ARGS
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=("within", "rules", "majority"))
    parser.add_argument("--lenses", type=int, default=48)
    parser.add_argument("--lux", default="0.5,2,12,50")
    parser.add_argument("--shared", type=Path, default=Path("../shared"))
    ARGS = parser.parse_args(argv)
    shipped = guarded_start.ONE_COLOUR_WITHIN, guarded_start.RANGE_EDGE_MAJORITY, guarded_start.ONE_COLOUR_MAJORITY
    lux_levels = [float(v) for v in ARGS.lux.split(",")]
    if ARGS.part == "within":
        settings = {f"W={w:g}": (w, NO_RANGE_EDGE) for w in WITHIN}
    elif ARGS.part == "majority":
        settings = {f"M={m}": (*shipped[:2], m) for m in MAJORITY}
    else:
        settings = {"neither": (0.0, NO_RANGE_EDGE), "one-colour": (shipped[0], NO_RANGE_EDGE, shipped[2]),
                    "both": shipped}
    rows = table(training_captures(ARGS.shared), settings, lux_levels)
    scores = summary(rows, settings, next(iter(settings)))
    if ARGS.part == "within":
        rounded = {w: (round(scores[f"W={w:g}"][0], 2), round(scores[f"W={w:g}"][1], 3)) for w in WITHIN}
        best = max(WITHIN, key=lambda w: (*rounded[w], -w))  # ties: the larger mean change, the smaller W
        print(f"\nchosen: W = {best:g} (worst change {scores[f'W={best:g}'][0]:+.2f} dB)")
    if ARGS.part == "majority":
        top = max(worst for worst, _ in scores.values())
        tied = [m for m in MAJORITY if scores[f"M={m}"][0] >= top - TIE_DB]
        best = max(tied, key=lambda m: scores[f"M={m}"][1])
        print(f"\nchosen: M = {best} (worst change {scores[f'M={best}'][0]:+.3f} dB)")
    print("\nheld out, periodic seed 7 (gain over Malvar, centre / mean):")
    table([("periodic 7", {"scene": "periodic", "seed": 7})], settings, lux_levels)
    guarded_start.ONE_COLOUR_WITHIN, guarded_start.RANGE_EDGE_MAJORITY, guarded_start.ONE_COLOUR_MAJORITY = shipped


if __name__ == "__main__":
    main()

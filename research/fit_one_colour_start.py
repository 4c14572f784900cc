"""Fit ONE_COLOUR_WITHIN (lfcl/demosaic/guarded_start.py) on training captures only; report the held-out periodic scene.

admm-epi from the guarded start takes Malvar's start also in the lenses whose disparity lies within W lenses per
view step of a one-colour disparity (an odd one, at an odd pitch: every sample along the epipolar line has the same
CFA colour, so the line's other two colours are the start's) with a confidence of at least ONE_COLOUR_CONFIDENCE. For every training capture (research/fit_auto.py's:
charts, deadleaves and finetexture at seeds 1 and 2, the four training photographs at seed 1) and light level,
admm-epi runs as `lfcl process` runs it (the noise from the DNG profile) at each W (0: no such rule), and the gains
over Malvar (centre view, mean image) are tabulated against W = 0. The W with the best worst change wins (ties:
the larger mean centre-view change, then the smaller W). Then the held-out `periodic` scene (seed 7), for the
report only.

    python research/fit_one_colour_start.py --lenses 48 --shared ../shared

Regenerates: lfcl.demosaic.guarded_start.ONE_COLOUR_WITHIN (by hand, from the printed table; docs/auto.md
"Periodic content").
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from fit_auto import training_captures  # the same training captures as auto's rule (research/fit_auto.py)

import lfcl.demosaic.guarded_start as guarded_start
from lfcl.evaluation.evaluate import run_method, simulated_capture

WITHIN = (0.0, 0.05, 0.1, 0.15, 0.2, 0.3)


def gains(capture, within: float, malvar: dict) -> tuple[float, float]:
    guarded_start.ONE_COLOUR_WITHIN = within
    result = run_method(capture, "admm-epi")
    return result["psnr_center"] - malvar["psnr_center"], result["psnr_mean"] - malvar["psnr_mean"]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lenses", type=int, default=48)
    parser.add_argument("--lux", default="0.5,2,12,50")
    parser.add_argument("--shared", type=Path, default=Path("../shared"))
    args = parser.parse_args(argv)
    shipped = guarded_start.ONE_COLOUR_WITHIN
    rows = {}  # (label, lux) -> {W: (centre, mean)}
    for label, source in training_captures(args.shared):
        for lux in (float(v) for v in args.lux.split(",")):
            capture = simulated_capture(args.lenses, lux, **source)
            malvar = run_method(capture, "malvar")
            rows[label, lux] = {w: gains(capture, w, malvar) for w in WITHIN}
            print(f"{label} {lux:g} lux: " + " | ".join(f"{w:g}: {c:+.2f}/{m:+.2f}"
                                                     for w, (c, m) in rows[label, lux].items()), flush=True)
    print("\n| W | worst change (centre, mean; dB against W = 0) | mean centre change | mean mean-image change | cells changed |")
    print("|---|---|---|---|---|")
    summary = {}
    for w in WITHIN:
        changes = [(cell[w][0] - cell[0.0][0], cell[w][1] - cell[0.0][1]) for cell in rows.values()]
        worst = min(min(c) for c in changes)
        centre, mean = float(np.mean([c[0] for c in changes])), float(np.mean([c[1] for c in changes]))
        moved = sum(1 for c in changes if max(abs(c[0]), abs(c[1])) >= 0.005)
        summary[w] = (round(worst, 2), round(centre, 3), -w)  # ties: the larger mean change, then the smaller W
        print(f"| {w:g} | {worst:+.2f} | {centre:+.3f} | {mean:+.3f} | {moved} of {len(changes)} |")
    best = max(WITHIN, key=lambda w: summary[w])
    print(f"\nchosen: W = {best:g} (worst change {summary[best][0]:+.2f} dB)")
    print("\nheld out, periodic seed 7 (gain over Malvar, centre / mean):")
    for lux in (float(v) for v in args.lux.split(",")):
        capture = simulated_capture(args.lenses, lux, seed=7, scene="periodic")
        malvar = run_method(capture, "malvar")
        cells = [(w, gains(capture, w, malvar)) for w in WITHIN]
        print(f"  {lux:g} lux: " + " | ".join(f"W={w:g}: {c:+.2f}/{m:+.2f}" for w, (c, m) in cells), flush=True)
    guarded_start.ONE_COLOUR_WITHIN = shipped


if __name__ == "__main__":
    main()

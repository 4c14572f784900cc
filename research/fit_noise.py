"""Fit and measure the noise estimate from the raw (lfcl/noise/model.py QUANTILE, lfcl/noise/epipolar.py
TOLERANCE and MIN_PAIRS) against the simulator's noise profile (docs/noise.md). Not shipped in the wheel.

    python research/fit_noise.py sweep --seeds 1,2 -o research/fit_noise_train.json     # training captures
    python research/fit_noise.py sweep --seeds 5,6 --real --grid shipped                 # held-out, shipped only
    python research/fit_noise.py sweep --seeds 5,6 --real --grid before     # its "plane": the estimate until now

Each row: the estimated sigma over the profile's (the truth: the simulated DNG carries the noise model
it was made with), for the plane fit alone and for the shipped combination (the lowest of the plane fit, the
epipolar pairs and the epipolar fit; ``method`` says which). The fit keeps the setting with the smallest worst |log ratio| over the training rows.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import time

import numpy as np

# the same captures as admm-epi's fit and table (research/fit_epi.py)
from fit_epi import REAL, add_capture_arguments, capture, parse_capture_arguments

import lfcl.noise.epipolar as epipolar
import lfcl.noise.model as model

GRID = {"quantile": (0.05, 0.02), "tolerance": (0.08, 0.12, 0.2), "min_pairs": (4, 6)}


def sweep(args):
    settings = [dict(zip(GRID, values)) for values in itertools.product(*GRID.values())]
    if args.grid in ("shipped", "before"):  # before: the plane fit's quantile until this fit (its "plane" column)
        settings = [{"quantile": model.QUANTILE if args.grid == "shipped" else 0.2, "tolerance": epipolar.TOLERANCE,
                     "min_pairs": epipolar.MIN_PAIRS}]
    scenes = [(s, seed) for s in args.scenes for seed in args.seeds] + \
        ([(name, args.seeds[0]) for name in REAL] if args.real else [])
    rows = []
    for (scene, seed), lux in itertools.product(scenes, args.lux):
        cap = capture(scene, seed, lux, args.lenses)
        truth = model.from_noise_profile(cap.noise_profile, cap.mosaic).sigma
        for setting in settings:
            model.QUANTILE, epipolar.TOLERANCE, epipolar.MIN_PAIRS = (setting[k] for k in GRID)
            began = time.perf_counter()
            plane = model.estimate_noise(cap.mosaic, cap.pattern, cap.pitch, light_field=False)
            both = model.estimate_noise(cap.mosaic, cap.pattern, cap.pitch)
            row = {"scene": scene, "seed": seed, "lux": lux, **setting, "plane": plane.sigma / truth,
                   "estimate": both.sigma / truth, "method": both.method, "seconds": time.perf_counter() - began}
            print(json.dumps(row), flush=True)
            rows.append(row)
    return rows


def fit(rows):
    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in GRID), []).append(r)
    ranked = sorted(groups.items(), key=lambda kv: max(abs(math.log(r["estimate"])) for r in kv[1]))
    for key, runs in ranked[:8]:
        ratios = [r["estimate"] for r in runs]
        print(dict(zip(GRID, key)), f"worst {max(ratios, key=lambda x: abs(math.log(x))):.2f}, "
              f"range {min(ratios):.2f}..{max(ratios):.2f}, median {np.median(ratios):.2f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=("sweep", "fit"))
    parser.add_argument("inputs", nargs="*", help="fit: sweep JSON files")
    add_capture_arguments(parser)
    parser.add_argument("--real", action="store_true", help="also the light fields antinous and 2067 (held out)")
    parser.add_argument("--grid", choices=("all", "shipped", "before"), default="all")
    parser.add_argument("-o", "--output")
    args = parse_capture_arguments(parser.parse_args())
    if args.mode == "fit":
        rows = []
        for path in args.inputs:
            with open(path) as fh:
                rows += json.load(fh)["rows"]
        fit(rows)
        return
    rows = sweep(args)
    if args.output:
        with open(args.output, "w") as fh:
            json.dump({"args": vars(args), "rows": rows}, fh, indent=1)


if __name__ == "__main__":
    main()

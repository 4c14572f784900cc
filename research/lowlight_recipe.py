"""The `lowlight` recipe's method (lfcl/pipeline/recipe_files/lowlight.toml; docs/auto.md, "admm-epi at low light").

    python research/lowlight_recipe.py [--lux 0.5,1,2,4] [-o lowlight.json]

On the matrix's held-out captures (lfcl.bench.matrix: every built-in scene and the real light fields in ../shared,
48x48 lenses, seed 7) at each light level, with the noise from the DNG's profile and from the raw, runs the recipe's
previous method (admm-uv at strength 2), auto and admm-epi through lfcl.evaluation.evaluate.run_method (as
`lfcl bench matrix` runs methods) and prints each one's centre-view / mean-image gain over Malvar and seconds.
Not shipped in the wheel.
"""

from __future__ import annotations

import argparse
import dataclasses
import json

from lfcl.bench.matrix import HELD_OUT_SEED, captures, parse_lux, real_lightfields
from lfcl.evaluation.evaluate import run_method, simulated_capture, truth_noise
from lfcl.sim import SCENES

VARIANTS = (("admm-uv at strength 2", "admm-uv", {"strength": 2.0}), ("auto", "auto", {}), ("admm-epi", "admm-epi", {}))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lux", default="0.5,1,2,4")
    parser.add_argument("--lenses", type=int, default=48)
    parser.add_argument("--shared", default="../shared")
    parser.add_argument("-o", "--output")
    args = parser.parse_args()
    rows = []
    for label, source in captures(SCENES, real_lightfields(args.shared), args.lenses, HELD_OUT_SEED):
        for lux in parse_lux(args.lux):
            profiled = simulated_capture(args.lenses, lux, **source)
            malvar = run_method(profiled, "malvar")
            own = truth_noise(profiled)
            for noise in ("profile", "raw"):
                capture = profiled if noise == "profile" else dataclasses.replace(profiled, noise_profile=None)
                line = f"{label:11s} {lux:4g} lux, noise from the {noise:7s} (truth's own {own:.2f}x):"
                for name, method, options in VARIANTS:
                    result = run_method(capture, method, **options)
                    gains = (result["psnr_center"] - malvar["psnr_center"], result["psnr_mean"] - malvar["psnr_mean"])
                    rows.append({"capture": label, "lux": lux, "noise": noise, "method": name, "centre_gain": gains[0],
                                 "mean_gain": gains[1], "seconds": result["seconds"], "truth_noise": own})
                    line += f" | {name} {gains[0]:+.2f} / {gains[1]:+.2f} dB, {result['seconds']:.1f} s"
                print(line, flush=True)
    if args.output:
        with open(args.output, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()

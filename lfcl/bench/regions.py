"""Measure regions that stop on their own (docs/auto.md): admm-uv on the whole image
against bands of N lens rows, each stopped by its own rule.

    python -m lfcl.bench.regions [--lenses 64] [--rows 16,8,4] [--repeats 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ..evaluate import capture_in_memory
from ..layout import LightFieldShape, planes_to_exchange
from ..methods import demosaic_lightfield
from ..metrics import lightfield_scores
from ..noise import from_noise_profile


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lenses", type=int, default=64)
    parser.add_argument("--scenes", default="charts,deadleaves")
    parser.add_argument("--lux", default="2,12,50")
    parser.add_argument("--rows", default="16,8,4")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    for scene in args.scenes.split(","):
        for lux in (float(v) for v in args.lux.split(",")):
            meta = {"scene": {"kind": "scene", "name": scene}, "lenses": [args.lenses] * 2, "pitch": [9, 9],
                    "pattern": "GRBG", "seed": args.seed}
            cap = capture_in_memory(meta, lux)
            noise = from_noise_profile(cap.noise_profile, cap.mosaic)
            shape = LightFieldShape.from_exchange(cap.truth)
            demosaic_lightfield(cap.mosaic, cap.pattern, cap.pitch, "admm-uv", noise=noise)  # warm-up: builds
            for rows in [None, *(int(r) for r in args.rows.split(","))]:
                times = []
                for _ in range(args.repeats):
                    start = time.perf_counter()
                    result = demosaic_lightfield(cap.mosaic, cap.pattern, cap.pitch, "admm-uv", noise=noise,
                                                 region_rows=rows)
                    times.append(time.perf_counter() - start)
                scores = lightfield_scores(planes_to_exchange(result.planes, shape), cap.truth)
                print(f"{scene:10s} {lux:5g} lux  regions {rows or 'whole':>5}  {np.median(times):.3f} s  "
                      f"PSNR centre {scores['psnr_center']:.2f} mean {scores['psnr_mean']:.2f}  "
                      f"{result.stop_reason}", flush=True)


if __name__ == "__main__":
    main()

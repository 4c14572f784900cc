"""Measure skipping flat lenses (lfcl/demosaic/flat_lenses.py, docs/auto.md): each ADMM method with every
lens solved against the same method leaving the flat lenses out (the default).

    python research/flat.py [--lenses 64,160] [--scenes charts,deadleaves] [--lightfield PATH]
                              [--lux 2,12,50] [--methods admm-uv,admm-uv-xc,admm-uv-xc:linear4d]
                              [--p 0.01] [--repeats 3] [--seed 0] [-o flat.json]

Per capture and method: one untimed warm-up of each setting (program builds; PoCL compiles
every new global size once, the packed grids' sizes too), then ``--repeats`` rounds that run
"solve every lens" and "skip flat lenses" in turn (so that load from other work on the
machine falls on both alike); the figure is the median of the whole ``demosaic_grid``
call (start, flat test, packing, solve, copy back). Rows: seconds of both, their ratio
(> 1: skipping is faster), iterations of both, the share of lenses found flat, the packed
solver's lens rows, and the PSNR change (centre view / mean image, dB; > 0: skipping is better).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from lfcl.bench.timing import add_capture_arguments, captures
from lfcl.demosaic.driver import demosaic_grid
from lfcl.demosaic.names import parse_method_spec
from lfcl.evaluation.metrics import lightfield_scores
from lfcl.grid.model import AlignedGrid
from lfcl.io.images import write_json
from lfcl.layout import LightFieldShape, planes_to_exchange
from lfcl.noise.model import from_noise_profile


def measure(capture, label: str, repeats: int, threshold: float | None = None) -> dict:
    """Every lens solved against flat lenses skipped, for one method (``METHOD[:START]``)."""
    method, start = parse_method_spec(label)
    noise = from_noise_profile(capture.noise_profile, capture.mosaic)
    shape = LightFieldShape.from_exchange(capture.truth)
    settings = {"solve": False, "skip": threshold if threshold is not None else True}

    def run(skip_flat):
        began = time.perf_counter()
        result = demosaic_grid(capture.mosaic, capture.pattern, AlignedGrid(capture.pitch), method, noise=noise,
                               start=start, skip_flat=skip_flat)
        return time.perf_counter() - began, result

    for skip_flat in settings.values():  # warm-up: program builds, packed sizes
        run(skip_flat)
    times: dict = {name: [] for name in settings}
    results: dict = {}
    for _ in range(repeats):
        for name, skip_flat in settings.items():
            seconds, results[name] = run(skip_flat)
            times[name].append(seconds)
    scores = {name: lightfield_scores(planes_to_exchange(r.planes, shape), capture.truth) for name, r in results.items()}
    flat = results["skip"].parameters["flat_lenses"]
    solve, skip = (float(np.median(times[name])) for name in ("solve", "skip"))
    return {"method": label, "seconds_solve": solve, "seconds_skip": skip, "speedup": solve / skip,
            "times": times, "iterations_solve": results["solve"].iterations,
            "iterations_skip": results["skip"].iterations, "flat_share": flat["share"],
            "solved_lens_rows": flat["solved_lens_rows"], "lens_rows": flat["sensor_lens_rows"],
            **{f"psnr_{view}_{name}": scores[name][f"psnr_{view}"] for name in settings for view in ("center", "mean")},
            "gain_center": scores["skip"]["psnr_center"] - scores["solve"]["psnr_center"],
            "gain_mean": scores["skip"]["psnr_mean"] - scores["solve"]["psnr_mean"]}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_capture_arguments(parser, "admm-uv,admm-uv-xc,admm-uv-xc:linear4d")
    parser.add_argument("--p", type=float, default=None, help="the flat test's p threshold (default: FLAT_P)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("-o", "--output", help="write the rows as JSON")
    args = parser.parse_args(argv)
    rows = []
    for lenses, scene, lux, capture in captures(args):
        for method in args.methods.split(","):
            row = {"lenses": lenses, "scene": scene, "lux": lux, **measure(capture, method, args.repeats, args.p)}
            rows.append(row)
            print(f"{lenses:4d} {scene[-12:]:12s} {lux:5g} lux {method:20s} solve {row['seconds_solve']:6.3f} s "
                  f"skip {row['seconds_skip']:6.3f} s x{row['speedup']:.2f}  it {row['iterations_solve']:2d} -> "
                  f"{row['iterations_skip']:2d}  flat {row['flat_share']:.2f}  rows {row['solved_lens_rows']}"
                  f"/{row['lens_rows']}  PSNR {row['psnr_center_skip']:.2f} / {row['psnr_mean_skip']:.2f} "
                  f"({row['gain_center']:+.2f} / {row['gain_mean']:+.2f})", flush=True)
    if args.output:
        write_json(args.output, rows)


if __name__ == "__main__":
    main()

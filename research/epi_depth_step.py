"""admm-epi's disparity step (lfcl/solvers/epi.py EPI_DEPTH_OPTIONS) on the training captures: the centre-view and
mean-image gains over Malvar and the seconds of admm-epi as ``lfcl process`` runs it, with the disparity searched in
steps of 0.05 (estimate_disparity's default) and 0.1 lens, or any steps, scenes and seeds (docs/admm.md). Not
shipped in the wheel.

    python research/epi_depth_step.py                                   # 0.05 against 0.1, training seeds
    python research/epi_depth_step.py --steps 0.1,0.2                   # 0.1 against 0.2
    python research/epi_depth_step.py --steps 0.1,0.2 --seeds 5,6 --scenes charts,deadleaves,finetexture,antinous,lytro2067
"""

from __future__ import annotations

import argparse

import numpy as np

# the captures and scores of admm-epi's fit (research/fit_epi.py)
from fit_epi import add_capture_arguments, captures_against_malvar, parse_capture_arguments, scores

import lfcl.solvers.epi as epi
from lfcl.demosaic.driver import demosaic_grid
from lfcl.grid.model import AlignedGrid


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", default="0.05,0.1", help="two candidate spacings, the first the reference")
    add_capture_arguments(parser)
    args = parse_capture_arguments(parser.parse_args())
    steps = tuple(float(v) for v in args.steps.split(","))
    rows = {step: [] for step in steps}
    for scene, seed, lux, cap, noise, malvar in captures_against_malvar(args):
        for step in steps:
            epi.EPI_DEPTH_OPTIONS = {**epi.EPI_DEPTH_OPTIONS, "step": step}
            result = demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "admm-epi", noise=noise)
            got = scores(result.planes, cap.truth)
            rows[step].append((got["psnr_center"] - malvar["psnr_center"],
                               got["psnr_mean"] - malvar["psnr_mean"], result.seconds,
                               result.part_seconds["disparity"]))
            print(f"{scene} seed {seed} {lux:g} lux step {step:g}: centre {rows[step][-1][0]:+.3f}, mean image "
                  f"{rows[step][-1][1]:+.3f} dB, {result.iterations} iterations, {result.seconds:.2f} s",
                  flush=True)
    for step, values in rows.items():
        v = np.array(values)
        print(f"step {step:g}: centre gain mean {v[:, 0].mean():+.3f} worst {v[:, 0].min():+.3f} dB, mean image mean "
              f"{v[:, 1].mean():+.3f} worst {v[:, 1].min():+.3f} dB, {v[:, 2].mean():.2f} s (disparity "
              f"{v[:, 3].mean():.3f} s)")
    for column, name in ((0, "centre"), (1, "mean image")):
        diff = np.array(rows[steps[1]])[:, column] - np.array(rows[steps[0]])[:, column]
        print(f"{name}, {steps[1]:g} - {steps[0]:g}: mean {diff.mean():+.3f}, {diff.min():+.3f}..{diff.max():+.3f} dB")


if __name__ == "__main__":
    main()

"""admm-epi's proximal term (lfcl/solvers/epi.py EPI_PROXIMAL) on and off: the centre-view and mean-image gains over
Malvar of admm-epi as ``lfcl process`` runs it, and the largest value it writes against the truth's (docs/admm.md,
"The proximal term"). Not shipped in the wheel.

    python research/epi_proximal.py                                          # training seeds
    python research/epi_proximal.py --seeds 5 --scenes charts,deadleaves,finetexture,antinous,lytro2067 --lux 0.5,2,4,12
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
    parser.add_argument("--values", default="0,0.01", help="EPI_PROXIMAL values, the first the reference")
    add_capture_arguments(parser)
    args = parse_capture_arguments(parser.parse_args())
    values = tuple(float(v) for v in args.values.split(","))
    rows = {value: [] for value in values}
    for scene, seed, lux, cap, noise, malvar in captures_against_malvar(args):
        for value in values:
            epi.EPI_PROXIMAL = value
            result = demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "admm-epi", noise=noise)
            got = scores(result.planes, cap.truth)
            peak = float(np.abs(result.planes).max()) / float(cap.truth.max())
            rows[value].append((got["psnr_center"] - malvar["psnr_center"],
                                got["psnr_mean"] - malvar["psnr_mean"], peak, result.seconds))
            print(f"{scene} seed {seed} {lux:g} lux proximal {value:g}: centre {rows[value][-1][0]:+.3f}, "
                  f"mean image {rows[value][-1][1]:+.3f} dB, largest value {peak:.2f}x the truth's, "
                  f"{result.iterations} iterations, {result.seconds:.2f} s", flush=True)
    for value, v in rows.items():
        v = np.array(v)
        print(f"proximal {value:g}: centre gain mean {v[:, 0].mean():+.3f} worst {v[:, 0].min():+.3f} dB, mean image "
              f"mean {v[:, 1].mean():+.3f} worst {v[:, 1].min():+.3f} dB, largest value {v[:, 2].max():.2f}x the "
              f"truth's, {v[:, 3].mean():.2f} s")
    for column, name in ((0, "centre"), (1, "mean image")):
        diff = np.array(rows[values[1]])[:, column] - np.array(rows[values[0]])[:, column]
        print(f"{name}, {values[1]:g} - {values[0]:g}: mean {diff.mean():+.3f}, {diff.min():+.3f}..{diff.max():+.3f} dB")


if __name__ == "__main__":
    main()

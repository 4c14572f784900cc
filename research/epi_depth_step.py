"""admm-epi's disparity step (lfcl/solvers/epi.py EPI_DEPTH_OPTIONS) on the training captures: the centre-view and
mean-image gains over Malvar and the seconds of admm-epi as ``lfcl process`` runs it, with the disparity searched in
steps of 0.05 (estimate_disparity's default) and 0.1 lens (docs/admm.md). Not shipped in the wheel.

    python research/epi_depth_step.py
"""

from __future__ import annotations

import numpy as np
from fit_epi import capture, noise_of, scores  # the captures and scores of admm-epi's fit (research/fit_epi.py)

import lfcl.solvers.epi as epi
from lfcl.demosaic.driver import demosaic_grid
from lfcl.grid.model import AlignedGrid

STEPS = (0.05, 0.1)


def main():
    rows = {step: [] for step in STEPS}
    for scene in ("charts", "deadleaves", "finetexture"):
        for seed in (1, 2):
            for lux in (0.5, 2, 12, 50):
                cap = capture(scene, seed, lux, 48)
                noise = noise_of(cap)
                malvar = scores(demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "malvar").planes,
                                cap.truth)
                for step in STEPS:
                    epi.EPI_DEPTH_OPTIONS = {**epi.EPI_DEPTH_OPTIONS, "step": step}
                    result = demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "admm-epi", noise=noise)
                    got = scores(result.planes, cap.truth)
                    rows[step].append((got["psnr_center"] - malvar["psnr_center"],
                                       got["psnr_mean"] - malvar["psnr_mean"], result.seconds,
                                       result.part_seconds["disparity"]))
    for step, values in rows.items():
        v = np.array(values)
        print(f"step {step:g}: centre gain mean {v[:, 0].mean():+.3f} worst {v[:, 0].min():+.3f} dB, mean image mean "
              f"{v[:, 1].mean():+.3f} worst {v[:, 1].min():+.3f} dB, {v[:, 2].mean():.2f} s (disparity "
              f"{v[:, 3].mean():.3f} s)")
    diff = np.array(rows[STEPS[1]])[:, 0] - np.array(rows[STEPS[0]])[:, 0]
    print(f"centre, {STEPS[1]:g} - {STEPS[0]:g}: mean {diff.mean():+.3f}, {diff.min():+.3f}..{diff.max():+.3f} dB")


if __name__ == "__main__":
    main()

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

# the captures and the comparison of admm-epi's fit (research/fit_epi.py)
from fit_epi import add_capture_arguments, compare_settings, parse_capture_arguments

import lfcl.solvers.epi as epi


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", default="0.05,0.1", help="candidate spacings, the first the reference")
    add_capture_arguments(parser)
    args = parse_capture_arguments(parser.parse_args())
    shipped = dict(epi.EPI_DEPTH_OPTIONS)

    def apply(step):
        epi.EPI_DEPTH_OPTIONS = {**shipped, "step": step}

    compare_settings(args, "step", tuple(float(v) for v in args.steps.split(",")), apply)


if __name__ == "__main__":
    main()

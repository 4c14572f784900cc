"""admm-epi's proximal term (lfcl/solvers/epi.py EPI_PROXIMAL) on and off: the centre-view and mean-image gains over
Malvar of admm-epi as ``lfcl process`` runs it, and the largest value it writes against the truth's (docs/admm.md,
"The proximal term"). Not shipped in the wheel.

    python research/epi_proximal.py                                          # training seeds
    python research/epi_proximal.py --seeds 5 --scenes charts,deadleaves,finetexture,antinous,lytro2067 --lux 0.5,2,4,12
"""

from __future__ import annotations

import argparse

# the captures and the comparison of admm-epi's fit (research/fit_epi.py)
from fit_epi import add_capture_arguments, compare_settings, parse_capture_arguments

import lfcl.solvers.epi as epi


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--values", default="0,0.01", help="EPI_PROXIMAL values, the first the reference")
    add_capture_arguments(parser)
    args = parse_capture_arguments(parser.parse_args())

    def apply(value):
        epi.EPI_PROXIMAL = value

    compare_settings(args, "proximal", tuple(float(v) for v in args.values.split(",")), apply)


if __name__ == "__main__":
    main()

"""admm-epi's CG steps per x-update (lfcl/demosaic/methods.py ADMM_DEFAULTS["admm-epi"].cg_steps): the centre-view
and mean-image gains over Malvar of admm-epi as ``lfcl process`` runs it, with each count (docs/admm.md, "The
preconditioner"). Not shipped in the wheel.

    python research/epi_cg_steps.py --values 5,4                              # training seeds
    python research/epi_cg_steps.py --values 5,4 --seeds 5 --scenes charts,deadleaves,finetexture,antinous,lytro2067 --lux 0.5,2,4,12,50

One value (``--values 5``) run from two source trees (PYTHONPATH) compares two preconditioners.
"""

from __future__ import annotations

import argparse
import dataclasses

# the captures and the comparison of admm-epi's fit (research/fit_epi.py)
from fit_epi import add_capture_arguments, compare_settings, parse_capture_arguments

import lfcl.demosaic.methods as methods


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--values", default="5,4", help="CG steps, the first the reference")
    add_capture_arguments(parser)
    args = parse_capture_arguments(parser.parse_args())
    shipped = methods.ADMM_DEFAULTS["admm-epi"]

    def apply(value):
        methods.ADMM_DEFAULTS["admm-epi"] = dataclasses.replace(shipped, cg_steps=int(value))

    compare_settings(args, "cg_steps", tuple(int(v) for v in args.values.split(",")), apply)


if __name__ == "__main__":
    main()

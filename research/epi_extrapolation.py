"""admm-epi's extrapolated warm start (lfcl/solvers/epi.py EpiSetting.cg_steps and .extrapolation): the centre-view and
mean-image gains over Malvar of admm-epi as ``lfcl process`` runs it, with every row's x-update as before (5 CG steps
from x_k) against the shipped schedule, or against one setting on every row (docs/admm.md, "The extrapolated warm
start"). Not shipped in the wheel.

    python research/epi_extrapolation.py                                           # training seeds, the shipped rows
    python research/epi_extrapolation.py --setting 3:0.8 --lux 0.5,2,12,50         # 3 CG steps, beta 0.8, every row
    python research/epi_extrapolation.py --seeds 5 --scenes charts,deadleaves,finetexture,antinous,lytro2067 --lux 0.5,2,4,12,50

Value 0 is the x-update before (5 CG steps from x_k on every row), 1 the shipped rows or ``--setting STEPS:BETA``
on every row; ``iterations x (steps + 1)`` counts the gathers' pairs (D and D^T) of a run.
"""

from __future__ import annotations

import argparse
import dataclasses

# the captures and the comparison of admm-epi's fit (research/fit_epi.py)
from fit_epi import add_capture_arguments, compare_settings, parse_capture_arguments

import lfcl.solvers.epi as epi


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--setting", default=None, help="STEPS:BETA on every row instead of the shipped rows")
    add_capture_arguments(parser)
    args = parse_capture_arguments(parser.parse_args())
    shipped = epi.EPI_SCHEDULE
    before = tuple(dataclasses.replace(row, cg_steps=5, extrapolation=0.0) for row in shipped)
    after = shipped
    if args.setting:
        steps, beta = args.setting.split(":")
        after = tuple(dataclasses.replace(row, cg_steps=int(steps), extrapolation=float(beta)) for row in shipped)

    def apply(value):
        epi.EPI_SCHEDULE = after if value else before

    rows = compare_settings(args, "x-update", (0, 1), apply)
    for value, runs in rows.items():
        print(f"x-update {value}: {sum(run[5] for run in runs)} iterations, "
              f"{sum(run[5] * (run[6] + 1) for run in runs)} pairs of gathers")


if __name__ == "__main__":
    main()

"""admm-uv-xc's lam and lam_xc per sigma as `lfcl process` runs it: fit on the training captures, lens-scale gratings
among them (docs/admm.md, "The cross-channel prior"; docs/auto.md, "Lens-scale gratings").

For every training capture (research/fit_auto.py's with its stress families: charts, deadleaves, finetexture and
gratings at seeds 1 and 2, the four training photographs)
at each light level, admm-uv-xc runs through lfcl.evaluation.evaluate.run_method (the Malvar start, its stop rule,
the safety net) with lam = c sigma and lam_xc = e sigma for every (c, e) of the grid, against Malvar: PSNR gains
(centre view, mean image) and mean CIEDE2000 changes (centre view, mean image). A pair is *eligible* when on every
capture both gains are at least -``TOLERANCE_DB`` and neither CIEDE2000 rises by more than ``TOLERANCE_DE``
(never worse than Malvar, to the precision the safety net leaves); eligible pairs rank by their worst centre-view
gain, then by the mean one.

    python research/fit_uv_xc.py --lam-factors 0.1,0.12,0.15,0.2 --xc-factors 0.03,0.06,0.075,0.09,0.12 \\
        --shared ../shared -o research/fit_uv_xc_48.json

Regenerates: the ``admm-uv-xc`` entry of lfcl.demosaic.methods.ADMM_DEFAULTS (lam_per_sigma, xc_per_sigma; by hand,
from the printed table).
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
from pathlib import Path

import numpy as np
from fit_auto import training_captures  # auto's training captures (research/fit_auto.py), with its stress families

import lfcl.demosaic.methods as methods
from lfcl.evaluation.evaluate import run_method, simulated_capture

TOLERANCE_DB = 0.05
TOLERANCE_DE = 0.05
KEYS = ("psnr_center", "psnr_mean", "de2000_mean_center", "de2000_mean_mean")


def changes(result: dict, malvar: dict) -> list[float]:
    """PSNR gains (centre, mean image) and CIEDE2000 changes (centre, mean image) against Malvar's."""
    return [result[k] - malvar[k] for k in KEYS]


def summary(rows: list[dict], pairs) -> list[dict]:
    table = []
    for pair in pairs:
        a = np.array([row["changes"][pair] for row in rows])
        table.append({"pair": pair, "worst_gain": float(a[:, :2].min()), "worst_centre": float(a[:, 0].min()),
                      "mean_centre": float(a[:, 0].mean()), "median_centre": float(np.median(a[:, 0])),
                      "worst_de": float(a[:, 2:].max()),
                      "eligible": bool(a[:, :2].min() >= -TOLERANCE_DB and a[:, 2:].max() <= TOLERANCE_DE)})
    return table


def chosen(table: list[dict]) -> dict | None:
    """The eligible pair of the best worst centre-view gain (to 0.01 dB), then the best mean one; None: none is."""
    eligible = [t for t in table if t["eligible"]]
    return max(eligible, key=lambda t: (round(t["worst_centre"], 2), t["mean_centre"])) if eligible else None


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lam-factors", default="0.1,0.12,0.15,0.2")
    parser.add_argument("--xc-factors", default="0.03,0.06,0.075,0.09,0.12")
    parser.add_argument("--lux", default="0.5,2,12,25,50")
    parser.add_argument("--lenses", type=int, default=48)
    parser.add_argument("--shared", type=Path, default=Path("../shared"))
    parser.add_argument("-o", "--output", type=Path)
    args = parser.parse_args(argv)
    grid = list(itertools.product((float(v) for v in args.lam_factors.split(",")),
                                  (float(v) for v in args.xc_factors.split(","))))
    pairs = [f"{c:g},{e:g}" for c, e in grid]
    shipped = methods.ADMM_DEFAULTS["admm-uv-xc"]
    rows = []
    try:
        for label, source in training_captures(args.shared, stress=True):
            for lux in (float(v) for v in args.lux.split(",")):
                capture = simulated_capture(args.lenses, lux, **source)
                malvar = run_method(capture, "malvar")
                row = {"capture": label, "lux": lux, "changes": {}}
                for (c, e), pair in zip(grid, pairs):
                    methods.ADMM_DEFAULTS["admm-uv-xc"] = dataclasses.replace(shipped, lam_per_sigma=c, xc_per_sigma=e)
                    row["changes"][pair] = changes(run_method(capture, "admm-uv-xc"), malvar)
                methods.ADMM_DEFAULTS["admm-uv-xc"] = shipped
                rows.append(row)
                print(f"{label} {lux:g} lux: " + " | ".join(f"{p} {v[0]:+.2f}/{v[1]:+.2f}"
                                                         for p, v in row["changes"].items()), flush=True)
    finally:
        methods.ADMM_DEFAULTS["admm-uv-xc"] = shipped
    table = summary(rows, pairs)
    print("\n| lam / sigma, lam_xc / sigma | worst gain (centre or mean, dB) | worst centre | mean centre | median centre "
          "| worst CIEDE2000 change | eligible |")
    print("|---|---|---|---|---|---|---|")
    for t in table:
        print(f"| {t['pair']} | {t['worst_gain']:+.2f} | {t['worst_centre']:+.2f} | {t['mean_centre']:+.2f} | "
              f"{t['median_centre']:+.2f} | {t['worst_de']:+.2f} | {'yes' if t['eligible'] else 'no'} |")
    best = chosen(table)
    if best is not None:
        print(f"\nchosen: {best['pair']} (worst centre gain {best['worst_centre']:+.2f} dB)")
    if args.output:
        args.output.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows,
                                           "table": table}, indent=1))


if __name__ == "__main__":
    main()

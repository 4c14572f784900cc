"""Fit the rule behind ``--method auto`` (lfcl/auto.py) on training captures.

For each training scene, seed and illumination, simulate a capture, read its noise
level sigma the way ``lfcl process`` does (the DNG NoiseProfile), run every
candidate (a method and a lambda strength) and score it against the ground truth.
Then, for each band of sigma (four per decade), pick the *cheapest* candidate
whose worst loss against the best fixed method (every method at its default
strength; PSNR of the centre view and of the mean image) is within ``--within``
dB of the smallest such loss (``fit_rule``).

The training seeds (default 1, 2) are not the evaluation seed 0 of docs/admm.md.

    python -m lfcl.bench.auto_rule -o lfcl/data/auto_rule.json
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from .. import __version__
from ..evaluate import capture_in_memory, run_method

DEFAULT_CANDIDATES = "malvar,admm-uv@0.5,admm-uv@1,admm-uv@2,admm-uv@4,admm-uvst@1"
#: Band edges in log10(sigma): four bands per decade.
BANDS_PER_DECADE = 4


def parse_candidates(spec: str) -> list[tuple[str, float]]:
    """'method[@strength],...' -> [(method, strength)]."""
    out = []
    for item in spec.split(","):
        method, _, strength = item.strip().partition("@")
        out.append((method, float(strength) if strength else 1.0))
    return out


def candidate_name(method: str, strength: float) -> str:
    return method if method == "malvar" or method == "linear4d" else f"{method}@{strength:g}"


def score_captures(scenes, seeds, lux_levels, lenses, candidates, log=print) -> list[dict]:
    """Every candidate on every training capture: sigma, PSNRs and seconds."""
    rows = []
    for scene in scenes:
        for seed in seeds:
            for lux in lux_levels:
                meta = {"scene": {"kind": "scene", "name": scene}, "lenses": list(lenses), "pitch": [9, 9],
                        "pattern": "GRBG", "seed": seed}
                capture = capture_in_memory(meta, lux)
                row = {"scene": scene, "seed": seed, "lux": lux, "results": {}}
                for method, strength in candidates:
                    overrides = {} if method in ("malvar", "linear4d") else {"strength": strength}
                    result = run_method(capture, method, **overrides)
                    if result["noise_sigma"] is not None:
                        row["sigma"] = result["noise_sigma"]
                    row["results"][candidate_name(method, strength)] = {
                        k: result[k] for k in ("psnr_center", "psnr_mean", "seconds", "iterations")}
                log(f"{scene:10s} seed {seed} {lux:6g} lux sigma {row.get('sigma', float('nan')):.5f}  " + "  ".join(
                    f"{name} {r['psnr_center']:.2f}/{r['psnr_mean']:.2f}" for name, r in row["results"].items()))
                rows.append(row)
    return rows


def band_of(sigma: float) -> int:
    return math.floor(math.log10(max(sigma, 1e-12)) * BANDS_PER_DECADE)


def is_fixed(name: str) -> bool:
    """A method at its default strength: the peers auto is measured against."""
    return "@" not in name or name.endswith("@1")


def fit_rule(rows: list[dict], within: float) -> list[dict]:
    """One entry per sigma band that has training captures: the chosen candidate and why.

    A candidate's loss on a capture is how far its PSNR (centre view or mean image,
    whichever is worse) falls below the best fixed method's (every method at its
    default strength); its band loss is the worst over the band's captures. The
    chosen candidate is the cheapest (median seconds) whose band loss is within
    ``within`` dB of the smallest band loss.
    """
    names = list(rows[0]["results"])
    fixed = [n for n in names if is_fixed(n)]
    seconds = {n: float(np.median([r["results"][n]["seconds"] for r in rows])) for n in names}
    bands: dict[int, list[dict]] = {}
    for r in rows:
        bands.setdefault(band_of(r["sigma"]), []).append(r)
    rule = []
    for band in sorted(bands):
        members = bands[band]

        def band_loss(name, members=members):
            return max(max(r["results"][n][key] for n in fixed) - r["results"][name][key]
                       for r in members for key in ("psnr_center", "psnr_mean"))

        losses = {n: band_loss(n) for n in names}
        smallest = min(losses.values())
        chosen = min((n for n in names if losses[n] <= smallest + within), key=lambda n: seconds[n])
        rule.append({
            "sigma_from": 10 ** (band / BANDS_PER_DECADE), "sigma_to": 10 ** ((band + 1) / BANDS_PER_DECADE),
            "candidate": chosen, "worst_loss_db": losses[chosen], "within_db": within, "captures": len(members),
            "losses_db": losses, "median_seconds": {n: seconds[n] for n in names},
        })
    return rule


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--output", required=True)
    parser.add_argument("--scenes", default="charts,deadleaves")
    parser.add_argument("--seeds", default="1,2")
    parser.add_argument("--lux", default="0.25,0.5,1,2,4,8,12,25,50,100,200")
    parser.add_argument("--lenses", default="64x64")
    parser.add_argument("--candidates", default=DEFAULT_CANDIDATES)
    parser.add_argument("--within", type=float, default=0.1, help="dB a cheaper candidate may lose")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    rows = score_captures(args.scenes.split(","), [int(s) for s in args.seeds.split(",")],
                          [float(v) for v in args.lux.split(",")], [int(n) for n in args.lenses.split("x")],
                          parse_candidates(args.candidates))
    rule = fit_rule(rows, args.within)
    out = {"generator": f"lfcl {__version__} python -m lfcl.bench.auto_rule", "args": vars(args),
           "seconds": time.perf_counter() - start, "rule": rule, "training": rows}
    from ..imageio import write_json

    write_json(args.output, out)
    for band in rule:
        print(f"sigma {band['sigma_from']:.4g}-{band['sigma_to']:.4g}: {band['candidate']} "
              f"(worst loss {band['worst_loss_db']:.2f} dB over {band['captures']} captures)")


if __name__ == "__main__":
    main()

"""admm-epi's disparity with and without the half-aperture occlusion curves (lfcl/solvers/epi.py
EPI_DEPTH_OPTIONS, lfcl.depth.estimate_disparity's ``occlusion``): the centre-view and mean-image gains over
Malvar and the seconds of admm-epi as ``lfcl process`` runs it (docs/admm.md, "admm-epi"). Not shipped in the wheel.

    python research/epi_occlusion.py --scenes charts,deadleaves,finetexture --seeds 1,2 -o train_std.json
    python research/epi_occlusion.py --scenes procedural-1000..1011 --seeds 1 -o train_procedural.json
    python research/epi_occlusion.py --scenes charts,deadleaves,finetexture,antinous,lytro2067 --seeds 5 -o held.json
    python research/epi_occlusion.py --scenes procedural-3000..3011 --seeds 5 -o held_procedural.json
    python research/epi_occlusion.py --summary train_std.json train_procedural.json held.json held_procedural.json

(``procedural-A..B``: research/training_scenes.py's scenes A to B.)
"""

from __future__ import annotations

import argparse
import itertools
import json

import numpy as np
from fit_epi import capture, noise_of, scores  # the captures and scores of admm-epi's fit (research/fit_epi.py)

import lfcl.solvers.epi as epi
from lfcl.demosaic.driver import demosaic_grid
from lfcl.grid.model import AlignedGrid

VARIANTS = {"off": False, "on": True}


def scene_list(text: str) -> list[str]:
    out = []
    for item in text.split(","):
        if item.startswith("procedural-") and ".." in item:
            lo, hi = item[len("procedural-"):].split("..")
            out += [f"procedural-{n}" for n in range(int(lo), int(hi) + 1)]
        else:
            out.append(item)
    return out


def run(args) -> list[dict]:
    shipped = dict(epi.EPI_DEPTH_OPTIONS)
    rows = []
    for scene, seed, lux in itertools.product(scene_list(args.scenes), args.seeds, args.lux):
        cap = capture(scene, seed, lux, args.lenses)
        noise = noise_of(cap)
        malvar = scores(demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "malvar").planes, cap.truth)
        row = {"scene": scene, "seed": seed, "lux": lux, "malvar": [malvar["psnr_center"], malvar["psnr_mean"]]}
        for name, occlusion in VARIANTS.items():
            epi.EPI_DEPTH_OPTIONS = {**shipped, "occlusion": occlusion}
            result = demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "admm-epi", noise=noise)
            got = scores(result.planes, cap.truth)
            row[name] = [got["psnr_center"], got["psnr_mean"], result.seconds,
                         result.part_seconds["disparity"]]
        epi.EPI_DEPTH_OPTIONS = shipped
        rows.append(row)
        print(scene, seed, lux, "  ".join(
            f"{name}: {row[name][0] - row['malvar'][0]:+.2f} / {row[name][1] - row['malvar'][1]:+.2f} dB "
            f"({row[name][2]:.2f} s, disparity {row[name][3]:.2f} s)" for name in VARIANTS), flush=True)
    return rows


def summary(paths):
    for path in paths:
        with open(path) as fh:
            rows = json.load(fh)
        centre = np.array([r["on"][0] - r["off"][0] for r in rows])
        mean = np.array([r["on"][1] - r["off"][1] for r in rows])
        fair = [r for r in rows if not r["scene"].startswith("lytro")]  # its truth is noisier than the sensor

        def worst(name):
            return min(min(r[name][0] - r["malvar"][0], r[name][1] - r["malvar"][1]) for r in fair)

        ratio = np.median([r["on"][2] / r["off"][2] for r in rows])
        print(f"{path}: {len(rows)} captures; on - off: centre {centre.mean():+.3f} dB mean ({centre.min():+.2f}.."
              f"{centre.max():+.2f}), mean image {mean.mean():+.3f} ({mean.min():+.2f}..{mean.max():+.2f}); worst "
              f"gain over Malvar (either view, Lytro left out) off {worst('off'):+.2f}, on {worst('on'):+.2f}; "
              f"admm-epi's time on / off, median {ratio:.2f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="charts,deadleaves,finetexture")
    parser.add_argument("--seeds", type=lambda s: [int(x) for x in s.split(",")], default=[1, 2])
    parser.add_argument("--lux", type=lambda s: [float(x) for x in s.split(",")], default=[0.5, 2, 12, 50])
    parser.add_argument("--lenses", type=int, default=48)
    parser.add_argument("-o", "--output")
    parser.add_argument("--summary", nargs="+", help="summarise earlier outputs instead")
    args = parser.parse_args()
    if args.summary:
        summary(args.summary)
        return
    rows = run(args)
    if args.output:
        with open(args.output, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()

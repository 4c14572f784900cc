"""Measure lfcl.depth.estimate_disparity with the HCI metrics (docs/depth.md has the table and commands).

Scenes: ``antinous`` (the HCI light field in ../shared, a centre crop of --lenses, simulated into a
lenslet raw by lfcl.sim), ``planes`` (two textured fronto-parallel planes of known disparity
over a background, rendered by lfcl.sim.planes) and the built-in scenes (charts, deadleaves, finetexture:
the truth is the disparity of the frontmost plane at each lens, lfcl.sim's ``disparity``). Noise model: the sensor's (what a DNG
NoiseProfile gives the pipeline). Not shipped in the wheel.

    .devvenv/bin/python research/depth_eval.py --scene antinous --lenses 128 --lux 0.5,2,12,50
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from lfcl.depth import depth_scores, estimate_disparity, read_pfm
from lfcl.noise.model import from_noise_profile
from lfcl.sim.capture import simulate
from lfcl.sim.planes import Plane
from lfcl.sim.scenes import SCENES

ROOT = Path(__file__).resolve().parents[1]
ANTINOUS = ROOT.parent / "shared" / "realdata" / "hci_epinet" / "antinous"


def planes_scene(S: int, T: int, seed: int = 0):
    """Dead-leaves planes: a rectangle at d = +0.85, a disc at +0.3 over a background at -0.6."""
    from lfcl.sim.deadleaves import DeadLeavesTexture, _texture_box

    specs = [("rect", 0.85, (0.15 * S, 0.1 * T, 0.55 * S, 0.5 * T), "rect"),
             ("disc", 0.3, (0.45 * S, 0.45 * T, 0.9 * S, 0.9 * T), "disc"),
             ("background", -0.6, None, "rect")]
    streams = np.random.SeedSequence([int(seed), 0xD15]).spawn(len(specs))
    planes = []
    for (name, d, rect, shape), stream in zip(specs, streams):
        size = min(S, T) if rect is None else min(rect[2] - rect[0], rect[3] - rect[1])
        texture = DeadLeavesTexture(_texture_box(rect, d, S, T), np.random.default_rng(stream), r_max=size / 4.0)
        planes.append(Plane(name, d, texture, rect, shape))
    return planes


def truth_of_planes(planes, S: int, T: int) -> np.ndarray:
    """Disparity of the frontmost plane at each centre-view lens centre."""
    y, x = np.mgrid[0:S, 0:T] + 0.5
    out = np.full((S, T), np.nan)
    for plane in planes:
        hit = np.isnan(out) & plane.covers(x, y)
        out[hit] = plane.disparity
    return out


def capture(scene: str, lenses: int, lux: float, seed: int):
    if scene == "antinous":
        gt = read_pfm(ANTINOUS / "gt_disp_lowres.pfm")
        s0 = (gt.shape[0] - lenses) // 2
        t0 = (gt.shape[1] - lenses) // 2
        cap = simulate(lightfield=ANTINOUS, lenses=(lenses, lenses), lux=lux, seed=seed)
        return cap, gt[s0:s0 + lenses, t0:t0 + lenses]
    if scene == "planes":
        planes = planes_scene(lenses, lenses, seed)
        cap = simulate(planes=planes, lenses=(lenses, lenses), pitch=9, lux=lux, seed=seed)
        return cap, truth_of_planes(planes, lenses, lenses)
    if scene in SCENES:  # a built-in scene: the disparity of its frontmost plane at each lens is the truth
        cap = simulate(scene, lenses=(lenses, lenses), pitch=9, lux=lux, seed=seed)
        return cap, cap.disparity.astype(np.float64)
    raise SystemExit(f"unknown scene {scene}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="antinous", choices=["antinous", "planes", *SCENES])
    ap.add_argument("--lenses", type=int, default=128)
    ap.add_argument("--lux", default="0.5,2,12,50")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--options", default="{}", help="JSON dict of estimate_disparity options")
    ap.add_argument("--confident", type=float, default=0.5, help="also score lenses of confidence >= this")
    args = ap.parse_args(argv)
    options = json.loads(args.options)
    print(f"scene {args.scene}, {args.lenses}x{args.lenses} lenses, seed {args.seed}, options {options}")
    print(f"| lux | BadPix(0.07) % | BadPix(0.1) % | MSE x100 | seconds | conf>={args.confident:.2f} share "
          "| its BadPix(0.1) |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for lux in (float(v) for v in args.lux.split(",")):
        cap, gt = capture(args.scene, args.lenses, lux, args.seed)
        raw = cap.normalised_raw()
        noise = from_noise_profile(cap.sensor.noise_profile(), raw)
        start = time.perf_counter()
        depth = estimate_disparity(raw, cap.pattern, cap.geometry.pitch, noise=noise, **options)
        seconds = time.perf_counter() - start
        scores = depth_scores(depth.disparity, gt)
        sure = depth.confidence >= args.confident
        sure_bp = depth_scores(depth.disparity, gt, sure)["badpix_0.1"] if sure.any() else float("nan")
        rows.append({"lux": lux, **scores, "seconds": seconds, "confident_share": float(sure.mean()),
                     "confident_badpix_0.1": sure_bp})
        print(f"| {lux:g} | {scores['badpix_0.07']:.1f} | {scores['badpix_0.1']:.1f} | {scores['mse_x100']:.2f} | "
              f"{seconds:.1f} | {100 * sure.mean():.0f} % | {sure_bp:.1f} |", flush=True)
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() else 1)

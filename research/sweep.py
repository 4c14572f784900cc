"""The parameter sweep behind the ADMM defaults (docs/admm.md).

For each scene, illumination and ADMM method, run the solver from the Malvar
start with lambda = c * sigma for a grid of c, and record PSNR (centre view and
mean image) and rms(x_k - x_{k-1}) after every iteration. From those curves we
read how PSNR moves with lambda and with the iteration count, and score stopping
rules "stop when rms change <= d * sigma" against the best iterate that ground
truth would pick.

    python research/sweep.py -o sweep.json [--lenses 64x64] [--lux 1,4,12,50]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from lfcl.demosaic.methods import ADMM_DEFAULTS
from lfcl.device import get_runtime
from lfcl.evaluation.evaluate import capture_in_memory
from lfcl.evaluation.metrics import lightfield_scores
from lfcl.layout import LightFieldShape, planes_to_exchange
from lfcl.noise.model import from_noise_profile
from lfcl.ops.malvar import Malvar
from lfcl.solvers.admm import AdmmSolver
from lfcl.solvers.params import AdmmParams


def sweep_capture(capture, method: str, lam_factors, max_iter: int, runtime, rho: float | None = None) -> dict:
    """PSNR/rms-change curves of ``method`` on one capture for each lambda factor."""
    defaults = ADMM_DEFAULTS[method]
    sigma = from_noise_profile(capture.noise_profile, capture.mosaic).sigma
    shape = LightFieldShape.from_exchange(capture.truth)
    b = runtime.to_device(capture.mosaic)
    x0 = Malvar(runtime, capture.mosaic.shape, capture.pattern).forward(b)
    start = planes_to_exchange(x0.get(), shape)
    solver = AdmmSolver(runtime, capture.mosaic.shape, capture.pattern, capture.pitch, defaults.dims)
    curves = {}
    for factor in lam_factors:
        psnr_c, psnr_m, change = [], [], []

        def record(rec, x):
            scores = lightfield_scores(planes_to_exchange(x.get(), shape), capture.truth)
            psnr_c.append(scores["psnr_center"])
            psnr_m.append(scores["psnr_mean"])
            change.append(rec.rms_change)

        params = AdmmParams(lam=factor * sigma, rho=rho or defaults.rho, max_iter=max_iter, cg_steps=defaults.cg_steps)
        solver.solve(b, x0, params, callback=record)
        curves[f"{factor:g}"] = {"psnr_center": psnr_c, "psnr_mean": psnr_m, "rms_change": change}
    return {"sigma": sigma, "rho": rho or defaults.rho, "malvar": lightfield_scores(start, capture.truth),
            "curves": curves}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--output", required=True)
    parser.add_argument("--scenes", default="charts,deadleaves")
    parser.add_argument("--lux", default="1,4,12,50")
    parser.add_argument("--lenses", default="64x64")
    parser.add_argument("--methods", default="admm-uv,admm-st,admm-uvst")
    parser.add_argument("--lam-factors", default="0.01,0.03,0.1,0.3,1,3")
    parser.add_argument("--max-iter", type=int, default=60)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rhos", default="", help="rho values to try (default: each method's default)")
    args = parser.parse_args(argv)
    runtime = get_runtime()
    lenses = [int(n) for n in args.lenses.split("x")]
    factors = [float(f) for f in args.lam_factors.split(",")]
    results = []
    for scene in args.scenes.split(","):
        for lux in (float(v) for v in args.lux.split(",")):
            meta = {"scene": {"kind": "scene", "name": scene}, "lenses": lenses, "pitch": [9, 9],
                    "pattern": "GRBG", "seed": args.seed}
            capture = capture_in_memory(meta, lux)
            runs = [(m, float(r) if r else None) for m in args.methods.split(",") for r in args.rhos.split(",")]
            for method, rho in runs:
                start = time.perf_counter()
                entry = sweep_capture(capture, method, factors, args.max_iter, runtime, rho)
                entry.update(scene=scene, lux=lux, method=method, seconds=time.perf_counter() - start)
                results.append(entry)
                best = max((max(c["psnr_center"]), f) for f, c in entry["curves"].items())
                print(f"{scene:10s} {lux:5g} lux {method:10s} rho {entry['rho']:g} sigma {entry['sigma']:.4f} "
                      f"malvar {entry['malvar']['psnr_center']:.2f} best centre {best[0]:.2f} at c={best[1]} "
                      f"({entry['seconds']:.0f} s)", flush=True)
                with open(args.output, "w") as f:
                    json.dump({"args": vars(args), "results": results}, f)


if __name__ == "__main__":
    main()


def rule_outcome(curves: dict, factor: str, change_per_sigma: float, max_iter: int, sigma: float):
    """(PSNR centre, PSNR mean, iterations) of "lam = factor*sigma, stop at rms change <= d*sigma".

    d = 0 means: run exactly ``max_iter`` iterations.
    """
    curve = curves[factor]
    last = min(max_iter, len(curve["psnr_center"]))
    k = last
    if change_per_sigma > 0:
        for i in range(1, last):  # the first iteration never moves x (see params.stop_reason)
            if curve["rms_change"][i] <= change_per_sigma * sigma:
                k = i + 1
                break
    return curve["psnr_center"][k - 1], curve["psnr_mean"][k - 1], k


def summarise(results: list[dict], method: str, rho: float | None = None, change_grid=(0.05, 0.1, 0.13, 0.2, 0.3, 0.5),
              iteration_grid=(5, 10, 15, 20, 30, 45, 60)) -> list[dict]:
    """Score every candidate rule over all (scene, lux) of ``method``; best rules first.

    A rule's score is its worst centre-view gain over Malvar across the settings
    (ties broken by the average gain); rules that lose more than 0.3 dB on the mean
    image somewhere rank after all others.
    """
    entries = [r for r in results if r["method"] == method and (rho is None or r.get("rho") == rho)]
    factors = list(entries[0]["curves"])
    rules = [(f, d, max(iteration_grid)) for f in factors for d in change_grid]
    rules += [(f, 0.0, k) for f in factors for k in iteration_grid]
    scored = []
    for factor, change, limit in rules:
        gains_c, gains_m, iters = [], [], []
        for e in entries:
            c, m, k = rule_outcome(e["curves"], factor, change, limit, e["sigma"])
            gains_c.append(c - e["malvar"]["psnr_center"])
            gains_m.append(m - e["malvar"]["psnr_mean"])
            iters.append(k)
        scored.append({"lam_per_sigma": float(factor), "change_per_sigma": change, "max_iter": limit,
                       "worst_gain_center": min(gains_c), "mean_gain_center": float(np.mean(gains_c)),
                       "worst_gain_mean": min(gains_m), "mean_gain_mean": float(np.mean(gains_m)),
                       "iterations": iters,
                       "settings": [f"{e['scene']}@{e['lux']:g}" for e in entries],
                       "gains_center": gains_c, "gains_mean": gains_m})
    # Rules that lose more than 0.3 dB on the mean image anywhere rank last.
    scored.sort(key=lambda r: (r["worst_gain_mean"] >= -0.3, r["worst_gain_center"], r["mean_gain_center"]),
                reverse=True)
    return scored

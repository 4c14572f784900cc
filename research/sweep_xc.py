"""The sweep behind the cross-channel defaults (docs/admm.md, "The cross-channel prior").

Training captures only: the built-in scenes re-simulated with seeds other than the
evaluation seed 0. For each capture, each cross-channel method and each pair
(c, e) of a grid, run the solver from the Malvar start with lam = c sigma and
lam_xc = e sigma, and record after every iteration PSNR (centre view, mean image),
mean CIEDE2000 (centre view, mean image) and rms(x_k - x_{k-1}). Then score the
rules "lam = c sigma, lam_xc = e sigma, stop when the rms change <= d sigma" and
"..., run exactly K iterations" over all captures (``summarise``).

    python research/sweep_xc.py -o sweep_xc.json --seeds 1,2 --lux 1,4,12,50
    python research/sweep_xc.py --summarise sweep_xc.json
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from lfcl.demosaic.methods import ADMM_DEFAULTS, admm_params
from lfcl.device import get_runtime
from lfcl.evaluation.evaluate import capture_in_memory
from lfcl.evaluation.metrics import lightfield_colour_scores, lightfield_scores
from lfcl.io.images import write_json
from lfcl.layout import LightFieldShape, planes_to_exchange
from lfcl.noise.model import from_noise_profile
from lfcl.ops.malvar import Malvar
from lfcl.solvers.admm import AdmmSolver
from lfcl.solvers.params import AdmmParams

METHOD_DIMS = {"admm-uv-xc": "uv", "admm-uvst-xc": "uvst"}
KEYS = ("psnr_center", "psnr_mean", "de2000_mean_center", "de2000_mean_mean")


def scores(planes: np.ndarray, shape: LightFieldShape, truth: np.ndarray) -> dict:
    """The four scores the rules are judged on, for [3, H, W] planes."""
    lightfield = planes_to_exchange(planes, shape)
    return {**lightfield_scores(lightfield, truth),
            **{k: v for k, v in lightfield_colour_scores(lightfield, truth).items() if k in KEYS}}


def sweep_capture(capture, dims: str, grid, max_iter: int, runtime) -> dict:
    """Score curves of the cross-channel prior over ``dims`` for each (c, e) of ``grid``."""
    sigma = from_noise_profile(capture.noise_profile, capture.mosaic).sigma
    shape = LightFieldShape.from_exchange(capture.truth)
    b = runtime.to_device(capture.mosaic)
    x0 = Malvar(runtime, capture.mosaic.shape, capture.pattern).forward(b)
    baseline = {"malvar": scores(x0.get(), shape, capture.truth)}
    # the existing (u, v) method with its defaults, to compare colour errors with
    plain = AdmmSolver(runtime, capture.mosaic.shape, capture.pattern, capture.pitch, "uv")
    baseline["admm-uv"] = scores(plain.solve(b, x0, admm_params("admm-uv", sigma)).x.get(), shape, capture.truth)
    solver = AdmmSolver(runtime, capture.mosaic.shape, capture.pattern, capture.pitch, dims)
    curves = {}
    for c, e in grid:
        curve = {key: [] for key in (*KEYS, "rms_change")}

        def record(rec, x, curve=curve):
            for key, value in scores(x.get(), shape, capture.truth).items():
                curve[key].append(value)
            curve["rms_change"].append(rec.rms_change)

        params = AdmmParams(lam=c * sigma, lam_xc=e * sigma, max_iter=max_iter)
        solver.solve(b, x0, params, callback=record)
        curves[f"{c:g},{e:g}"] = curve
    return {"sigma": sigma, "baseline": baseline, "curves": curves}


def rule_outcome(curve: dict, sigma: float, change_per_sigma: float, max_iter: int) -> tuple[dict, int]:
    """(scores, iterations) of "stop at rms change <= d sigma, else after max_iter" (d = 0: run max_iter)."""
    last = min(max_iter, len(curve["psnr_center"]))
    k = last
    if change_per_sigma > 0:
        for i in range(1, last):  # the first iteration never moves x (see params.stop_reason)
            if curve["rms_change"][i] <= change_per_sigma * sigma:
                k = i + 1
                break
    return {key: curve[key][k - 1] for key in KEYS}, k


def summarise(results: list[dict], method: str, change_grid=(0.05, 0.1, 0.2, 0.3, 0.5),
              iteration_grid=(5, 10, 15, 20, 30, 45, 60)) -> list[dict]:
    """Every rule scored over all captures of ``method``; best first.

    Per capture, a rule's gains over Malvar: PSNR centre and mean (dB) and the
    reductions of mean CIEDE2000 (centre, mean image). A rule is eligible when all four
    gains are positive on every capture. Rank: eligible first, then the worst
    centre-view PSNR gain (as the TV defaults), then the worst ΔE00 reduction.
    """
    entries = [r for r in results if r["method"] == method]
    pairs = list(entries[0]["curves"])
    rules = [(p, d, max(iteration_grid)) for p in pairs for d in change_grid]
    rules += [(p, 0.0, k) for p in pairs for k in iteration_grid]
    scored = []
    for pair, change, limit in rules:
        rows = []
        for entry in entries:
            outcome, k = rule_outcome(entry["curves"][pair], entry["sigma"], change, limit)
            malvar, plain = entry["baseline"]["malvar"], entry["baseline"]["admm-uv"]
            rows.append({
                "setting": f"{entry['scene']}@{entry['lux']:g}/seed{entry['seed']}", "iterations": k,
                "gain_center": outcome["psnr_center"] - malvar["psnr_center"],
                "gain_mean": outcome["psnr_mean"] - malvar["psnr_mean"],
                "de_gain_center": malvar["de2000_mean_center"] - outcome["de2000_mean_center"],
                "de_gain_mean": malvar["de2000_mean_mean"] - outcome["de2000_mean_mean"],
                "de_vs_uv_center": plain["de2000_mean_center"] - outcome["de2000_mean_center"],
                "de_vs_uv_mean": plain["de2000_mean_mean"] - outcome["de2000_mean_mean"],
            })
        c, e = (float(v) for v in pair.split(","))
        worst = {key: min(r[key] for r in rows) for key in rows[0] if key not in ("setting", "iterations")}
        scored.append({"lam_per_sigma": c, "xc_per_sigma": e, "change_per_sigma": change, "max_iter": limit,
                       "eligible": all(worst[k] > 0 for k in ("gain_center", "gain_mean", "de_gain_center",
                                                              "de_gain_mean")),
                       "worst": worst, "rows": rows})
    scored.sort(key=lambda r: (r["eligible"], r["worst"]["gain_center"], r["worst"]["de_gain_center"]), reverse=True)
    return scored


def print_summary(path: str, top: int = 8):
    with open(path) as f:
        results = json.load(f)["results"]
    for method in sorted({r["method"] for r in results}):
        print(f"== {method}: best rules (worst gains over the training captures) ==")
        for rule in summarise(results, method)[:top]:
            w = rule["worst"]
            stop = (f"stop at {rule['change_per_sigma']:g} sigma" if rule["change_per_sigma"]
                    else f"{rule['max_iter']} iterations")
            print(f"c={rule['lam_per_sigma']:g} e={rule['xc_per_sigma']:g} {stop:20s} eligible={rule['eligible']} "
                  f"PSNR centre {w['gain_center']:+.2f} mean {w['gain_mean']:+.2f} dB; dE00 centre "
                  f"{w['de_gain_center']:+.2f} mean {w['de_gain_mean']:+.2f}; vs admm-uv dE00 centre "
                  f"{w['de_vs_uv_center']:+.2f} mean {w['de_vs_uv_mean']:+.2f}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--output")
    parser.add_argument("--summarise", metavar="JSON", help="print the best rules of an earlier sweep and exit")
    parser.add_argument("--scenes", default="charts,deadleaves")
    parser.add_argument("--lux", default="1,4,12,50")
    parser.add_argument("--seeds", default="1")
    parser.add_argument("--lenses", default="64x64")
    parser.add_argument("--methods", default="admm-uv-xc,admm-uvst-xc")
    parser.add_argument("--lam-factors", default="0.03,0.1,0.3")
    parser.add_argument("--xc-factors", default="0.1,0.3,1,3")
    parser.add_argument("--max-iter", type=int, default=60)
    args = parser.parse_args(argv)
    if args.summarise:
        print_summary(args.summarise)
        return
    if not args.output:
        parser.error("-o/--output is required for a sweep")
    seeds = [int(s) for s in args.seeds.split(",")]
    if 0 in seeds:
        parser.error("seed 0 is the evaluation capture: train on other seeds")
    runtime = get_runtime()
    lenses = [int(n) for n in args.lenses.split("x")]
    grid = [(float(c), float(e)) for c in args.lam_factors.split(",") for e in args.xc_factors.split(",")]
    results = []
    for seed in seeds:
        for scene in args.scenes.split(","):
            for lux in (float(v) for v in args.lux.split(",")):
                meta = {"scene": {"kind": "scene", "name": scene}, "lenses": lenses, "pitch": [9, 9],
                        "pattern": "GRBG", "seed": seed}
                capture = capture_in_memory(meta, lux)
                for method in args.methods.split(","):
                    dims = METHOD_DIMS.get(method) or ADMM_DEFAULTS[method].dims
                    start = time.perf_counter()
                    entry = sweep_capture(capture, dims, grid, args.max_iter, runtime)
                    entry.update(scene=scene, lux=lux, seed=seed, method=method, seconds=time.perf_counter() - start)
                    results.append(entry)
                    best = max((max(c["psnr_center"]), p) for p, c in entry["curves"].items())
                    print(f"{scene:10s} seed {seed} {lux:5g} lux {method:13s} sigma {entry['sigma']:.4f} malvar "
                          f"{entry['baseline']['malvar']['psnr_center']:.2f} admm-uv "
                          f"{entry['baseline']['admm-uv']['psnr_center']:.2f} best centre {best[0]:.2f} at c,e={best[1]} "
                          f"({entry['seconds']:.0f} s)", flush=True)
                    write_json(args.output, {"args": vars(args), "results": results})


if __name__ == "__main__":
    main()

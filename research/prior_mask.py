"""Dark pixels in or out of the prior (issue #6, docs/admm.md): scores on a vignetted capture.

Simulates a capture with microlens vignetting strong enough to leave dark corners
(a fast microlens: f-number 0.4 puts 32 of the 81 pixels of a 9x9 lens below the
0.2 response threshold; the CLI's ``--vignetting`` is f/2.8, where none is),
calibrates the lens response from the capture's own white image as
``lfcl process --white`` does (lfcl.grid, then lens_response_from_calibration;
``--response white``: the plain lens average of the white image instead,
lfcl.grid.vignetting.lens_response_from_white),
flat-fields, starts from Malvar and runs each method with its defaults twice:
dark pixels out of the data term only (``prior_mask=False``, the old behaviour)
and out of the prior too (the default). Scores against the truth: PSNR and mean
CIEDE2000 on the centre view and the mean image, also over the lit pixels alone.

    python research/prior_mask.py --scene charts --lux 1,12,50 --f-number 0.4
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from lfcl.demosaic.methods import ADMM_DEFAULTS, admm_params
from lfcl.device import get_runtime
from lfcl.evaluation.metrics import lightfield_colour_scores, lightfield_scores, psnr
from lfcl.grid import calibrate_array
from lfcl.grid.vignetting import DEFAULT_THRESHOLD, flat_field, lens_response_from_calibration, lens_response_from_white
from lfcl.layout import LightFieldShape, planes_to_exchange
from lfcl.noise.model import from_noise_profile
from lfcl.ops.malvar import Malvar
from lfcl.solvers.admm import AdmmSolver


def lit_psnr(lightfield: np.ndarray, truth: np.ndarray, lit: np.ndarray) -> float:
    """PSNR over the samples of lit lens pixels only (all views, all lenses)."""
    return psnr(lightfield[:, :, lit], truth[:, :, lit])


def run(scene: str, lux: float, f_number: float, methods, seed: int = 0, lenses=(64, 64),
        response_from: str = "calibration") -> list[dict]:
    from lfcl.sim import simulate

    sim = simulate(scene, lenses=lenses, lux=lux, seed=seed, vignetting=True, f_number=f_number)
    mosaic = sim.normalised_raw()
    white = ((sim.white.astype(np.float32) - sim.black_level) / (sim.white_level - sim.black_level))
    pitch = tuple(sim.geometry.pitch)
    if response_from == "calibration":
        response = lens_response_from_calibration(calibrate_array(white, sim.pattern), pitch)
    else:
        response = lens_response_from_white(white, pitch)
    lit = response >= DEFAULT_THRESHOLD
    flat, weights = flat_field(mosaic, response)
    runtime = get_runtime()
    shape = LightFieldShape.from_exchange(sim.truth)
    sigma = from_noise_profile(list(sim.sensor.noise_profile()) * 3, mosaic).sigma
    b = runtime.to_device(flat)
    x0 = Malvar(runtime, flat.shape, sim.pattern).forward(b)

    def score(planes, method, prior_mask, seconds, iterations):
        lightfield = planes_to_exchange(planes, shape)
        colour = lightfield_colour_scores(lightfield, sim.truth)
        return {"scene": scene, "lux": lux, "method": method, "prior_mask": prior_mask,
                **lightfield_scores(lightfield, sim.truth), "psnr_lit": lit_psnr(lightfield, sim.truth, lit),
                "de2000_mean_center": colour["de2000_mean_center"], "de2000_mean_mean": colour["de2000_mean_mean"],
                "seconds": seconds, "iterations": iterations, "dark_pixels": int((~lit).sum())}

    rows = [score(x0.get(), "malvar", None, 0.0, 0)]
    for method in methods:
        solver = AdmmSolver(runtime, flat.shape, sim.pattern, pitch, ADMM_DEFAULTS[method].dims)
        for prior_mask in (False, True):
            params = dataclasses.replace(admm_params(method, sigma), prior_mask=prior_mask)
            solver.solve(b, x0, dataclasses.replace(params, max_iter=1), lens_weights=weights)  # build kernels
            start = time.perf_counter()
            result = solver.solve(b, x0, params, lens_weights=weights)
            planes = result.x.get()
            rows.append(score(planes, method, prior_mask, time.perf_counter() - start, result.iterations))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="charts,deadleaves")
    parser.add_argument("--lux", default="1,12,50")
    parser.add_argument("--f-number", type=float, default=0.4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--methods", default="admm-uv,admm-uv-xc,admm-uvst-xc")
    parser.add_argument("--response", choices=("calibration", "white"), default="calibration",
                        help="lens response from the calibration's weight model (as lfcl process --white) "
                             "or the white image's plain lens average")
    args = parser.parse_args(argv)
    print("| scene | lux | method | prior | PSNR centre | PSNR mean | PSNR lit | ΔE00 centre | ΔE00 mean | s | it |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for scene in args.scenes.split(","):
        for lux in (float(v) for v in args.lux.split(",")):
            for r in run(scene, lux, args.f_number, args.methods.split(","), args.seed, response_from=args.response):
                prior = {None: "-", False: "all pixels", True: "lit only"}[r["prior_mask"]]
                print(f"| {scene} | {lux:g} | {r['method']} | {prior} | {r['psnr_center']:.2f} | {r['psnr_mean']:.2f} "
                      f"| {r['psnr_lit']:.2f} | {r['de2000_mean_center']:.2f} | {r['de2000_mean_mean']:.2f} "
                      f"| {r['seconds']:.2f} | {r['iterations']} |", flush=True)


if __name__ == "__main__":
    main()

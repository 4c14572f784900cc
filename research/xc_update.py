"""The cross-channel x-update: exact 3UV x 3UV lens blocks against Jacobi-PCG (docs/admm.md).

With the cross-channel prior over (u, v) the normal matrix A^T W A + rho K^T K is
still block diagonal over lenses, but each lens's block couples its three colours
(3UV x 3UV: 243 x 243 at pitch 9). This times both x-updates on one capture over
the same iterations and reports ms per iteration, the objective reached and the
scores, with the plain (u, v) prior for comparison.

    lfcl simulate --scene charts --lenses 64x64 --lux 12 --seed 0 -o cap
    python research/xc_update.py cap --iterations 20
"""

from __future__ import annotations

import argparse
import time

from lfcl.demosaic.methods import ADMM_DEFAULTS
from lfcl.device import get_runtime
from lfcl.evaluation.evaluate import load_capture
from lfcl.evaluation.metrics import lightfield_colour_scores, lightfield_scores
from lfcl.layout import LightFieldShape, planes_to_exchange
from lfcl.noise.model import from_noise_profile
from lfcl.ops.malvar import Malvar
from lfcl.solvers.admm import AdmmSolver
from lfcl.solvers.params import AdmmParams


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("capture")
    parser.add_argument("--iterations", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=3, help="timed runs of each variant; the fastest counts")
    args = parser.parse_args(argv)
    capture = load_capture(args.capture)
    sigma = from_noise_profile(capture.noise_profile, capture.mosaic).sigma
    runtime = get_runtime()
    b = runtime.to_device(capture.mosaic)
    x0 = Malvar(runtime, capture.mosaic.shape, capture.pattern).forward(b)
    shape = LightFieldShape.from_exchange(capture.truth)
    solver = AdmmSolver(runtime, capture.mosaic.shape, capture.pattern, capture.pitch, "uv")
    d = ADMM_DEFAULTS["admm-uv-xc"]
    print(f"{runtime.name}; {args.iterations} iterations, lam = {d.lam_per_sigma:g} sigma, "
          f"lam_xc = {d.xc_per_sigma:g} sigma or 0")
    print("| prior | x-update | ms / iteration | objective | PSNR centre / mean | ΔE00 centre / mean |")
    print("|---|---|---|---|---|---|")
    for lam_xc in (0.0, d.xc_per_sigma * sigma):
        for x_update, steps in (("lens", 4), ("cg", 4), ("cg", 8), ("cg", 16)):
            params = AdmmParams(lam=d.lam_per_sigma * sigma, lam_xc=lam_xc, max_iter=args.iterations,
                                cg_steps=steps, x_update=x_update)
            solver.solve(b, x0, AdmmParams(lam=params.lam, lam_xc=lam_xc, max_iter=2, x_update=x_update))  # build
            best = float("inf")
            for _ in range(args.repeat):
                runtime.queue.finish()
                start = time.perf_counter()
                result = solver.solve(b, x0, params)
                runtime.queue.finish()
                best = min(best, time.perf_counter() - start)
            lightfield = planes_to_exchange(result.x.get(), shape)
            s, c = lightfield_scores(lightfield, capture.truth), lightfield_colour_scores(lightfield, capture.truth)
            label = "exact per lens" if x_update == "lens" else f"Jacobi-PCG, {steps} steps"
            print(f"| {'TV + cross-channel' if lam_xc else 'TV'} | {label} | {1000 * best / args.iterations:.1f} "
                  f"| {result.history[-1].objective:.6g} | {s['psnr_center']:.2f} / {s['psnr_mean']:.2f} "
                  f"| {c['de2000_mean_center']:.2f} / {c['de2000_mean_mean']:.2f} |", flush=True)


if __name__ == "__main__":
    main()

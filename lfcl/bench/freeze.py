"""Measure freezing converged lenses (lfcl/solvers/freeze.py, docs/auto.md): admm-uv and
admm-uv-xc plain against ``demosaic_lightfield(..., freeze=fraction)``.

    python -m lfcl.bench.freeze [--lenses 64,160] [--lux 2,12,50] [--methods admm-uv,admm-uv-xc]
                                [--fractions 0.1,0.2,0.3] [--repeats 3] [-o freeze.json]

Per scene, lux and method: one untimed warm-up run of each setting (program builds; with
freezing also the moved solvers' sizes, which PoCL compiles once per size), then
``--repeats`` rounds that run plain and every fraction in turn (alternating, so that load
from other work on the machine falls on all of them alike); the figure is the median. A
run is the whole ``demosaic_lightfield`` call (Malvar start, solve, copy back). "cpu" is
the process's CPU time (PoCL runs the kernels on threads of this process): less sensitive
to other work on a shared machine than the wall clock.
"skipped" is the share of the plain solve's lens-iterations that frozen lenses skipped,
"work" the lens-iterations the solvers ran (the moved grids' padding included) against it.

``--potential`` measures the ceiling instead: from one plain solve, the share of its
lens-iterations that units of lens rows, 2 x 4 lens blocks or single lenses would skip if
each froze at the first iteration (from the second) where its own rms change is <=
fraction * change_tol, at no cost and with the plain trajectory (no timing, no PSNR).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ..imageio import write_json
from ..layout import LightFieldShape, planes_to_exchange
from ..methods import demosaic_lightfield
from ..metrics import lightfield_scores
from ..noise import from_noise_profile
from ..solvers.freeze import FreezeSettings
from .timing import add_capture_arguments, captures


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v]


def measure(capture, method: str, fractions: list[float], repeats: int, shrink_at: float | None = None) -> list[dict]:
    """Plain and each freeze fraction on one capture: a row per setting."""
    noise = from_noise_profile(capture.noise_profile, capture.mosaic)
    shape = LightFieldShape.from_exchange(capture.truth)
    settings = [0.0, *fractions]

    def run(fraction):
        freeze = FreezeSettings(fraction, shrink_at) if fraction and shrink_at is not None else fraction or False
        start, cpu = time.perf_counter(), time.process_time()
        result = demosaic_lightfield(capture.mosaic, capture.pattern, capture.pitch, method, noise=noise,
                                     freeze=freeze)
        return (time.perf_counter() - start, time.process_time() - cpu), result

    first = {f: run(f)[0][0] for f in settings}  # warm-up: program builds and the moved solvers' sizes
    times: dict = {f: [] for f in settings}
    cpu_times: dict = {f: [] for f in settings}
    results: dict = {}
    for _ in range(repeats):
        for f in settings:
            (seconds, cpu), results[f] = run(f)
            times[f].append(seconds)
            cpu_times[f].append(cpu)
    rows = []
    for f in settings:
        result = results[f]
        scores = lightfield_scores(planes_to_exchange(result.planes, shape), capture.truth)
        record = result.parameters.get("freeze", {})
        rows.append({"fraction": f, "seconds": float(np.median(times[f])), "first_seconds": first[f],
                     "times": times[f], "cpu_seconds": float(np.median(cpu_times[f])), "iterations": result.iterations,
                     "psnr_center": scores["psnr_center"], "psnr_mean": scores["psnr_mean"],
                     "skipped": record.get("skipped_share", 0.0), "work": record.get("work_share", 1.0),
                     "frozen_lenses": record.get("frozen_lenses", 0), "moves": len(record.get("moves", []))})
    plain = rows[0]
    for row in rows:
        row["loss_center"] = plain["psnr_center"] - row["psnr_center"]
        row["loss_mean"] = plain["psnr_mean"] - row["psnr_mean"]
        row["speedup"] = plain["seconds"] / row["seconds"]
        row["cpu_speedup"] = plain["cpu_seconds"] / row["cpu_seconds"]
    return rows


def potential(capture, method: str, fractions: list[float]) -> dict:
    """The skippable share of a plain solve's lens-iterations per unit and fraction (module docstring)."""
    from ..device import get_runtime
    from ..methods import admm_params
    from ..ops.malvar import Malvar
    from ..solvers.admm import AdmmSolver

    runtime = get_runtime()
    noise = from_noise_profile(capture.noise_profile, capture.mosaic)
    params = admm_params(method, noise.sigma)
    (U, V), (H, W) = capture.pitch, capture.mosaic.shape
    S, T = H // U, W // V
    b = runtime.to_device(capture.mosaic)
    x0 = Malvar(runtime, (H, W), capture.pattern).forward(b)
    previous, changes = [x0.get()], []

    def record(_, x):
        now = x.get()
        changes.append(((now - previous[0]).astype(np.float64) ** 2).reshape(3, S, U, T, V).sum(axis=(0, 2, 4)))
        previous[0] = now

    AdmmSolver(runtime, (H, W), capture.pattern, capture.pitch, "uv").solve(b, x0, params, callback=record)
    per_lens = np.array(changes)  # [iterations, S, T] squared change per lens
    K, samples = len(per_lens), 3 * U * V
    Sb, Tb = S // 2 * 2, T // 4 * 4  # whole 2 x 4 blocks
    units = {"lens rows": np.sqrt(per_lens.sum(axis=2) / (samples * T)),
             "2x4 blocks": np.sqrt(per_lens[:, :Sb, :Tb].reshape(K, Sb // 2, 2, Tb // 4, 4).sum(axis=(2, 4))
                                   / (8 * samples)).reshape(K, -1),
             "lenses": np.sqrt(per_lens / samples).reshape(K, -1)}
    out = {"iterations": K}
    for name, rms in units.items():
        for fraction in fractions:
            below = rms <= fraction * params.change_tol
            below[0] = False  # the first x-update from the Malvar start changes nothing
            first = np.where(below.any(axis=0), below.argmax(axis=0) + 1, K)
            out[f"{name} {fraction:g}"] = float(np.sum(K - first) / (K * rms.shape[1]))
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_capture_arguments(parser, "admm-uv,admm-uv-xc")
    parser.add_argument("--fractions", default="0.1,0.2,0.3")
    parser.add_argument("--shrink-at", type=float, default=None,
                        help="move once the active blocks are at most this share (default: FreezeSettings')")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--potential", action="store_true", help="the ceiling: skippable lens-iterations only")
    parser.add_argument("-o", "--output", help="write the rows as JSON")
    args = parser.parse_args(argv)
    out = []
    for lenses, scene, lux, capture in captures(args):
        for method in args.methods.split(","):
            if args.potential:
                row = {"lenses": lenses, "scene": scene, "lux": lux, "method": method,
                       **potential(capture, method, _floats(args.fractions))}
                out.append(row)
                print(f"{lenses:4d} {scene:10s} {lux:4g} lux {method:10s} " + "  ".join(
                    f"{k} {v:.2f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()
                    if k not in ("lenses", "scene", "lux", "method")), flush=True)
                continue
            for row in measure(capture, method, _floats(args.fractions), args.repeats, args.shrink_at):
                row.update(lenses=lenses, scene=scene, lux=lux, method=method)
                out.append(row)
                label = "plain" if not row["fraction"] else f"freeze {row['fraction']:g}"
                print(f"{lenses:4d} {scene:10s} {lux:4g} lux {method:10s} {label:11s} "
                      f"{row['seconds']:6.3f} s (x{row['speedup']:.2f}, first {row['first_seconds']:.2f} s, "
                      f"cpu {row['cpu_seconds']:.2f} s x{row['cpu_speedup']:.2f})  "
                      f"{row['iterations']:2d} it  skipped {row['skipped']:.3f} work {row['work']:.3f} "
                      f"moves {row['moves']}  PSNR {row['psnr_center']:.2f} / {row['psnr_mean']:.2f}  "
                      f"loss {row['loss_center']:+.3f} / {row['loss_mean']:+.3f}", flush=True)
    if args.output:
        write_json(args.output, out)


if __name__ == "__main__":
    main()

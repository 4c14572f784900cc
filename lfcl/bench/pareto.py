"""Quality against run time (``lfcl bench pareto``) and the ADMM iteration cost (``lfcl bench admm``).

Pareto: on one simulated capture (a ``lfcl simulate`` folder, or simulated in
memory), every method at every iteration budget gives one point (seconds, PSNR of
the centre view, PSNR of the mean image), with two peers timed in the same run:

* ``malvar``, ``linear4d``: lfcl's OpenCL Malvar-He-Cutler and learned 4D filter (one
  point each; no iterations);
* ``admm-uv``, ``admm-st``, ``admm-uvst``, ... (any ADMM method, ``METHOD[:START]`` as
  ``lfcl process --method`` takes it, e.g. ``admm-uv-xc:linear4d``): ``lfcl.demosaic.driver.demosaic_grid`` with
  ``iterations=k`` (no early stop), the noise level from the capture's DNG noise
  profile as ``lfcl.evaluation.evaluate.run_method`` does;
* ``colour-demosaicing Malvar2004``: ``demosaicing_CFA_Bayer_Malvar2004`` on the
  whole mosaic (numpy/scipy, float64);
* ``numpy reference admm-uv (CG)``: ``lfcl.solvers.reference.admm_reference`` (float64)
  from a numpy Malvar start with the same parameters as admm-uv. It always solves the
  x-update with 4 warm-started CG steps; the device's admm-uv uses its default
  x-update (the exact per-lens solve where the solver has it), so the two curves are
  the same ADMM but not the same x-update.

Seconds are end to end for the method (upload, Malvar start, solver set-up and
iterations, download), the median over ``repeats`` runs after one untimed warm-up
per method (which builds the OpenCL programs). A point is on the *front* when no
other point is faster and at least as good in centre-view PSNR (:func:`mark_front`).

ADMM iteration: ``AdmmSolver.solve`` against ``admm_reference`` for a fixed number
of iterations with a fixed CG step count (``cg_tol = 0``), divided by the iterations.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..demosaic.driver import demosaic_grid
from ..demosaic.methods import ADMM_DEFAULTS, STARTS, admm_params
from ..demosaic.names import parse_method_spec
from ..evaluation.evaluate import Capture, capture_in_memory, load_capture
from ..evaluation.metrics import lightfield_scores
from ..grid.model import AlignedGrid
from ..layout import LightFieldShape, planes_to_exchange
from .timing import format_table, time_calls

ADMM_METHODS = tuple(ADMM_DEFAULTS)
PEER_MALVAR = "colour-demosaicing Malvar2004"
PEER_ADMM = "numpy reference admm-uv (CG)"
REFERENCE_MAX_BUDGET = 10  # default: the numpy reference runs the budgets up to this


def make_capture(directory=None, lenses=(64, 64), lux: float = 12.0, scene: str = "charts", seed: int = 0) -> Capture:
    """A capture folder, or the scene simulated in memory (pitch 9, GRBG)."""
    if directory is not None:
        return load_capture(directory)
    meta = {"scene": {"kind": "scene", "name": scene}, "lenses": list(lenses), "pitch": [9, 9],
            "pattern": "GRBG", "seed": seed}
    capture = capture_in_memory(meta, lux)
    capture.meta.setdefault("lux", lux)
    return capture


def _noise(capture: Capture):
    """The noise model run_method uses: the DNG noise profile, else an estimate from the raw."""
    from ..noise.model import estimate_noise, from_noise_profile

    if capture.noise_profile is not None:
        return from_noise_profile(capture.noise_profile, capture.mosaic)
    return estimate_noise(capture.mosaic, capture.pattern, capture.pitch)


def _colour_demosaicing():
    import warnings

    try:
        with warnings.catch_warnings():  # its scipy.ndimage.filters imports are deprecated
            warnings.simplefilter("ignore", DeprecationWarning)
            from colour_demosaicing import demosaicing_CFA_Bayer_Malvar2004
    except ImportError:
        raise ValueError(
            "bench pareto compares against colour-demosaicing's Malvar2004, which is not installed: "
            "pip install 'lfcl[test]' (or pip install colour-demosaicing)"
        ) from None
    return demosaicing_CFA_Bayer_Malvar2004


def _median_run(fn, repeats: int):
    """(median seconds, last result) of ``repeats`` timed calls of ``fn``."""
    results = []
    timing = time_calls(lambda: results.append(fn()), repeats, warmup=0)
    return timing.median, results[-1]


def _point(method, implementation, iterations, seconds, scores, stop_reason=None) -> dict:
    return {"method": method, "implementation": implementation, "iterations": iterations, "seconds": seconds,
            "psnr_center": scores["psnr_center"], "psnr_mean": scores["psnr_mean"], "stop_reason": stop_reason}


def mark_front(points: list[dict], key: str = "psnr_center", tolerance_db: float = 0.01) -> None:
    """Set ``front`` on every point that no other point beats: faster and at least as good.

    PSNRs within ``tolerance_db`` count as equal (the first ADMM iteration moves the
    Malvar start by float rounding only).
    """
    def beats(q, p):
        no_worse = q["seconds"] <= p["seconds"] and q[key] >= p[key] - tolerance_db
        return no_worse and (q["seconds"] < p["seconds"] or q[key] > p[key] + tolerance_db)

    for p in points:
        p["front"] = not any(q is not p and beats(q, p) for q in points)


def _admm_method(label: str) -> str | None:
    """The ADMM method of ``METHOD[:START]`` (lfcl.demosaic.names.parse_method_spec), None for any other."""
    try:
        method, _ = parse_method_spec(label)
    except ValueError:
        return None
    return method if method in ADMM_METHODS else None


def run(capture: Capture, budgets, reference_budgets=None, methods=ADMM_METHODS, repeats: int = 1,
        device=None, progress=None, skip_flat: bool | None = None, safety_net: bool = True) -> dict:
    """Every (method, budget) point and the peers on ``capture``; a JSON-ready dict.

    ``reference_budgets``: budgets for the numpy reference ADMM (None: those of
    ``budgets`` up to 10; empty: skip it). ``progress(label)`` is called before
    each point. ``skip_flat``: as ``demosaic_grid``'s (None: each method's default,
    which for admm-uv and admm-uv-xc leaves flat lenses out; False: every lens solved,
    like the numpy reference). ``safety_net``: lfcl's methods with the net (as `lfcl process` runs them); False: the
    solvers alone, like the numpy reference.
    """
    from ..device import get_runtime
    from ..ops.malvar import malvar_np
    from ..solvers.reference import admm_reference

    malvar2004 = _colour_demosaicing()
    budgets = sorted({int(b) for b in budgets})
    if not budgets or budgets[0] < 1:
        raise ValueError(f"budgets must be positive integers, got {budgets}")
    if reference_budgets is None:
        reference_budgets = [b for b in budgets if b <= REFERENCE_MAX_BUDGET] or budgets[:1]
    unknown = [m for m in methods if _admm_method(m) is None]
    if unknown:
        raise ValueError(f"unknown ADMM method(s) {', '.join(unknown)}: expected {', '.join(ADMM_METHODS)}, "
                         f"optionally METHOD:START with START one of {', '.join(STARTS)}")
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    runtime = get_runtime(device)
    shape = LightFieldShape.from_exchange(capture.truth)
    mosaic, pattern, pitch = capture.mosaic, capture.pattern, capture.pitch
    noise = _noise(capture)
    say = progress or (lambda label: None)

    def score(planes):
        return lightfield_scores(planes_to_exchange(np.asarray(planes, np.float32), shape), capture.truth)

    def lfcl_method(label, iterations=None):
        method, start = parse_method_spec(label)
        return demosaic_grid(mosaic, pattern, AlignedGrid(pitch), method, iterations=iterations,
                             noise=None if method == "malvar" else noise, device=device, start=start,
                             skip_flat=skip_flat if iterations is not None else None, safety_net=safety_net)

    points = []
    # the direct methods: warm-up (program build), then timed
    for direct in ("malvar", "linear4d"):
        say(direct)
        lfcl_method(direct)
        seconds, result = _median_run(lambda direct=direct: lfcl_method(direct), repeats)
        points.append(_point(direct, "lfcl OpenCL", 0, seconds, score(result.planes), result.stop_reason))

    for method in methods:
        say(f"{method} warm-up")
        lfcl_method(method, 1)
        for k in budgets:
            say(f"{method} x{k}")
            seconds, result = _median_run(lambda: lfcl_method(method, k), repeats)
            points.append(_point(method, "lfcl OpenCL", result.iterations, seconds, score(result.planes),
                                 result.stop_reason))

    say(PEER_MALVAR)
    seconds, rgb = _median_run(lambda: malvar2004(mosaic, pattern), repeats)
    points.append(_point(PEER_MALVAR, "colour-demosaicing (numpy/scipy, float64)", 0, seconds,
                         score(np.moveaxis(np.asarray(rgb), -1, 0)), "direct"))

    dims = ADMM_DEFAULTS["admm-uv"].dims
    for k in reference_budgets:
        say(f"{PEER_ADMM} x{k}")
        params = admm_params("admm-uv", noise.sigma, iterations=k)

        def reference():
            x0 = malvar_np(mosaic, pattern)
            return admm_reference(mosaic, pattern, pitch, dims, params, x0)

        seconds, result = _median_run(reference, repeats)
        points.append(_point(PEER_ADMM, "lfcl.solvers.reference (numpy, float64)", result.iterations, seconds,
                             score(result.x), result.stop_reason))

    mark_front(points)
    return {
        "device": runtime.name,
        "capture": None if str(capture.directory) == "." else str(capture.directory),
        "scene": capture.meta.get("scene"),
        "lux": capture.meta.get("lux"),
        "lenses": [shape.S, shape.T],
        "pitch": [shape.U, shape.V],
        "pattern": pattern,
        "noise_sigma": noise.sigma,
        "budgets": budgets,
        "reference_budgets": list(reference_budgets),
        "skip_flat": skip_flat,
        "safety_net": safety_net,
        "repeats": repeats,
        "points": points,
    }


def format_report(report: dict) -> str:
    S, T = report["lenses"]
    scene = report["scene"] or {}
    lux = f" at {report['lux']:g} lux" if report.get("lux") is not None else ""
    head = (f"{scene.get('name', 'capture')}{lux}, {S}x{T} lenses of "
            f"{report['pitch'][0]}x{report['pitch'][1]} ({report['pattern']}, noise sigma {report['noise_sigma']:.4f}), "
            f"{report['device']}; seconds: median of {report['repeats']}; * = on the front (no other point is "
            f"faster and as good in centre PSNR, 0.01 dB counting as equal)")
    rows = [[p["method"], str(p["iterations"]) if p["iterations"] else "-", f"{p['seconds']:.3f}",
             f"{p['psnr_center']:.2f}", f"{p['psnr_mean']:.2f}", "*" if p.get("front") else ""]
            for p in report["points"]]
    return head + "\n\n" + format_table(["method", "iterations", "seconds", "PSNR centre (dB)", "PSNR mean (dB)",
                                         "front"], rows, align="lrrrrl")


def plot(report: dict, path) -> Path:
    """PSNR against seconds (log x): centre view and mean image side by side, one line per method."""
    import matplotlib.pyplot as plt

    from ..evaluation import plots  # noqa: F401  (selects the Agg backend)
    from ..io.images import atomic_path

    methods = list(dict.fromkeys(p["method"] for p in report["points"]))
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharex=True)
    for ax, key, title in ((axes[0], "psnr_center", "centre view"), (axes[1], "psnr_mean", "mean image")):
        for i, method in enumerate(methods):
            pts = sorted((p for p in report["points"] if p["method"] == method),
                         key=lambda p: (p["iterations"], p["seconds"]))
            style = "--" if "reference" in method or "colour" in method else "-"
            ax.plot([p["seconds"] for p in pts], [p[key] for p in pts], style, marker="o", color=f"C{i}", label=method)
            if len(pts) > 1:
                for p in pts:
                    ax.annotate(str(p["iterations"]), (p["seconds"], p[key]), textcoords="offset points",
                                xytext=(3, 3), fontsize=7, color=f"C{i}")
        ax.set_xscale("log")
        ax.set_xlabel("seconds (log)")
        ax.set_ylabel("PSNR (dB)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[1].legend(fontsize=8)
    S, T = report["lenses"]
    scene = report["scene"] or {}
    lux = f", {report['lux']:g} lux" if report.get("lux") is not None else ""
    fig.suptitle(f"PSNR against run time: {scene.get('name', 'capture')}{lux}, {S}x{T} lenses, "
                 f"{report['device']} (labels: iterations)", fontsize=10)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
    plt.close(fig)
    return path


# --- ADMM iteration: device solver against the numpy reference ---


def per_iteration(seconds: float, first_seconds: float, iterations: int) -> float:
    """Seconds per iteration without the per-solve set-up: (T(k) - T(1)) / (k - 1).

    The first iteration from the Malvar start is also set-up (its x-update is exact
    there), so it goes with the set-up. With k = 1 there is nothing to subtract.
    """
    if iterations <= 1:
        return seconds
    return max(seconds - first_seconds, 0.0) / (iterations - 1)


def _ratio(reference: float, device: float) -> float | None:
    """reference / device; None where the device's time per iteration came out 0 (T(k) <= T(1) within the timer's
    noise: a tiny problem on a busy machine), as the kernel table does."""
    return reference / device if device > 0 else None


def admm_iteration(capture: Capture, methods=ADMM_METHODS, iterations: int = 5, cg_steps: int = 4,
                   repeats: int = 3, reference_repeats: int = 1, device=None, progress=None) -> dict:
    """Seconds per ADMM iteration of AdmmSolver and admm_reference (fixed CG steps, cg_tol = 0)."""
    from ..device import get_runtime
    from ..ops.malvar import Malvar
    from ..solvers.admm import AdmmSolver
    from ..solvers.params import AdmmParams
    from ..solvers.reference import admm_reference

    if iterations < 1 or cg_steps < 1 or repeats < 1 or reference_repeats < 0:
        raise ValueError("iterations, cg_steps and repeats must be >= 1 (reference repeats >= 0)")
    unknown = [m for m in methods if m not in ADMM_METHODS]
    if unknown:
        raise ValueError(f"unknown ADMM method(s) {', '.join(unknown)}: expected {', '.join(ADMM_METHODS)}")
    runtime = get_runtime(device)
    mosaic, pattern, pitch = capture.mosaic, capture.pattern, capture.pitch
    sigma = _noise(capture).sigma
    b = runtime.to_device(mosaic)
    x0 = Malvar(runtime, mosaic.shape, pattern).forward(b)
    x0_host = x0.get()
    has_x_update = "x_update" in {f.name for f in dataclasses.fields(AdmmParams)}
    rows = []
    for method in methods:
        dims = ADMM_DEFAULTS[method].dims
        default = dataclasses.replace(admm_params(method, sigma, iterations=iterations), max_iter=iterations,
                                      cg_steps=cg_steps, cg_tol=0.0)
        # the reference always runs CG: so does the like-for-like device run
        params = dataclasses.replace(default, x_update="cg") if has_x_update else default
        if progress:
            progress(method)
        solver = AdmmSolver(runtime, mosaic.shape, pattern, pitch, dims)

        def timed(p):
            """(timing of p, its result, seconds per iteration without the per-solve set-up)."""
            one = dataclasses.replace(p, max_iter=1)
            solver.solve(b, x0, one)  # warm-up: program builds, lens blocks
            results = []
            timing = time_calls(lambda: results.append(solver.solve(b, x0, p)), repeats, warmup=0,
                                sync=runtime.queue.finish)
            first = time_calls(lambda: solver.solve(b, x0, one), repeats, warmup=0, sync=runtime.queue.finish)
            return timing, results[-1], per_iteration(timing.median, first.median, results[-1].iterations)

        timing, device_result, device_per = timed(params)
        row = {"method": method, "dims": dims, "lam": params.lam, "rho": params.rho,
               "device_iterations": device_result.iterations,
               "device_cg_steps": [r.cg_steps for r in device_result.history],
               "device_seconds": timing.median, "device_times": timing.times,
               "device_per_iteration": device_per,
               "default_x_update": "cg", "default_per_iteration": device_per,
               "reference_seconds": None, "reference_per_iteration": None, "speedup": None,
               "max_abs_diff": None}
        if has_x_update and default.x_update != "cg":
            default_timing, default_result, default_per = timed(default)
            if any(r.cg_steps != c for r, c in zip(default_result.history, row["device_cg_steps"])):
                row.update(default_x_update="lens" if all(r.cg_steps == 0 for r in default_result.history)
                           else default.x_update,
                           default_per_iteration=default_per,
                           default_times=default_timing.times)
        if reference_repeats:
            if progress:
                progress(f"{method} numpy reference")
            ref = []
            ref_timing = time_calls(lambda: ref.append(admm_reference(mosaic, pattern, pitch, dims, params, x0_host)),
                                    reference_repeats, warmup=0)
            one = dataclasses.replace(params, max_iter=1)
            ref_first = time_calls(lambda: admm_reference(mosaic, pattern, pitch, dims, one, x0_host), 1, warmup=0)
            per = per_iteration(ref_timing.median, ref_first.median, ref[-1].iterations)
            row.update(reference_seconds=ref_timing.median, reference_times=ref_timing.times,
                       reference_iterations=ref[-1].iterations, reference_per_iteration=per,
                       speedup=_ratio(per, row["device_per_iteration"]),
                       speedup_default=_ratio(per, row["default_per_iteration"]),
                       max_abs_diff=float(np.max(np.abs(device_result.x.get() - ref[-1].x))))
        rows.append(row)
    shape = LightFieldShape.from_sensor(mosaic.shape, pitch)
    return {"device": runtime.name, "lenses": [shape.S, shape.T], "pitch": list(pitch), "sensor": list(mosaic.shape),
            "iterations": iterations, "cg_steps": cg_steps, "cg_tol": 0.0, "noise_sigma": sigma,
            "repeats": repeats, "reference_repeats": reference_repeats, "methods": rows}


def format_admm(report: dict) -> str:
    S, T = report["lenses"]
    head = (f"ADMM iteration, {S}x{T} lenses ({report['sensor'][0]}x{report['sensor'][1]} sensor), "
            f"{report['iterations']} iterations of {report['cg_steps']} CG steps (cg_tol 0), {report['device']}; "
            f"device: median of {report['repeats']}, numpy reference: median of {report['reference_repeats']}; "
            "per iteration = (T(k) - T(1)) / (k - 1), the per-solve set-up and first iteration left out")
    rows = []
    for r in report["methods"]:
        ref = r["reference_per_iteration"]
        default = (f"{r['default_per_iteration'] * 1e3:.1f} ({r['default_x_update']})"
                   if r["default_x_update"] != "cg" else "same")
        if r.get("speedup_default") is not None and r["default_x_update"] != "cg":
            default += f", {r['speedup_default']:.1f}x"
        rows.append([r["method"], f"{r['device_per_iteration'] * 1e3:.1f}",
                     f"{ref * 1e3:.1f}" if ref is not None else "-",
                     f"{r['speedup']:.1f}x" if r["speedup"] is not None else "-",
                     f"{r['max_abs_diff']:.2g}" if r["max_abs_diff"] is not None else "-", default])
    return head + "\n\n" + format_table(["method", "AdmmSolver ms/iter (CG)", "admm_reference ms/iter",
                                         "speed-up", "max abs(x_dev - x_ref)", "AdmmSolver default x-update ms/iter, speed-up"],
                                        rows)

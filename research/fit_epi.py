"""Fit and measure ``admm-epi`` (lfcl/solvers/epi.py): the schedule in lfcl/solvers/epi.py EPI_SCHEDULE (used by
lfcl/demosaic/methods.py for ADMM_DEFAULTS["admm-epi"]) and the table in docs/admm.md ("admm-epi: the prior along the
epipolar lines"). Not shipped in the wheel.

    python research/fit_epi.py trace --seeds 1,2 --starts malvar,linear4d,guarded --c 0.05,0.1,0.2,0.4 -o main.json
    python research/fit_epi.py fit main.json [more traces] -o research/fit_epi_fit_48.json
    python research/fit_epi.py fit main.json --others others.json -o ...   # issue 20's worst-case target instead
    python research/fit_epi.py table --seeds 5,6 --real -o research/fit_epi_table_48.json
    python research/fit_epi.py format research/fit_epi_table_48.json
    python research/fit_epi.py profile --scenes charts --seeds 5 --lux 12

(the exact runs behind the shipped schedule: docs/admm.md, "admm-epi").

``trace``: for a grid of lam = c sigma (lam_fb = f lam, lam_xc = xc lam: the cross-channel block along the epipolar
lines, rho, CG steps), starts (malvar, linear4d, guarded) and
disparities (``shipped``: lfcl.depth.estimate_disparity with admm-epi's EPI_DEPTH_OPTIONS, with the half-aperture
occlusion curves since they came back (before that, ``shipped`` was without them and ``occlusion`` or ``estimated``
with them); ``noocc``: the same without them; ``trusted``: ``shipped`` with confidence 1 everywhere, so no fall-back block; ``truth``: the scene's
own, lfcl.sim.scenes.render_disparity, confidence 1, for comparison only), the PSNR (centre view, mean image, against the noise-free truth; without and with the lens safety net)
after every iteration. The noise is the capture's DNG noise profile, as ``lfcl process`` reads it. ``fit``: per light level
(training sigma), the rule (c, f, xc, start, iterations or stop at rms change <= r sigma) with the best mean gain over
Malvar (centre view, as admm-epi runs: without the net) among rules that never lose to Malvar. ``table``: admm-epi with its
defaults and the other methods on held-out seeds (and the real light fields), seconds, with and without the net.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import time

import numpy as np

from lfcl.demosaic.driver import demosaic_grid
from lfcl.demosaic.safety_net import apply_safety_net
from lfcl.device import get_runtime
from lfcl.evaluation.evaluate import simulated_capture
from lfcl.evaluation.metrics import lightfield_scores
from lfcl.grid.model import AlignedGrid
from lfcl.layout import LightFieldShape, planes_to_exchange
from lfcl.noise.model import from_noise_profile
from lfcl.ops.malvar import Malvar
from lfcl.solvers.epi import EPI_SCHEDULE, EpiAdmmSolver, EpiPrior, epi_depth_options
from lfcl.solvers.params import AdmmParams

REAL = {"antinous": "../shared/realdata/hci_epinet/antinous", "lytro2067": "../shared/realdata/lytro_epinet/2067"}
OTHERS = ("malvar", "linear4d", "admm-uv", "admm-uvst", "admm-uv-xc")


PROCEDURAL = "procedural-"  # research/training_scenes.py's scene of that seed (linear4d's training family)


def procedural_lightfield(seed: int, lenses: int) -> str:
    """A .npy of the procedural training scene ``seed`` at ``lenses`` x ``lenses`` (rendered once, cached)."""
    import pathlib
    import tempfile

    from training_scenes import training_planes

    from lfcl.sim import render_planes

    path = pathlib.Path(tempfile.gettempdir()) / "lfcl_procedural" / f"{lenses}_{seed}.npy"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        np.save(path, render_planes(training_planes((lenses, lenses), seed, (9, 9)), (lenses, lenses), (9, 9)))
    return str(path)


def capture(scene, seed, lux, lenses):
    """A simulated capture of a built-in scene, a real light field (REAL) or ``procedural-N`` (noise seed ``seed``)."""
    if scene in REAL:
        return simulated_capture(lenses, lux, seed, lightfield=REAL[scene])
    if scene.startswith(PROCEDURAL):
        return simulated_capture(lenses, lux, seed, lightfield=procedural_lightfield(int(scene[len(PROCEDURAL):]),
                                                                                      lenses))
    return simulated_capture(lenses, lux, seed, scene)


def noise_of(cap):
    """The noise model ``lfcl process`` uses for this capture: its DNG noise profile (a simulated raw carries
    one, as most camera DNGs do)."""
    return from_noise_profile(cap.noise_profile, cap.mosaic)


def scores(planes, truth) -> dict:
    return lightfield_scores(planes_to_exchange(planes, LightFieldShape.from_exchange(truth)), truth)


def colour_of(planes, truth) -> dict:
    """Mean CIEDE2000 of the centre view and of the mean image (lfcl.evaluation.metrics.colour_scores)."""
    from lfcl.evaluation.metrics import lightfield_colour_scores

    got = lightfield_colour_scores(planes_to_exchange(planes, LightFieldShape.from_exchange(truth)), truth)
    return {"de2000_center": got["de2000_mean_center"], "de2000_mean": got["de2000_mean_mean"]}


@dataclasses.dataclass
class Depth:
    disparity: np.ndarray
    confidence: np.ndarray | None


def depth_for(kind, cap, noise, scene, seed, lenses) -> tuple[Depth, dict]:
    from lfcl.depth import badpix, estimate_disparity
    from lfcl.sim.scenes import render_disparity

    if scene.startswith(PROCEDURAL) and kind == "truth":
        raise SystemExit(f"{scene}: no scene disparity for --depth truth")
    gt = None if scene.startswith(PROCEDURAL) else np.nan_to_num(render_disparity(scene, lenses, seed, cap.pitch))
    if kind == "truth":
        return Depth(gt, None), {"source": "truth", "seconds": 0.0}
    began = time.perf_counter()
    options = {**epi_depth_options(noise.sigma), **({"occlusion": False} if kind == "noocc" else {})}
    est = estimate_disparity(cap.mosaic, cap.pattern, cap.pitch, noise=noise, **options)
    seconds = time.perf_counter() - began
    if kind == "trusted":  # the estimate with confidence 1 everywhere: no fall-back block
        est.confidence = np.ones_like(est.confidence)
    if gt is None:
        return Depth(est.disparity, est.confidence), {"source": kind, "seconds": seconds}
    return Depth(est.disparity, est.confidence), {
        "source": kind, "seconds": seconds, "badpix_0.1": float(badpix(est.disparity, gt, 0.1)),
        "badpix_0.1_confident": float(badpix(est.disparity[est.confidence >= 0.5], gt[est.confidence >= 0.5], 0.1))
        if np.any(est.confidence >= 0.5) else None, "confidence_mean": float(est.confidence.mean())}


def start_for(kind, runtime, cap, b, noise):
    malvar = Malvar(runtime, cap.mosaic.shape, cap.pattern).forward(b)
    if kind == "malvar":
        return malvar
    from lfcl.ops.linear4d import linear4d_operator

    x0 = linear4d_operator(runtime, cap.mosaic, cap.pattern, cap.pitch, (0, 0), noise).forward(b)
    if kind == "guarded":
        from lfcl.demosaic.guarded_start import guarded_start

        x0, _ = guarded_start(runtime, x0, malvar, b, cap.pitch, noise)
    return x0


def run_trace(args):
    lenses = (args.lenses, args.lenses)
    runtime = get_runtime()
    out = []
    for scene, seed, lux in itertools.product(args.scenes, args.seeds, args.lux):
        cap = capture(scene, seed, lux, args.lenses)
        noise = noise_of(cap)
        base = scores(demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "malvar").planes, cap.truth)
        b = runtime.to_device(cap.mosaic)
        solver = EpiAdmmSolver(runtime, cap.mosaic.shape, cap.pattern, cap.pitch)
        for depth_kind in args.depth:
            depth, depth_meta = depth_for(depth_kind, cap, noise, scene, seed, lenses)
            for start in args.starts:
                x0 = start_for(start, runtime, cap, b, noise)
                start_scores = scores(x0.get(), cap.truth)
                for c, f, xc, rho, cg in itertools.product(args.c, args.f, args.xc, args.rho, args.cg):
                    began = time.perf_counter()
                    params = AdmmParams(lam=c * noise.sigma, rho=rho, max_iter=args.iterations, cg_steps=cg,
                                        lam_xc=xc * c * noise.sigma)
                    prior = EpiPrior(depth.disparity, depth.confidence, lam_fb=f * c * noise.sigma)
                    rows = []

                    def record(rec, x, cap=cap, noise=noise, rows=rows):
                        planes = x.get()
                        s = scores(planes, cap.truth)
                        if args.no_net:  # admm-epi runs without it (docs/auto.md): the same scores
                            sn = s
                        else:
                            net, _ = apply_safety_net(runtime, planes, cap.mosaic, cap.pattern, cap.pitch, (0, 0),
                                                      noise)
                            sn = scores(net, cap.truth)
                        rows.append({"iteration": rec.iteration, "rms_change_sigma": rec.rms_change / noise.sigma,
                                     **s, "psnr_center_net": sn["psnr_center"], "psnr_mean_net": sn["psnr_mean"]})

                    solver.solve(b, x0, params, prior, callback=record)
                    best = max(rows, key=lambda r: r["psnr_center_net"])
                    print(f"{scene} s{seed} {lux:4g} lux sigma={noise.sigma:.2e} {depth_kind} {start} c={c:g} f={f:g} "
                          f"xc={xc:g} rho={rho:g} cg={cg}: malvar {base['psnr_center']:.2f}/{base['psnr_mean']:.2f}, start "
                          f"{start_scores['psnr_center']:.2f}/{start_scores['psnr_mean']:.2f}, best centre (net) "
                          f"{best['psnr_center_net']:.2f} at {best['iteration']} (mean {best['psnr_mean_net']:.2f}), "
                          f"last {rows[-1]['psnr_center_net']:.2f}/{rows[-1]['psnr_mean_net']:.2f} "
                          f"[{time.perf_counter() - began:.1f} s] {json.dumps(depth_meta)}", flush=True)
                    out.append({"scene": scene, "seed": seed, "lux": lux, "sigma": noise.sigma, "depth": depth_kind,
                                "start": start, "c": c, "f": f, "xc": xc, "rho": rho, "cg_steps": cg, "malvar": base,
                                "start_scores": start_scores, "depth_meta": depth_meta, "trace": rows})
    return out


STOPS = [f"K={k}" for k in (1, 2, 3, 4, 5, 6, 8, 10, 12, 15, 20, 25, 30, 40, 50, 60, 80)] + \
    [f"change<={r:g}" for r in (0.02, 0.05, 0.1, 0.2, 0.3, 0.5)]


def pick(trace: list[dict], stop: str) -> dict:
    """The iteration a stop rule ends at (the last traced if it never fires)."""
    if stop.startswith("K="):
        return trace[min(int(stop[2:]), len(trace)) - 1]
    ratio = float(stop.split("<=")[1])
    hit = [row for row in trace if row["iteration"] > 1 and row["rms_change_sigma"] <= ratio]
    return hit[0] if hit else trace[-1]


def rule_scores(runs: list[dict], stop: str, best_other: dict | None = None) -> dict:
    """A stop rule's gains over Malvar across ``runs``: centre view with the safety net (as ``lfcl process``
    runs), centre view and mean image without it; with ``best_other`` ((scene, seed, lux) -> the best other
    method's centre view, :func:`best_others`) also the centre view's gain over that."""
    picks = [pick(r["trace"], stop) for r in runs]
    net = [p["psnr_center_net"] - r["malvar"]["psnr_center"] for p, r in zip(picks, runs)]
    centre = [p["psnr_center"] - r["malvar"]["psnr_center"] for p, r in zip(picks, runs)]
    mean = [p["psnr_mean"] - r["malvar"]["psnr_mean"] for p, r in zip(picks, runs)]
    out = {"stop": stop, "mean_centre_net": float(np.mean(net)), "worst_centre_net": min(net),
           "mean_centre": float(np.mean(centre)), "worst_centre": min(centre), "mean_mean": float(np.mean(mean)),
           "worst_mean": min(mean), "iterations": [p["iteration"] for p in picks]}
    if best_other is not None:
        over = [p["psnr_center"] - best_other[(r["scene"], r["seed"], r["lux"])] for p, r in zip(picks, runs)]
        out.update(mean_over_best=float(np.mean(over)), worst_over_best=min(over))
    return out


def best_others(paths) -> dict:
    """(scene, seed, lux) -> the best centre view of the other methods in ``table`` outputs, each as ``lfcl
    process`` runs it (the safety net on, Malvar without)."""
    best: dict = {}
    for path in paths:
        with open(path) as fh:
            for r in json.load(fh)["rows"]:
                if r["method"] != "admm-epi" and (r["net"] or r["method"] == "malvar"):
                    key = (r["scene"], r["seed"], r["lux"])
                    best[key] = max(best.get(key, -np.inf), r["psnr_center"])
    return best


def run_fit(args):
    """Per light level: the best (depth, start, c, f, xc, rho, cg, stop) rule over the traced training captures
    (traces from before ``--xc`` count as xc = 0).

    The score is the mean centre-view gain over Malvar as ``lfcl process`` runs admm-epi, without the safety net
    (its fitted threshold, lfcl/demosaic/safety_net.py); a rule qualifies if it beats Malvar on the centre view of
    every capture and keeps the mean image within 0.1 dB of Malvar's or better. With ``--others`` (``table``
    outputs of the other methods on the same captures) the score is issue 20's target instead: the worst
    centre-view gain over the best other method, ties within 0.05 dB broken by the mean of that gain."""
    results = []
    for path in args.inputs:
        with open(path) as fh:
            results += json.load(fh)["results"]
    best = best_others(args.others) if args.others else None
    by_lux: dict = {}
    for r in results:
        by_lux.setdefault(r["lux"], []).append(r)
    fitted = []
    for lux in sorted(by_lux):
        groups: dict = {}
        for r in by_lux[lux]:
            key = (r["depth"], r["start"], r["c"], r["f"], r.get("xc", 0.0), r["rho"], r["cg_steps"])
            groups.setdefault(key, []).append(r)
        n = max(len(g) for g in groups.values())
        rules = []
        for key, runs in groups.items():
            if len(runs) < n:
                continue
            for stop in STOPS:
                s = rule_scores(runs, stop, best)
                s["qualifies"] = s["worst_centre"] > 0 and s["worst_mean"] >= -0.1
                s["score"] = s["mean_centre"] if s["qualifies"] else -100 + s["mean_centre"]
                rules.append({"depth": key[0], "start": key[1], "c": key[2], "f": key[3], "xc": key[4],
                              "rho": key[5], "cg_steps": key[6], **s})
        if best is not None:  # the worst gain over the best other method, ties within 0.05 dB by its mean
            top = max((r["worst_over_best"] for r in rules if r["qualifies"]), default=-np.inf)
            for r in rules:
                near = r["qualifies"] and r["worst_over_best"] >= top - 0.05
                r["score"] = r["mean_over_best"] if near else (-100 if r["qualifies"] else -200) + r["worst_over_best"]
        rules.sort(key=lambda x: -x["score"])
        sig = float(np.median([r["sigma"] for r in by_lux[lux]]))
        print(f"lux {lux:g} (median sigma {sig:.3e}, {n} captures): best rules")
        for rule in rules[:args.top]:
            print("  ", {k: (round(v, 3) if isinstance(v, float) else v) for k, v in rule.items()})
        fitted.append({"lux": lux, "sigma": sig, "sigmas": sorted(r["sigma"] for r in by_lux[lux]),
                       "rules": rules[:args.top]})
    return fitted


def pick_capped(trace: list[dict], most: int, change: float | None) -> dict:
    """The iteration admm-epi stops at with at most ``most`` iterations and (``change``) the change rule."""
    capped = trace[:most]
    if change is not None:
        hit = [row for row in capped if row["iteration"] > 1 and row["rms_change_sigma"] <= change]
        if hit:
            return hit[0]
    return capped[-1]


def run_fast(args):
    """admm-epi's schedule at a fraction of the shipped one's time: per light level, among the rules (start, c =
    lam / sigma, rho, CG steps, at most K iterations, the change rule or none) that cost at most ``--budget`` times
    the shipped rule there and keep its scores on the traced training captures, the one with the best mean
    centre-view gain over Malvar (the shipped rule where none qualifies).

    Keeping the scores: on every capture the centre view and the mean image within 0.1 dB of the shipped rule's or
    better (a rule that trades one scene's loss for another's gain does not qualify), and the mean centre-view gain
    at least the shipped rule's. A run's cost is its iterations times one iteration's (``--iteration-ms`` outside CG plus
    ``--cg-step-ms`` per CG step, from ``profile``). The shipped rule (the schedule's row nearest a level's median
    sigma, with ADMM_DEFAULTS' rho and CG steps) must be among the traces."""
    from lfcl.demosaic.methods import ADMM_DEFAULTS

    defaults = ADMM_DEFAULTS["admm-epi"]
    results = []
    for path in args.inputs:
        with open(path) as fh:
            results += json.load(fh)["results"]
    levels = []
    for lux in sorted({r["lux"] for r in results}):
        at = [r for r in results if r["lux"] == lux]
        sigma = float(np.median([r["sigma"] for r in at]))
        ship = min(EPI_SCHEDULE, key=lambda row: abs(np.log(row.sigma / sigma)))
        groups: dict = {}
        for r in at:
            groups.setdefault((r["start"], r["c"], r["rho"], r["cg_steps"]), []).append(r)
        rules = []
        for (start, c, rho, cg), runs in groups.items():
            for most, change in itertools.product((4, 6, 8, 10, 12, 15, 20, 25), (None, 0.02, 0.05, 0.1)):
                picks = [pick_capped(r["trace"], most, change) for r in runs]
                centre = [p["psnr_center"] - r["malvar"]["psnr_center"] for p, r in zip(picks, runs)]
                mean = [p["psnr_mean"] - r["malvar"]["psnr_mean"] for p, r in zip(picks, runs)]
                iterations = float(np.mean([p["iteration"] for p in picks]))
                rules.append({"start": start, "c": c, "rho": rho, "cg_steps": cg, "most": most, "change": change,
                              "captures": len(runs), "iterations": iterations,
                              "per_capture": {f"{r['scene']} {r['seed']}": (a, b) for r, a, b in zip(runs, centre, mean)},
                              "cost": iterations * (args.iteration_ms + cg * args.cg_step_ms) / 1e3,
                              "mean_centre": float(np.mean(centre)), "worst_centre": min(centre),
                              "mean_mean": float(np.mean(mean)), "worst_mean": min(mean)})
        shipped = [x for x in rules if (x["start"], x["rho"], x["cg_steps"], x["most"], x["c"], x["change"]) == (
            ship.start, defaults.rho, defaults.cg_steps, ship.iterations, ship.lam_per_sigma, ship.change_per_sigma or None)]
        if not shipped:
            raise SystemExit(f"lux {lux:g}: no traces of the shipped rule {ship} (trace it)")
        base = shipped[0]
        def keeps(x):
            mine = x["per_capture"]
            return mine.keys() == base["per_capture"].keys() and all(
                mine[k][0] >= own[0] - 0.1 and mine[k][1] >= own[1] - 0.1 for k, own in base["per_capture"].items())

        keep = [x for x in rules if x["cost"] <= args.budget * base["cost"] and x["mean_centre"] >= base["mean_centre"]
                and keeps(x)]
        keep.sort(key=lambda x: (-x["mean_centre"], x["cost"]))
        levels.append({"lux": lux, "sigma": sigma, "shipped": base, "pick": keep[0] if keep else base,
                       "runners_up": keep[1:args.top]})

    def brief(rule):
        return json.dumps({k: (round(v, 3) if isinstance(v, float) else v) for k, v in rule.items()
                           if k not in ("start", "captures", "per_capture")})

    for level in levels:
        print(f"lux {level['lux']:g} (median sigma {level['sigma']:.3e}):\n   shipped {brief(level['shipped'])}")
        for rule in [level["pick"], *level["runners_up"]]:
            print(f"   {rule['cost'] / level['shipped']['cost']:.2f}x the time: {brief(rule)}")
    return levels


def run_table(args):
    rows = []
    scenes = [(s, seed) for s in args.scenes for seed in args.seeds] + \
        ([(name, args.seeds[0]) for name in REAL] if args.real else [])
    for (scene, seed), lux in itertools.product(scenes, args.lux):
        cap = capture(scene, seed, lux, args.lenses)
        noise = noise_of(cap)
        for method in args.methods:
            for net in (False, True) if method != "malvar" else (False,):
                began = time.perf_counter()
                result = demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), method, safety_net=net,
                                       noise=None if method == "malvar" else noise)
                seconds = time.perf_counter() - began
                row = {"scene": scene, "seed": seed, "lux": lux, "method": method, "net": net, "seconds": seconds,
                       "iterations": result.iterations, **scores(result.planes, cap.truth),
                       **colour_of(result.planes, cap.truth)}
                if method == "admm-epi":
                    row["disparity"] = result.parameters["disparity"]
                    row["lam_per_sigma"] = result.parameters["lam"] / result.noise.sigma
                print(json.dumps({k: v for k, v in row.items() if k != "disparity"}), flush=True)
                rows.append(row)
    return rows


def format_table(rows: list[dict], net: bool) -> str:
    """The markdown table of docs/admm.md: centre / mean PSNR per method, epi - malvar, epi - best other, s."""
    cell = {(r["scene"], r["seed"], r["lux"], r["method"]): r for r in rows if r["net"] == net or r["method"] == "malvar"}
    methods = [m for m in OTHERS if any(k[3] == m for k in cell)]
    keys = sorted({k[:3] for k in cell}, key=lambda k: (k[0], k[1], k[2]))
    head = "| scene | seed | lux | " + " | ".join(methods) + " | admm-epi | epi - malvar | epi - best other | " \
        "epi s | uv s | uvst s |"
    lines = [head, "|---" * head.count("|")[:-1] if False else "|---" * (head.count("|") - 1) + "|"]
    for k in keys:
        if (*k, "admm-epi") not in cell:
            continue
        e = cell[(*k, "admm-epi")]
        m = cell[(*k, "malvar")]
        others = [cell[(*k, x)] for x in methods]
        bc = max(o["psnr_center"] for o in others)
        bm = max(o["psnr_mean"] for o in others)
        lines.append(f"| {k[0]} | {k[1]} | {k[2]:g} | " + " | ".join(
            f"{o['psnr_center']:.2f} / {o['psnr_mean']:.2f}" for o in others) +
            f" | {e['psnr_center']:.2f} / {e['psnr_mean']:.2f} | {e['psnr_center'] - m['psnr_center']:+.2f} / "
            f"{e['psnr_mean'] - m['psnr_mean']:+.2f} | {e['psnr_center'] - bc:+.2f} / {e['psnr_mean'] - bm:+.2f} | "
            f"{e['seconds']:.1f} | {cell[(*k, 'admm-uv')]['seconds']:.2f} | {cell[(*k, 'admm-uvst')]['seconds']:.2f} |")
    return "\n".join(lines)


def format_colour_table(rows: list[dict], net: bool) -> str:
    """Mean CIEDE2000 (centre view / mean image) per method; lower is better (tables from before it: none)."""
    cell = {(r["scene"], r["seed"], r["lux"], r["method"]): r for r in rows
            if (r["net"] == net or r["method"] == "malvar") and "de2000_center" in r}
    methods = [m for m in (*OTHERS, "admm-epi") if any(k[3] == m for k in cell)]
    keys = sorted({k[:3] for k in cell if (*k[:3], "admm-epi") in cell})
    head = "| scene | seed | lux | " + " | ".join(methods) + " | epi - best other |"
    lines = [head, "|---" * (head.count("|") - 1) + "|"]
    for k in keys:
        e = cell[(*k, "admm-epi")]
        others = [cell[(*k, m)] for m in methods if m != "admm-epi"]
        lines.append(f"| {k[0]} | {k[1]} | {k[2]:g} | " + " | ".join(
            f"{cell[(*k, m)]['de2000_center']:.3f} / {cell[(*k, m)]['de2000_mean']:.3f}" for m in methods) +
            f" | {e['de2000_center'] - min(o['de2000_center'] for o in others):+.3f} / "
            f"{e['de2000_mean'] - min(o['de2000_mean'] for o in others):+.3f} |")
    return "\n".join(lines)


def run_profile(args):
    """Where admm-epi's time goes on one capture: disparity (with and without the occlusion halves), the ADMM
    iterations at two CG step counts (the difference: the CG steps), and admm-uv / admm-uvst end to end."""
    from lfcl.demosaic.methods import ADMM_DEFAULTS
    from lfcl.depth import estimate_disparity
    from lfcl.solvers.epi import epi_setting

    runtime = get_runtime()
    cap = capture(args.scenes[0], args.seeds[0], args.lux[0], args.lenses)
    noise = noise_of(cap)
    setting = epi_setting(noise.sigma)
    b = runtime.to_device(cap.mosaic)
    x0 = start_for("malvar", runtime, cap, b, noise)
    solver = EpiAdmmSolver(runtime, cap.mosaic.shape, cap.pattern, cap.pitch)
    times: dict = {}

    def best_of(name, fn, repeats=3):
        fn()  # warm: kernels built, buffers allocated
        spans = []
        for _ in range(repeats):
            began = time.perf_counter()
            fn()
            runtime.queue.finish()
            spans.append(time.perf_counter() - began)
        times[name] = min(spans)
        print(f"{name}: {times[name]:.3f} s", flush=True)

    for occ in (True, False):
        best_of(f"disparity occlusion={occ}", lambda occ=occ: estimate_disparity(cap.mosaic, cap.pattern, cap.pitch,
                                                                                  noise=noise, occlusion=occ))
    depth = estimate_disparity(cap.mosaic, cap.pattern, cap.pitch, noise=noise, **epi_depth_options(noise.sigma))
    lam = setting.lam_per_sigma * noise.sigma
    lam_fb = setting.fb_per_lam * lam
    prior = EpiPrior(depth.disparity, depth.confidence if lam_fb > 0 else None, lam_fb=lam_fb)  # as admm-epi runs
    for cg in (1, 5):
        params = AdmmParams(lam=lam, lam_xc=setting.xc_per_lam * lam, rho=ADMM_DEFAULTS["admm-epi"].rho, max_iter=10,
                            cg_steps=cg, cg_tol=0.0)
        best_of(f"admm 10 iterations, {cg} CG steps", lambda params=params: solver.solve(b, x0, params, prior))
    per_step = (times["admm 10 iterations, 5 CG steps"] - times["admm 10 iterations, 1 CG steps"]) / 40
    print(f"one CG step: {per_step * 1e3:.1f} ms; one iteration without its CG steps: "
          f"{(times['admm 10 iterations, 1 CG steps'] / 10 - per_step) * 1e3:.1f} ms")
    for method in ("admm-uv", "admm-uvst", "admm-epi"):
        best_of(f"{method} end to end (net on)", lambda method=method: demosaic_grid(
            cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), method, noise=noise))
    return times


def add_capture_arguments(parser):
    """The captures a research script runs on: --scenes, --seeds, --lux (comma lists), --lenses."""
    parser.add_argument("--scenes", default="charts,deadleaves,finetexture")
    parser.add_argument("--seeds", default="1,2")
    parser.add_argument("--lux", default="0.5,2,12,50")
    parser.add_argument("--lenses", type=int, default=48)


def parse_capture_arguments(args):
    """The lists of :func:`add_capture_arguments`, parsed in place."""
    args.scenes = args.scenes.split(",")
    args.seeds = [int(s) for s in args.seeds.split(",")]
    args.lux = [float(v) for v in args.lux.split(",")]
    return args


def captures_against_malvar(args):
    """Every capture of :func:`parse_capture_arguments`'s lists, with its noise model and Malvar's scores:
    (scene, seed, lux, capture, noise, Malvar's scores)."""
    for scene, seed, lux in itertools.product(args.scenes, args.seeds, args.lux):
        cap = capture(scene, seed, lux, args.lenses)
        malvar = scores(demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "malvar").planes, cap.truth)
        yield scene, seed, lux, cap, noise_of(cap), malvar


def compare_settings(args, name: str, values, apply):
    """admm-epi as ``lfcl process`` runs it under two (or more) values of one setting, ``apply(value)`` putting each in
    place, on every capture of ``args`` (:func:`captures_against_malvar`): per capture and in sum, the centre-view and
    mean-image gains over Malvar, the largest value written (in units of the truth's largest), the iterations and
    seconds (the disparity's apart), and the gains' differences from the first value. Returns, per value, a tuple per
    capture: (centre gain, mean-image gain, largest value, seconds, disparity seconds, iterations, CG steps)."""
    rows = {value: [] for value in values}
    for scene, seed, lux, cap, noise, malvar in captures_against_malvar(args):
        for value in values:
            apply(value)
            result = demosaic_grid(cap.mosaic, cap.pattern, AlignedGrid(cap.pitch), "admm-epi", noise=noise)
            got = scores(result.planes, cap.truth)
            peak = float(np.abs(result.planes).max()) / float(cap.truth.max())
            rows[value].append((got["psnr_center"] - malvar["psnr_center"], got["psnr_mean"] - malvar["psnr_mean"],
                                peak, result.seconds, result.part_seconds["disparity"], result.iterations,
                                result.parameters["cg_steps"]))
            print(f"{scene} seed {seed} {lux:g} lux {name} {value:g}: centre {rows[value][-1][0]:+.3f}, mean image "
                  f"{rows[value][-1][1]:+.3f} dB, largest value {peak:.2f}x the truth's, {result.iterations} "
                  f"iterations, {result.seconds:.2f} s", flush=True)
    for value, v in rows.items():
        v = np.array(v)
        print(f"{name} {value:g}: centre gain mean {v[:, 0].mean():+.3f} worst {v[:, 0].min():+.3f} dB, mean image mean "
              f"{v[:, 1].mean():+.3f} worst {v[:, 1].min():+.3f} dB, largest value {v[:, 2].max():.2f}x the truth's, "
              f"{v[:, 3].mean():.2f} s (disparity {v[:, 4].mean():.3f} s)")
    first = np.array(rows[values[0]])
    for other in values[1:]:
        for column, label in ((0, "centre"), (1, "mean image")):
            diff = np.array(rows[other])[:, column] - first[:, column]
            print(f"{label}, {other:g} - {values[0]:g}: mean {diff.mean():+.3f}, {diff.min():+.3f}..{diff.max():+.3f} dB")
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mode", choices=("trace", "fit", "fast", "table", "format", "profile"))
    parser.add_argument("inputs", nargs="*", help="fit / format: the trace / table JSON files")
    add_capture_arguments(parser)
    parser.add_argument("--c", default="0.3", help="lam / sigma values (trace)")
    parser.add_argument("--f", default="1", help="lam_fb / lam values (trace)")
    parser.add_argument("--xc", default="0", help="lam_xc / lam values (trace): the cross-channel block, 0 for none")
    parser.add_argument("--rho", default="1")
    parser.add_argument("--cg", default="5")
    parser.add_argument("--starts", default="malvar", help="trace: malvar, linear4d, guarded")
    parser.add_argument("--no-net", action="store_true", help="trace: skip the safety-net scores (faster)")
    parser.add_argument("--depth", default="shipped", help="trace: shipped, noocc, trusted, truth")
    parser.add_argument("--iterations", type=int, default=30)
    parser.add_argument("--top", type=int, default=8)
    parser.add_argument("--real", action="store_true", help="table: also the light fields antinous and 2067")
    parser.add_argument("--others", nargs="+", help="fit: table outputs of the other methods on the traced captures "
                        "(the score becomes the worst centre-view gain over the best of them)")
    parser.add_argument("--methods", default=",".join((*OTHERS, "admm-epi")))
    parser.add_argument("--iteration-ms", type=float, default=47.7, help="fast: one iteration outside its CG steps")
    parser.add_argument("--cg-step-ms", type=float, default=22.5, help="fast: one CG step")
    parser.add_argument("--budget", type=float, default=0.5, help="fast: the most time, relative to the shipped rule")
    parser.add_argument("-o", "--output")
    args = parse_capture_arguments(parser.parse_args())
    args.c, args.f, args.xc, args.rho = ([float(v) for v in getattr(args, k).split(",")] for k in ("c", "f", "xc", "rho"))
    args.cg = [int(v) for v in args.cg.split(",")]
    args.starts, args.depth, args.methods = args.starts.split(","), args.depth.split(","), args.methods.split(",")
    if args.mode == "trace":
        payload = {"args": dict(vars(args)), "results": run_trace(args)}
    elif args.mode == "fast":
        payload = {"levels": run_fast(args), "schedule": [dataclasses.asdict(s) for s in EPI_SCHEDULE],
                   "cost_ms": {"iteration": args.iteration_ms, "cg_step": args.cg_step_ms}}
    elif args.mode == "fit":
        payload = {"fitted": run_fit(args), "schedule": [dataclasses.asdict(s) for s in EPI_SCHEDULE]}
    elif args.mode == "profile":
        payload = {"args": dict(vars(args)), "seconds": run_profile(args)}
    elif args.mode == "table":
        payload = {"args": dict(vars(args)), "rows": run_table(args),
                   "schedule": [dataclasses.asdict(s) for s in EPI_SCHEDULE]}
    else:
        rows = []
        for path in args.inputs:
            with open(path) as fh:
                rows += json.load(fh)["rows"]
        for net in (False, True):
            print(f"\nsafety net {'on' if net else 'off'}\n\n" + format_table(rows, net))
        if any("de2000_center" in r for r in rows):
            print("\nmean CIEDE2000, centre view / mean image (safety net on)\n\n" + format_colour_table(rows, True))
        return
    if args.output:
        with open(args.output, "w") as fh:
            json.dump(payload, fh, indent=1, default=float)


if __name__ == "__main__":
    main()

"""`lfcl bench matrix`: every built-in scene and real light field x light level x method, against Malvar.

The "never worse than Malvar" check (issue 18): for each capture (a built-in scene at a seed that no
default was fitted on, or a raw simulated from a real light field in ../shared) and each light level,
run Malvar and each method through the public entry point (:func:`lfcl.evaluation.evaluate.run_method`, the
same call `lfcl process` makes) and print the PSNR of the centre view and of the mean image minus
Malvar's, the worst cell first. Not a timed test: a benchmark to read (BENCHMARKS.md, docs/auto.md).

Each capture runs with each of ``noise``: ``profile`` (the noise model its DNG carries, as most camera DNGs do)
and ``raw`` (the profile dropped: the noise estimated from the raw, as for a LibRaw raw or a DNG without one).
Each row also says how noisy its ground truth is itself (:func:`lfcl.evaluation.evaluate.truth_noise`, as a
share of the sensor's noise): a light field decoded from a real camera (the Lytro frame) carries that camera's
noise, and where it outweighs the simulated sensor's, a method is scored down for removing it.

Example::

    lfcl bench matrix --lenses 48 --lux 0.5,12 --methods admm-uv,auto
"""

from __future__ import annotations

import math
from pathlib import Path

#: Real light fields in the workplace's shared folder, by label (SOURCES.md there); those absent are left out.
REAL_LIGHTFIELDS = {
    "antinous": ("realdata", "hci_epinet", "antinous"),
    "lytro-2067": ("realdata", "lytro_epinet", "2067"),
}
#: The light levels: issue 20's six, and 25 lux inside the band where auto runs its cheaper pick (above about
#: 16 lux for the reference camera, docs/auto.md), which the six sampled only at 50 lux.
LUX = (0.5, 1, 2, 4, 12, 25, 50)
#: Seeds no default or rule of lfcl was fitted on (the fits use seeds 1 and 2, docs/admm.md).
HELD_OUT_SEED = 7
#: Where the methods' noise model comes from (module docstring).
NOISE_SOURCES = ("profile", "raw")


def real_lightfields(shared) -> dict[str, str]:
    """The real light fields present under the workplace's ``shared`` folder, label -> folder."""
    shared = Path(shared)
    found = {}
    for label, parts in REAL_LIGHTFIELDS.items():
        path = shared.joinpath(*parts)
        if path.is_dir():
            found[label] = str(path)
    return found


def captures(scenes, lightfields: dict[str, str], lenses: int, seed: int):
    """(label, simulated_capture kwargs) for every scene and light field."""
    for scene in scenes:
        yield scene, {"scene": scene, "seed": seed}
    for label, path in lightfields.items():
        yield label, {"lightfield": path, "seed": seed}


def run(scenes, lightfields: dict[str, str], lux_levels, methods, *, lenses: int = 48, seed: int = HELD_OUT_SEED,
        noise_sources=NOISE_SOURCES, device=None, progress=None) -> list[dict]:
    """One row per (capture, lux, noise source, method): PSNR (centre, mean) and its gain over Malvar, seconds."""
    import dataclasses

    from ..evaluation.evaluate import run_method, simulated_capture, truth_noise

    unknown = sorted(set(noise_sources) - set(NOISE_SOURCES))
    if unknown or not noise_sources:
        raise ValueError(f"noise sources must be among {', '.join(NOISE_SOURCES)}, got {', '.join(noise_sources)}")
    rows = []
    for label, source in captures(scenes, lightfields, lenses, seed):
        for lux in lux_levels:
            profiled = simulated_capture(lenses, lux, **source)
            malvar = run_method(profiled, "malvar", device=device)
            own_noise = truth_noise(profiled)
            for noise, method in ((n, m) for n in noise_sources for m in methods):
                capture = profiled if noise == "profile" else dataclasses.replace(profiled, noise_profile=None)
                result = run_method(capture, method, device=device)
                row = {"capture": label, "lux": lux, "noise": noise, "method": method,
                       "centre": result["psnr_center"], "mean": result["psnr_mean"],
                       "centre_gain": result["psnr_center"] - malvar["psnr_center"],
                       "mean_gain": result["psnr_mean"] - malvar["psnr_mean"],
                       "seconds": result["seconds"], "malvar_seconds": malvar["seconds"],
                       "net": result["parameters"].get("safety_net", {}).get("lenses_from_malvar"),
                       "truth_noise": own_noise}
                rows.append(row)
                if progress is not None:
                    progress(row)
    return rows


def worst(row: dict) -> float:
    return min(row["centre_gain"], row["mean_gain"])


def format_rows(rows: list[dict]) -> str:
    """The rows as a markdown table, the worst cell (lower of the two gains) first."""
    lines = ["| capture | lux | noise | method | centre - Malvar dB | mean - Malvar dB | centre dB | mean dB | s | "
             "net lenses | truth's own noise |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=worst):
        net = "-" if r["net"] is None else str(r["net"])
        own = "-" if r["truth_noise"] is None else f"{r['truth_noise']:.2f}x"
        lines.append(f"| {r['capture']} | {r['lux']:g} | {r['noise']} | {r['method']} | {r['centre_gain']:+.2f} | "
                     f"{r['mean_gain']:+.2f} "
                     f"| {r['centre']:.2f} | {r['mean']:.2f} | {r['seconds']:.2f} | {net} | {own} |")
    if rows:
        low = min(rows, key=worst)
        lines.append("")
        lines.append(f"worst cell: {low['capture']} at {low['lux']:g} lux, noise from the {low['noise']}, "
                     f"{low['method']}: {worst(low):+.2f} dB "
                     f"({'within' if worst(low) >= -0.1 else 'outside'} Malvar - 0.1 dB)")
        below = [r for r in rows if worst(r) < -0.1]
        noisy = [r for r in below if r["truth_noise"] is not None and r["truth_noise"] >= 1]
        lines.append(f"cells below Malvar - 0.1 dB: {len(below)} of {len(rows)}; of them {len(noisy)} score against a "
                     "truth with more noise of its own than the sensor's (the truth's own noise column)")
    return "\n".join(lines)


def parse_lux(text: str) -> tuple[float, ...]:
    values = tuple(float(v) for v in text.split(",") if v.strip())
    if not values or not all(math.isfinite(v) and v > 0 for v in values):
        raise ValueError(f"--lux must be a comma-separated list of positive numbers, got {text!r}")
    return values

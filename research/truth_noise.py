"""How noisy is each capture's ground truth itself, and what does a truth with noise of its own do to the scores?
(docs/auto.md, "A truth with noise of its own"). Not shipped in the wheel.

    python research/truth_noise.py -o research/truth_noise.json

Two tables:

1. ``truth``: lfcl.evaluation.evaluate.truth_noise (the raw noise estimate run on the truth's noise-free mosaic,
   over the sensor's sigma) for every capture of `lfcl bench matrix` (held-out seed 7, 48x48 lenses) at each
   light level. The rendered scenes' truths are noise-free; the Lytro frame was decoded from a real camera.
2. ``views``: how the truth's fine detail relates from view to view, for the real light fields and the control's
   truth: the correlation of the high-pass (a 3x3 Laplacian) of the centre view with its neighbour (4, 5) and with
   the corner view (0, 0), and the mean image's high-pass over the centre view's. A scene off the focal plane
   shifts its texture from view to view (low neighbour correlation) and blurs it in the mean image (a small
   share); grain shared by neighbouring views (a decoder that interpolates between them) correlates them.
3. ``control``: the rendered ``antinous`` light field with camera-like grain baked into its truth (multiplicative,
   ~1 pixel wide in (s, t), shared by neighbouring views like the Lytro frame's: a Gaussian of 0.6 views in
   (u, v); its amplitude set so that truth_noise reads what it reads on the Lytro frame at 12 lux), simulated at
   2, 12 and 50 lux. Each method's gain over Malvar is scored twice: against the grainy truth (what the matrix
   scores) and against the clean one.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np
import scipy.ndimage

SHARED = Path(__file__).resolve().parents[2] / "shared"
LUX = (0.5, 1, 2, 4, 12, 50)
CONTROL_LUX = (2, 12, 50)
METHODS = ("auto", "admm-epi", "admm-uvst")
LENSES = 48


def truth_table(shared: Path, lenses: int) -> list[dict]:
    from lfcl.bench.matrix import HELD_OUT_SEED, captures, real_lightfields
    from lfcl.evaluation.evaluate import simulated_capture, truth_noise
    from lfcl.sim.scenes import SCENES

    rows = []
    for label, source in captures(SCENES, real_lightfields(shared), lenses, HELD_OUT_SEED):
        for lux in LUX:
            ratio = truth_noise(simulated_capture(lenses, lux, **source))
            rows.append({"capture": label, "lux": lux, "truth_noise": ratio})
            print(f"truth  {label:12s} {lux:5g} lux  truth's own noise {ratio:.2f}x the sensor's", flush=True)
    return rows


#: The control's grain: its width in (s, t) pixels and in (u, v) views (0.6: neighbouring views correlate ~0.5).
GRAIN_PIXELS, GRAIN_VIEWS = 0.7, 0.6


def grainy(clean: np.ndarray, amplitude: float, seed: int = 123) -> np.ndarray:
    """``clean`` [S, T, U, V, 3] times (1 + grain): the grain ~1 pixel wide in (s, t), shared by neighbouring views,
    the same in the three colours, its rms ``amplitude``."""
    grain = np.random.default_rng(seed).standard_normal(clean.shape[:4]).astype(np.float32)
    grain = scipy.ndimage.gaussian_filter(grain, (GRAIN_PIXELS, GRAIN_PIXELS, GRAIN_VIEWS, GRAIN_VIEWS))
    grain *= amplitude / grain.std()
    return np.clip(clean * (1 + grain[..., None]), 0, None).astype(np.float32)


HIGH_PASS = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float64)


def view_structure(lightfield: np.ndarray) -> dict:
    """The high-pass correlations of the centre view with its neighbour and with the corner view, and the mean
    image's high-pass rms over the centre view's (grey, [S, T, U, V, 3] input)."""
    grey = np.asarray(lightfield, np.float64).mean(axis=-1)
    U, V = grey.shape[2:]
    u0, v0 = U // 2, V // 2

    def high(image):
        return scipy.ndimage.convolve(image, HIGH_PASS)[1:-1, 1:-1].ravel()

    centre = high(grey[:, :, u0, v0])
    return {"neighbour_correlation": float(np.corrcoef(centre, high(grey[:, :, u0, v0 + 1]))[0, 1]),
            "corner_correlation": float(np.corrcoef(centre, high(grey[:, :, 0, 0]))[0, 1]),
            "mean_image_share": float(high(grey.mean(axis=(2, 3))).std() / centre.std())}


def views_table(shared: Path, lenses: int, control_truth: np.ndarray) -> list[dict]:
    from lfcl.bench.matrix import real_lightfields
    from lfcl.sim.lightfield import load_lightfield

    rows = []
    fields = {label: load_lightfield(path, (lenses, lenses)) for label, path in real_lightfields(shared).items()}
    fields["control (antinous + grain)"] = control_truth
    for label, field in fields.items():
        row = {"light field": label, **view_structure(field)}
        rows.append(row)
        print(f"views  {label:28s} high-pass correlation with the neighbour {row['neighbour_correlation']:+.2f}, "
              f"with the corner {row['corner_correlation']:+.2f}; mean image / centre view {row['mean_image_share']:.2f}",
              flush=True)
    return rows


def matched_amplitude(clean: np.ndarray, target: float, lux: float = 12) -> float:
    """The grain amplitude whose truth_noise at ``lux`` reads ``target`` (it grows linearly with the amplitude)."""
    from lfcl.evaluation.evaluate import simulation_capture, truth_noise
    from lfcl.sim import simulate

    probe = 0.05
    ratio = truth_noise(simulation_capture(simulate(lightfield=grainy(clean, probe), lux=lux, seed=7)))
    return probe * target / ratio


def control(shared: Path, lenses: int, target: float) -> dict:
    from lfcl.evaluation.evaluate import run_method, simulation_capture, truth_noise
    from lfcl.evaluation.metrics import lightfield_scores
    from lfcl.sim import simulate
    from lfcl.sim.lightfield import load_lightfield

    clean = load_lightfield(shared / "realdata" / "hci_epinet" / "antinous", (lenses, lenses)).astype(np.float32)
    amplitude = matched_amplitude(clean, target)
    noisy = grainy(clean, amplitude)
    views = views_table(shared, lenses, noisy)
    rows = []
    for lux in CONTROL_LUX:
        sim = simulate(lightfield=noisy, lux=lux, seed=7)
        unclipped = sim.truth < 0.9
        scale = float(np.median(sim.truth[unclipped] / np.maximum(noisy[unclipped], 1e-9)))
        clean_truth = np.minimum(clean * scale, 1.0)
        capture = simulation_capture(sim)
        ratio = truth_noise(capture)
        malvar = run_method(capture, "malvar")
        malvar_clean = lightfield_scores(malvar["lightfield"], clean_truth)
        for noise in ("profile", "raw"):
            source = capture if noise == "profile" else dataclasses.replace(capture, noise_profile=None)
            for method in METHODS:
                result = run_method(source, method)
                scored = lightfield_scores(result["lightfield"], clean_truth)
                row = {"lux": lux, "noise": noise, "method": method, "truth_noise": ratio,
                       "grainy_centre": result["psnr_center"] - malvar["psnr_center"],
                       "grainy_mean": result["psnr_mean"] - malvar["psnr_mean"],
                       "clean_centre": scored["psnr_center"] - malvar_clean["psnr_center"],
                       "clean_mean": scored["psnr_mean"] - malvar_clean["psnr_mean"]}
                rows.append(row)
                print(f"control {lux:3g} lux ({ratio:.2f}x) {noise:7s} {method:9s} gain over Malvar against the "
                      f"grainy truth {row['grainy_centre']:+.2f} / {row['grainy_mean']:+.2f}, against the clean "
                      f"truth {row['clean_centre']:+.2f} / {row['clean_mean']:+.2f} (centre / mean image)", flush=True)
    return {"amplitude": amplitude, "target_truth_noise_at_12_lux": target, "grain_pixels": GRAIN_PIXELS,
            "grain_views": GRAIN_VIEWS, "views": views, "rows": rows}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--lenses", type=int, default=LENSES)
    parser.add_argument("-o", "--output", type=Path, default=Path("research/truth_noise.json"))
    args = parser.parse_args(argv)
    truth = truth_table(args.shared, args.lenses)
    lytro = [r["truth_noise"] for r in truth if r["capture"] == "lytro-2067" and r["lux"] == 12]
    if not lytro:
        raise SystemExit(f"the Lytro frame is not under {args.shared}: the control matches its truth's noise")
    result = {"lenses": args.lenses, "truth": truth, "control": control(args.shared, args.lenses, lytro[0])}
    args.output.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()

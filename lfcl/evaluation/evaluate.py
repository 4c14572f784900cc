"""The paper's evaluation: methods scored against a simulated capture's ground truth.

A capture folder (``lfcl simulate``) holds raw.dng, meta.json and truth.npy. For
each method we demosaic raw.dng, reshape to [S, T, U, V, 3] and score PSNR on the
centre view and the mean image (Tables 1-2), with seconds and iterations, and the
colour-artefact metrics of docs/colour-metrics.md (CIEDE2000 mean and 95th
percentile, false colour on grey edges, chroma error at high frequencies; the
paper's section 5 claim); the figures are error maps (Figs 6-7), zoomed crops
(Figs 8-9), PSNR and colour errors against illumination (Fig. 10) and
ground-truth gradients (Fig. 5).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from ..demosaic.driver import demosaic_grid
from ..demosaic.names import METHODS, method_spec, parse_method_spec
from ..grid.model import AlignedGrid
from ..io.raw import read_mosaic
from ..layout import DIMS, LightFieldShape, planes_to_exchange
from . import plots
from .metrics import centre_view, lightfield_colour_scores, lightfield_scores, mean_image


@dataclasses.dataclass
class Capture:
    """A simulated capture: normalised mosaic, its pattern, lens pitch and ground truth."""

    directory: Path
    mosaic: np.ndarray
    pattern: str
    pitch: tuple[int, int]
    truth: np.ndarray
    meta: dict
    noise_profile: object = None


def load_capture(directory) -> Capture:
    directory = Path(directory)
    for name in ("raw.dng", "meta.json", "truth.npy"):
        if not (directory / name).is_file():
            raise ValueError(f"{directory} is not a capture folder: {name} is missing (make one with `lfcl simulate`)")
    try:
        meta = json.loads((directory / "meta.json").read_text())
    except ValueError as error:
        raise ValueError(f"{directory / 'meta.json'} is not valid JSON ({error})") from None
    if meta.get("mode") == "grid" or not isinstance(meta.get("pitch"), list):
        grid = meta.get("lenslet", {}).get("grid", "another") if isinstance(meta.get("lenslet"), dict) else "another"
        raise ValueError(f"{directory} is a capture of a {grid} lens grid (lfcl simulate --grid): lfcl evaluate scores "
                         "captures of the aligned simulator (no --grid); calibrate the white image and run lfcl process "
                         "--calibration on it instead (docs/geometry.md)")
    pitch = tuple(int(p) for p in meta["pitch"])
    raw = read_mosaic(directory / "raw.dng")
    truth = np.load(directory / "truth.npy")
    shape = LightFieldShape.from_sensor(raw.data.shape, pitch)
    expected = (shape.S, shape.T, shape.U, shape.V, 3)
    if truth.shape != expected:
        raise ValueError(f"truth.npy has shape {truth.shape} but raw.dng holds a light field of {expected}")
    H, W = shape.sensor_shape
    return Capture(directory, raw.data[:H, :W], raw.pattern, pitch, truth, meta, raw.noise_profile)


def run_method(capture: Capture, method: str, device=None, **overrides) -> dict:
    """Demosaic the capture with ``method`` (``METHOD[:START]``, lfcl.demosaic.names.parse_method_spec); scores,
    timings and the light field."""
    from ..noise.model import from_noise_profile

    label, (method, start) = method, parse_method_spec(method)
    if start is not None:
        overrides = {**overrides, "start": start}
    noise = None
    if capture.noise_profile is not None and method != "malvar":
        noise = from_noise_profile(capture.noise_profile, capture.mosaic)
    result = demosaic_grid(capture.mosaic, capture.pattern, AlignedGrid(capture.pitch), method, device=device,
                           noise=noise, **overrides)
    lightfield = planes_to_exchange(result.planes, LightFieldShape.from_exchange(capture.truth))
    return {
        "method": label,
        **lightfield_scores(lightfield, capture.truth),
        **lightfield_colour_scores(lightfield, capture.truth),
        "seconds": result.seconds,
        "iterations": result.iterations,
        "stop_reason": result.stop_reason,
        "parameters": result.parameters,
        "noise_sigma": None if result.noise is None else result.noise.sigma,
        "lightfield": lightfield,
    }


# (key, row label, format) of the colour rows of the tables, per view (docs/colour-metrics.md).
COLOUR_ROWS = (
    ("de2000_mean", "ΔE00 mean", "{:.2f}"),
    ("de2000_p95", "ΔE00 p95", "{:.2f}"),
    ("false_colour", "False colour", "{:.2f}"),
    ("hf_chroma_error", "HF chroma error", "{:.2f}"),
)
VIEW_LABELS = (("center", "centre"), ("mean", "mean image"))


def _cell(value, fmt: str = "{:.2f}") -> str:
    return "n/a" if value is None else fmt.format(value)


def format_table(rows: list[dict], title: str) -> str:
    """The paper's table layout: methods as columns, Center / Mean Image as rows (Markdown).

    Below PSNR, the colour-artefact rows (ΔE00 mean and p95, false colour, HF chroma error) for
    the centre view and the mean image, when the rows carry them; "n/a" where undefined.
    """
    names = [r["method"] for r in rows]
    lines = [f"**{title}**", "", "| | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    lines.append("| Center | " + " | ".join(f"{r['psnr_center']:.2f} dB" for r in rows) + " |")
    lines.append("| Mean Image | " + " | ".join(f"{r['psnr_mean']:.2f} dB" for r in rows) + " |")
    for view, view_label in VIEW_LABELS:
        for key, label, fmt in COLOUR_ROWS:
            if all(f"{key}_{view}" in r for r in rows):
                lines.append(f"| {label} ({view_label}) | " + " | ".join(_cell(r[f"{key}_{view}"], fmt) for r in rows) + " |")
    lines.append("| Seconds | " + " | ".join(f"{r['seconds']:.2f}" for r in rows) + " |")
    lines.append("| Iterations | " + " | ".join(str(r["iterations"]) for r in rows) + " |")
    return "\n".join(lines)


def busiest_box(image: np.ndarray, size: int) -> tuple[int, int, int, int]:
    """The size x size window with the most gradient energy: where artefacts show (Figs 8-9)."""
    grey = image.mean(axis=-1)
    energy = np.abs(np.diff(grey, axis=0))[:, :-1] + np.abs(np.diff(grey, axis=1))[:-1, :]
    size = min(size, energy.shape[0], energy.shape[1])
    integral = np.pad(energy, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    sums = integral[size:, size:] - integral[:-size, size:] - integral[size:, :-size] + integral[:-size, :-size]
    r, c = np.unravel_index(int(np.argmax(sums)), sums.shape)
    return int(r), int(r + size), int(c), int(c + size)


def gradient_sparsity(truth: np.ndarray, threshold: float = 0.01) -> dict:
    """Per dim: mean |gradient| and the share of gradients below ``threshold`` (Fig. 5)."""
    axes = {"s": 0, "t": 1, "u": 2, "v": 3}
    report = {}
    for d in DIMS:
        grad = np.abs(np.diff(truth, axis=axes[d]))
        report[d] = {"mean_abs": float(grad.mean()), "share_below": float((grad < threshold).mean())}
    return report


def write_figures(capture: Capture, results: list[dict], out: Path, label: str) -> list[str]:
    """Error maps and zoomed crops of the centre view and the mean image."""
    written = []
    for view_name, view in (("center", centre_view), ("mean", mean_image)):
        truth = view(capture.truth)
        estimates = {r["method"]: view(r["lightfield"]) for r in results}
        written.append(str(plots.error_maps(truth, estimates, out / f"error_{view_name}.png",
                                            f"{label}: {view_name} view")))
        box = busiest_box(truth, max(16, min(truth.shape[:2]) // 4))
        written.append(str(plots.zoomed_crops(truth, estimates, box, out / f"crops_{view_name}.png",
                                              f"{label}: {view_name} view, rows {box[0]}-{box[1]}, cols {box[2]}-{box[3]}")))
    return written


def check_methods(methods) -> list[str]:
    """Methods, each ``METHOD[:START]`` (lfcl.demosaic.names.parse_method_spec; a start with an ADMM method only)."""
    from ..demosaic.methods import ADMM_DEFAULTS, STARTS

    methods = [m.strip() for m in methods if m.strip()]
    if not methods:
        raise ValueError(f"no methods given: choose from {', '.join(METHODS)}")
    checked = []
    for label in methods:
        name, start = parse_method_spec(label)
        if start is not None and name not in ADMM_DEFAULTS:
            raise ValueError(f"{label!r}: a start ({', '.join(STARTS)}) goes with an ADMM method only, as "
                             f"admm-uv-xc:linear4d")
        checked.append(method_spec(name, start))
    return checked


def capture_in_memory(meta: dict, lux: float) -> Capture:
    """Re-simulate a capture folder's scene at another illumination (same seed and camera)."""
    from ..sim import simulate

    scene = meta["scene"]
    kwargs = dict(lenses=tuple(meta["lenses"]) if meta.get("lenses") else None, pitch=int(meta["pitch"][0]), pattern=meta["pattern"],
                  lux=lux, seed=int(meta["seed"]), vignetting=bool(meta.get("vignetting", {}).get("enabled", False)))
    if scene.get("kind") == "scene":
        sim = simulate(scene["name"], texture=scene.get("texture"), **kwargs)
    elif scene.get("kind") == "lightfield" and scene.get("path"):
        kwargs.pop("pitch")
        sim = simulate(lightfield=scene["path"], **kwargs)
    else:
        raise ValueError(f"cannot re-simulate a capture made from {scene.get('kind')!r} for a lux sweep")
    return simulation_capture(sim)


def simulation_capture(sim) -> Capture:
    """A simulated capture (lfcl.sim.simulate's result) as a Capture in memory, its DNG noise
    profile (one pair per colour plane) as a raw file of it would carry."""
    return Capture(Path("."), sim.normalised_raw(), sim.pattern, tuple(sim.geometry.pitch), sim.truth, sim.meta,
                   list(sim.sensor.noise_profile()) * 3)


def truth_noise(capture: Capture) -> float | None:
    """The ground truth's own noise as a share of the sensor's (``None`` without a noise profile).

    The raw noise estimate (:func:`lfcl.noise.model.estimate_noise`, what a raw without a profile gets) run on
    the truth's noise-free mosaic, over the DNG profile's sigma. Texture can only inflate it (as it does the raw's
    estimate): at 48x48 lenses the rendered scenes read 0 (charts, deadleaves) to 1.3 (finetexture at 50 lux), on
    a few lenses with no flat ones far more; a light field decoded from a real camera carries that camera's noise,
    view to view, and a method that removes noise is scored down for removing it (docs/auto.md, "A truth with
    noise of its own").
    """
    from ..noise.model import estimate_noise, from_noise_profile
    from ..sim.geometry import LensletGeometry

    if capture.noise_profile is None:
        return None
    S, T, U, V, _ = capture.truth.shape
    clean = LensletGeometry((S, T), (U, V)).mosaic(capture.truth, capture.pattern).astype(np.float32)
    own = estimate_noise(clean, capture.pattern, capture.pitch)
    return own.sigma / from_noise_profile(capture.noise_profile, capture.mosaic).sigma


def simulated_capture(lenses: int | None, lux: float, seed: int = 0, scene: str = "charts",
                      lightfield: str | None = None, texture: str | None = None) -> Capture:
    """A square capture of ``lenses`` x ``lenses`` 9x9 lenses (GRBG) of a built-in scene (its planes
    textured with the image ``texture``, if given), or of a rendered or decoded light field
    (``lightfield``: an HCI-layout folder or .npy), in memory.
    ``lenses=None`` (light fields only): every lens of the light field, its full frame."""
    source = {"kind": "lightfield", "path": lightfield} if lightfield else {"kind": "scene", "name": scene,
                                                                           "texture": texture}
    if lenses is None and not lightfield:
        raise ValueError(f"a built-in scene ({scene}) needs a number of lenses; only a light field has a full frame")
    meta = {"scene": source, "lenses": None if lenses is None else [lenses] * 2, "pitch": [9, 9], "pattern": "GRBG", "seed": seed}
    return capture_in_memory(meta, lux)


def centre_gradient_images(truth: np.ndarray) -> dict:
    """The centre view and |gradient| of the light field along each dim, at the centre view."""
    _, _, U, V, _ = truth.shape
    u0, v0 = U // 2, V // 2
    grey = truth.mean(axis=-1)
    images = {"ground truth": np.clip(centre_view(truth).mean(axis=-1) / max(float(grey.max()), 1e-6), 0, 1)}
    images["u"] = np.abs(grey[:, :, min(u0 + 1, U - 1), v0] - grey[:, :, u0, v0])
    images["v"] = np.abs(grey[:, :, u0, min(v0 + 1, V - 1)] - grey[:, :, u0, v0])
    images["s"] = np.abs(np.diff(grey[:, :, u0, v0], axis=0, append=grey[-1:, :, u0, v0]))
    images["t"] = np.abs(np.diff(grey[:, :, u0, v0], axis=1, append=grey[:, -1:, u0, v0]))
    return images


def format_sweep(sweep: list[dict]) -> str:
    """PSNR against illumination, centre / mean per method (paper, Fig. 10 as a table), then the
    colour-artefact metrics against illumination, one table per view."""
    methods = [r["method"] for r in sweep[0]["results"]]
    header = ["| lux | " + " | ".join(methods) + " |", "|---" * (len(methods) + 1) + "|"]
    lines = ["**PSNR against illumination** (centre / mean, dB)", "", *header]
    for entry in sweep:
        cells = [f"{r['psnr_center']:.2f} / {r['psnr_mean']:.2f}" for r in entry["results"]]
        lines.append(f"| {entry['lux']:g} | " + " | ".join(cells) + " |")
    if all("de2000_mean_center" in r for e in sweep for r in e["results"]):
        for view, view_label in VIEW_LABELS:
            title = (f"**Colour errors against illumination, {view_label}** "
                     "(ΔE00 mean / ΔE00 p95 / false colour / HF chroma error)")
            lines += ["", title, "", *header]
            for entry in sweep:
                cells = [" / ".join(_cell(r[f"{key}_{view}"]) for key, _, _ in COLOUR_ROWS) for r in entry["results"]]
                lines.append(f"| {entry['lux']:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot_sweep(sweep: list[dict], path, label: str):
    lux = [e["lux"] for e in sweep]
    methods = [r["method"] for r in sweep[0]["results"]]
    series = {}
    for view in ("center", "mean"):
        for i, m in enumerate(methods):
            series[f"{m} ({view})"] = [e["results"][i][f"psnr_{view}"] for e in sweep]
    return plots.psnr_curves(lux, series, path, "mean illuminance (lux)", "PSNR (dB)", f"{label}: PSNR vs illumination")


def plot_colour_sweep(sweep: list[dict], path, label: str):
    """ΔE00 mean, false colour and HF chroma error against illumination: one panel each,
    centre view solid, mean image dashed, one colour per method."""
    import matplotlib.pyplot as plt

    lux = [e["lux"] for e in sweep]
    methods = [r["method"] for r in sweep[0]["results"]]
    panels = [("de2000_mean", "ΔE00 mean"), ("false_colour", "false colour (Δa*b*, grey edges)"),
              ("hf_chroma_error", "HF chroma error (Δa*b*)")]
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4), squeeze=False)
    legend_drawn = False
    for ax, (key, title) in zip(axes[0], panels):
        drawn = False
        for i, m in enumerate(methods):
            for view, style, marker in (("center", "-", "o"), ("mean", "--", "s")):
                ys = [e["results"][i][f"{key}_{view}"] for e in sweep]
                if all(y is None for y in ys):
                    continue
                ax.plot(lux, [np.nan if y is None else y for y in ys], style, marker=marker, color=f"C{i}",
                        label=f"{m} ({view})")
                drawn = True
        ax.set_xscale("log")
        ax.set_xlabel("mean illuminance (lux)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        if drawn and not legend_drawn:
            ax.legend(fontsize=7)
            legend_drawn = True
        elif not drawn:
            ax.text(0.5, 0.5, "n/a: too few grey high-contrast pixels", ha="center", va="center",
                    transform=ax.transAxes)
    fig.suptitle(f"{label}: colour errors vs illumination (centre solid, mean image dashed)", y=1.03)
    return plots._save(fig, path)

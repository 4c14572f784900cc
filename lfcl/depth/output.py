"""The ``depth`` output: ``depth.exr``, ``depth_confidence.exr`` and ``depth.png`` (docs/outputs.md).

``depth.exr``: one float32 channel at lens resolution [S, T], the disparity d in lenses per
view step, HCI's sign (lfcl/depth/estimate.py). ``depth_confidence.exr``: one channel in [0, 1]
(0 = unknown). ``depth.png``: an 8-bit preview, the disparity through a matplotlib colour map
over the range in its metadata (``preview_range``: that of the lenses the estimate is sure of), each lens's
colour darkened by how unsure it is (:data:`UNSURE_BRIGHTNESS` at confidence 0). Every file records units, sign, search
range and the estimator's options as ``lfcl:`` attributes (lfcl.io.images.write_image); each is
written atomically (temporary name, then rename).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

COLORMAP = "viridis"
FILES = ("depth.exr", "depth_confidence.exr", "depth.png")
#: The preview's range is that of the lenses with at least this confidence, where they are at least
#: :data:`SURE_SHARE` of the map (else of every lens). A flat, texture-less lens takes any candidate (the search
#: range's ends as often as not), so over every lens the range was the whole search range: at 500x500 lenses
#: (charts, 2 lux, 45 % of the lenses below confidence 0.1) the 1st..99th percentile was -2..2 lenses, and the
#: scene's planes (-0.25..0.33) all came out one green.
SURE = 0.5
SURE_SHARE = 0.01
#: A lens's colour is scaled by ``UNSURE_BRIGHTNESS + (1 - UNSURE_BRIGHTNESS) * confidence``: the unknown lenses
#: recede, as the confidence map would show them, and the colour stays readable where the estimate is unsure but
#: right (textured lenses in bright light often are, docs/depth.md).
UNSURE_BRIGHTNESS = 0.2


def preview_range(depth) -> tuple[float, float]:
    """The colour map's range: the 1st..99th percentile of the disparity of the lenses of confidence >= :data:`SURE`
    (every lens where those are fewer than :data:`SURE_SHARE`; a flat map gets +-0.5 about it)."""
    d = np.asarray(depth.disparity, dtype=np.float64)
    sure = np.asarray(depth.confidence) >= SURE
    if sure.sum() >= max(1, SURE_SHARE * d.size):
        d = d[sure]
    lo, hi = (float(v) for v in np.percentile(d, [1, 99]))
    if not hi > lo:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi


def preview(depth, value_range=None) -> np.ndarray:
    """The colour-mapped disparity ``(S, T, 3)`` float32 in [0, 1] (sRGB-encoded colours of the map), each lens
    darkened by its confidence (:data:`UNSURE_BRIGHTNESS`)."""
    from matplotlib import colormaps

    lo, hi = preview_range(depth) if value_range is None else value_range
    scaled = np.clip((np.asarray(depth.disparity, np.float64) - lo) / (hi - lo), 0.0, 1.0)
    brightness = UNSURE_BRIGHTNESS + (1.0 - UNSURE_BRIGHTNESS) * np.clip(np.asarray(depth.confidence, np.float64), 0, 1)
    return np.ascontiguousarray(colormaps[COLORMAP](scaled)[..., :3] * brightness[..., None], dtype=np.float32)


def depth_files(depth, metadata: dict | None = None) -> list[tuple[str, np.ndarray, dict]]:
    """``(name, image, metadata)`` of the three files, nothing written."""
    described = depth.as_dict()
    described.pop("seconds")  # the files' headers hold no timings: the same raw and options give the same bytes
    base = {**(metadata or {}), "output": "depth", "depth": described}
    lo, hi = preview_range(depth)
    return [
        ("depth.exr", depth.disparity, {**base, "channel": "disparity d, lenses per view step (one float32 channel)"}),
        ("depth_confidence.exr", depth.confidence,
         {**base, "channel": "confidence in [0, 1], 0 = unknown (flat, occluded, saturated; one float32 channel)"}),
        ("depth.png", preview(depth, (lo, hi)),
         {**base, "encoding": f"8-bit preview: disparity through matplotlib's {COLORMAP} over preview_range (the "
                              f"1st..99th percentile of the lenses of confidence >= {SURE}), each colour times "
                              f"{UNSURE_BRIGHTNESS} + {1 - UNSURE_BRIGHTNESS:g} confidence",
          "preview_range": [lo, hi], "colormap": COLORMAP, "unsure_brightness": UNSURE_BRIGHTNESS}),
    ]


def write_depth(out_dir, depth, metadata: dict | None = None) -> list[Path]:
    """Write the three files into ``out_dir`` (each atomically); returns their paths."""
    from ..io.images import write_image

    out_dir = Path(out_dir)
    return [write_image(out_dir / name, image, meta) for name, image, meta in depth_files(depth, metadata)]


def depth_from_mosaic(mosaic, geometry: dict, device=None, **options):
    """The disparity map of a decoded raw (:class:`lfcl.io.raw.Mosaic`) on the pipeline's lens grid.

    ``geometry`` is the Grid stage's ``metadata["geometry"]``: an ``aligned-square`` grid (``pitch``,
    ``lenses``, ``first_lens_pixel``); other grids are refused (``ValueError``). The noise model is
    the raw's NoiseProfile where it has one, else estimated from the raw.
    """
    if geometry.get("grid") != "aligned-square":
        raise ValueError(f"the depth output needs an aligned square lens grid; this one is {geometry.get('grid')!r} "
                         "(rotated, non-integer-pitch and hexagonal grids are not supported yet)")
    from ..noise.model import from_noise_profile
    from .estimate import estimate_disparity

    U, V = (int(p) for p in geometry["pitch"])
    S, T = (int(n) for n in geometry["lenses"])
    r0, c0 = (int(n) for n in geometry.get("first_lens_pixel", (0, 0)))
    data = np.asarray(mosaic.data)[r0:r0 + S * U, c0:c0 + T * V]
    noise = None if mosaic.noise_profile is None else from_noise_profile(mosaic.noise_profile, data)
    return estimate_disparity(data, mosaic.pattern, (U, V), origin=(r0, c0), noise=noise, device=device, **options)

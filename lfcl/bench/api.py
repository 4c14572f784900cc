"""`lfcl bench api`: the public calls users make, timed against their published peer in the same run.

``lfcl.malvar(mosaic, pattern)`` takes a host (H, W) mosaic and returns a host (H, W, 3) image, copies
and transfers included, against colour-demosaicing's ``demosaicing_CFA_Bayer_Malvar2004`` on the same
mosaic. ``lfcl.lightfield(mosaic, pattern=..., pitch=9, method="malvar")`` returns the light field
[S, T, U, V, 3] of the same mosaic (a 9x9-lens grid), against the peer's image cut into that layout with
numpy (what a user without lfcl would write). Medians of ``repeats`` calls each after a warm-up, and
their ratios (issue 21's target: >= 10x at the paper's 4500x4500 sensor). BENCHMARKS.md has figures.
"""

from __future__ import annotations

import numpy as np

from .timing import time_calls

PATTERN = "GRBG"
PITCH = 9


def _exchange(image: np.ndarray, pitch: int) -> np.ndarray:
    """An (H, W, 3) image of whole lenses as [S, T, U, V, 3]."""
    H, W, _ = image.shape
    return np.ascontiguousarray(image.reshape(H // pitch, pitch, W // pitch, pitch, 3).transpose(0, 2, 1, 3, 4))


def run(height: int, width: int, repeats: int = 3, device=None) -> dict:
    """Median seconds of lfcl.malvar and lfcl.lightfield against colour-demosaicing's Malvar2004 (and that
    image cut into the light-field layout) on one random mosaic, and the ratios."""
    import lfcl
    from lfcl.device import get_runtime

    from .pareto import _colour_demosaicing

    if height % PITCH or width % PITCH:
        raise ValueError(f"the mosaic must be whole {PITCH}x{PITCH} lenses, got {height}x{width}")
    peer = _colour_demosaicing()
    runtime = get_runtime(device)
    mosaic = np.random.default_rng(0).random((height, width), dtype=np.float32)
    ours = time_calls(lambda: lfcl.malvar(mosaic, PATTERN, device=device), repeats)
    theirs = time_calls(lambda: peer(mosaic, PATTERN), repeats)
    ours_lf = time_calls(lambda: lfcl.lightfield(mosaic, pattern=PATTERN, pitch=PITCH, method="malvar",
                                                 device=device), repeats)
    theirs_lf = time_calls(lambda: _exchange(peer(mosaic, PATTERN), PITCH), repeats)
    return {"device": runtime.name, "size": [height, width], "repeats": repeats,
            "lfcl_malvar_seconds": ours.median, "colour_demosaicing_seconds": theirs.median,
            "speedup": theirs.median / ours.median,
            "lfcl_lightfield_seconds": ours_lf.median, "colour_demosaicing_lightfield_seconds": theirs_lf.median,
            "lightfield_speedup": theirs_lf.median / ours_lf.median}


def format_report(report: dict) -> str:
    h, w = report["size"]
    return (f"{h}x{w} mosaic on {report['device']}, median of {report['repeats']}:\n"
            f"  lfcl.malvar (host in, host out)                  {report['lfcl_malvar_seconds']:.3f} s\n"
            f"  colour-demosaicing Malvar2004                    {report['colour_demosaicing_seconds']:.3f} s\n"
            f"  speed-up                                         x{report['speedup']:.1f}\n"
            f"  lfcl.lightfield(method='malvar', pitch={PITCH})         {report['lfcl_lightfield_seconds']:.3f} s\n"
            f"  colour-demosaicing Malvar2004 + numpy [S,T,U,V,3] {report['colour_demosaicing_lightfield_seconds']:.3f} s\n"
            f"  speed-up                                         x{report['lightfield_speedup']:.1f}")

"""`lfcl bench api`: the public calls users make, timed against their published peer in the same run.

``lfcl.malvar(mosaic, pattern)`` takes a host (H, W) mosaic and returns a host (H, W, 3) image, copies
and transfers included, against colour-demosaicing's ``demosaicing_CFA_Bayer_Malvar2004`` on the same
mosaic: the median of ``repeats`` calls each after a warm-up, and their ratio (issue 21's target: >= 10x
at the paper's 4500x4500 sensor). BENCHMARKS.md has measured figures.
"""

from __future__ import annotations

import numpy as np

from .timing import time_calls

PATTERN = "GRBG"


def run(height: int, width: int, repeats: int = 3, device=None) -> dict:
    """Median seconds of lfcl.malvar and of colour-demosaicing's Malvar2004 on one random mosaic, and the ratio."""
    import lfcl
    from lfcl.device import get_runtime

    from .pareto import _colour_demosaicing

    peer = _colour_demosaicing()
    runtime = get_runtime(device)
    mosaic = np.random.default_rng(0).random((height, width), dtype=np.float32)
    ours = time_calls(lambda: lfcl.malvar(mosaic, PATTERN, device=device), repeats)
    theirs = time_calls(lambda: peer(mosaic, PATTERN), repeats)
    return {"device": runtime.name, "size": [height, width], "repeats": repeats,
            "lfcl_malvar_seconds": ours.median, "colour_demosaicing_seconds": theirs.median,
            "speedup": theirs.median / ours.median}


def format_report(report: dict) -> str:
    h, w = report["size"]
    return (f"{h}x{w} mosaic on {report['device']}, median of {report['repeats']}:\n"
            f"  lfcl.malvar (host in, host out)            {report['lfcl_malvar_seconds']:.3f} s\n"
            f"  colour-demosaicing Malvar2004              {report['colour_demosaicing_seconds']:.3f} s\n"
            f"  speed-up                                   x{report['speedup']:.1f}")

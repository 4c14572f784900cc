"""Disparity from the lenslet raw (docs/depth.md): a cost volume along the epipolar lines on the
device (lfcl/kernels/depth.cl, numpy twin :func:`lfcl.depth.cost.cost_volume_np`), aggregation, sub-step
refinement, a confidence and confidence-weighted smoothing.

    >>> from lfcl.depth import estimate_disparity  # doctest: +SKIP
    >>> depth = estimate_disparity(mosaic, "GRBG", 9)  # doctest: +SKIP
    >>> depth.disparity.shape, depth.confidence.shape  # doctest: +SKIP
    ((S, T), (S, T))
"""

from __future__ import annotations

from .estimate import DEFAULTS, DisparityMap, candidates, estimate_disparity
from .metrics import badpix, depth_scores, mse100, read_pfm

__all__ = ["DEFAULTS", "DisparityMap", "badpix", "candidates", "depth_scores", "estimate_disparity", "mse100",
           "read_pfm"]

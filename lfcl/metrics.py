"""Image-quality metrics on light fields in the exchange layout [S, T, U, V, 3].

PSNR uses peak 1.0 (the normalised raw's white level) over all three channels,
as in the paper's Tables 1-2: on the centre sub-aperture view and on the mean
image (the average over u, v).
"""

from __future__ import annotations

import math

import numpy as np


def psnr(estimate: np.ndarray, truth: np.ndarray, peak: float = 1.0) -> float:
    """10 log10(peak^2 / MSE), MSE over every element, accumulated in float64."""
    if estimate.shape != truth.shape:
        raise ValueError(f"cannot compare shapes {estimate.shape} and {truth.shape}")
    mse = float(np.mean((estimate.astype(np.float64) - truth.astype(np.float64)) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(peak**2 / mse)


def centre_view(lightfield: np.ndarray) -> np.ndarray:
    """The centre sub-aperture view [S, T, 3] (u = U // 2, v = V // 2)."""
    _, _, U, V, _ = lightfield.shape
    return lightfield[:, :, U // 2, V // 2]


def mean_image(lightfield: np.ndarray) -> np.ndarray:
    """The mean over all (u, v) views [S, T, 3] (float64 accumulation)."""
    return lightfield.mean(axis=(2, 3), dtype=np.float64).astype(np.float32)


def lightfield_scores(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """PSNR of the centre view and of the mean image (the paper's two rows)."""
    if estimate.shape != truth.shape:
        raise ValueError(f"light field {estimate.shape} and truth {truth.shape} differ in shape")
    return {
        "psnr_center": psnr(centre_view(estimate), centre_view(truth)),
        "psnr_mean": psnr(mean_image(estimate), mean_image(truth)),
    }


"""HCI 4D light-field benchmark depth metrics and its PFM ground truth.

K. Honauer, O. Johannsen, D. Kondermann, B. Goldluecke, "A dataset and evaluation methodology
for depth estimation on 4D light fields", ACCV 2016: BadPix(t) is the share of pixels whose
disparity error exceeds ``t`` (in %), MSE x 100 the mean squared disparity error times 100.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _pair(estimate, truth, mask):
    estimate = np.asarray(estimate, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    if estimate.shape != truth.shape:
        raise ValueError(f"disparity shapes differ: estimate {estimate.shape}, truth {truth.shape}")
    if mask is None:
        mask = np.ones(truth.shape, bool)
    mask = np.asarray(mask, bool)
    if mask.shape != truth.shape:
        raise ValueError(f"mask shape {mask.shape} differs from the disparity's {truth.shape}")
    if not mask.any():
        raise ValueError("no pixel to score (empty mask)")
    if not (np.all(np.isfinite(estimate[mask])) and np.all(np.isfinite(truth[mask]))):
        raise ValueError("disparities must be finite where scored")
    return estimate[mask], truth[mask]


def badpix(estimate, truth, threshold: float = 0.07, mask=None) -> float:
    """BadPix(threshold): % of pixels with ``|estimate - truth| > threshold``."""
    e, t = _pair(estimate, truth, mask)
    return float(100.0 * np.mean(np.abs(e - t) > threshold))


def mse100(estimate, truth, mask=None) -> float:
    """MSE x 100 of the disparity."""
    e, t = _pair(estimate, truth, mask)
    return float(100.0 * np.mean((e - t) ** 2))


def depth_scores(estimate, truth, mask=None) -> dict:
    """``{"badpix_0.07", "badpix_0.1", "mse_x100"}`` (the HCI benchmark's figures)."""
    return {"badpix_0.07": badpix(estimate, truth, 0.07, mask), "badpix_0.1": badpix(estimate, truth, 0.1, mask),
            "mse_x100": mse100(estimate, truth, mask)}


def read_pfm(path) -> np.ndarray:
    """A one-channel PFM (``Pf``) as float32 [H, W], top row first (PFM stores the bottom row first)."""
    path = Path(path)
    with open(path, "rb") as f:
        kind = f.readline().strip()
        if kind not in (b"Pf", b"PF"):
            raise ValueError(f"{path} is not a PFM file")
        try:
            width, height = (int(n) for n in f.readline().split())
            scale = float(f.readline().strip())
        except ValueError:
            raise ValueError(f"{path}: malformed PFM header") from None
        channels = 1 if kind == b"Pf" else 3
        data = np.fromfile(f, dtype="<f4" if scale < 0 else ">f4")
    if data.size != width * height * channels:
        raise ValueError(f"{path}: {data.size} values, the header says {width}x{height}x{channels}")
    data = data.reshape(height, width, channels)[::-1]
    return np.ascontiguousarray(data[:, :, 0] if channels == 1 else data, dtype=np.float32)
